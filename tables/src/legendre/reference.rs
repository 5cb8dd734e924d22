//! Slow, obviously-correct references for the kernels in [`super::bins`]. They are the test
//! oracles; production code does not call them.
//!
//! - [`legendre_p_all`], [`legendre_p_all_versine`]: P_0..P_L at one point by Bonnet's
//!   recurrence (the versine form near the poles).
//! - [`gauss_legendre`]: the solver's n-point Gauss–Legendre rule (`mie::quadrature`), exact for
//!   polynomials of degree ≤ 2n − 1.
//! - [`bin_integrals_by_quadrature`]: ∫_bin P_l dμ = ∫ P_l(cos θ) sin θ dθ by Gauss–Legendre in
//!   θ over the bin, converged to rounding with ~l/2 + 2 nodes on bins of lΔθ ≲ 10.

pub use grid::quadrature::gauss_legendre;

/// P_0(μ) … P_{l_max}(μ) by Bonnet's recurrence (l + 1) P_{l+1} = (2l + 1) μ P_l − l P_{l−1}.
pub fn legendre_p_all(l_max: usize, mu: f64) -> Vec<f64> {
    let mut p = Vec::with_capacity(l_max + 1);
    let (mut p_prev, mut p_l) = (0.0, 1.0);
    for l in 0..=l_max {
        p.push(p_l);
        let lf = l as f64;
        let p_next = ((2.0 * lf + 1.0) * mu * p_l - lf * p_prev) / (lf + 1.0);
        p_prev = p_l;
        p_l = p_next;
    }
    p
}

/// P_0 … P_{l_max} at μ = cos θ = 1 − v, given v = 1 − cos θ = 2 sin²(θ/2) (0 ≤ θ ≤ π/2), by
/// Reinsch's difference form of Bonnet's recurrence, D_l = P_l − P_{l−1}:
///
///   D_{l+1} = (l D_l − (2l + 1) v P_l) / (l + 1),   P_{l+1} = P_l + D_{l+1}.
///
/// Near μ = 1 the plain recurrence P_{l+1} ≈ 2P_l − P_{l−1} has a double characteristic root,
/// so its rounding errors grow like l^{3/2} ulp, and the rounding of μ itself (one ulp is a
/// relative error of 1e-10 in 1 − μ at 0.09°) shifts P_l by P'_l·1e-16 ≈ l²·6e-17. The
/// difference form injects errors only of size ulp·|D_l| and ulp·v|P_l|, and never forms μ.
pub fn legendre_p_all_versine(l_max: usize, v: f64) -> Vec<f64> {
    let mut p = Vec::with_capacity(l_max + 1);
    let (mut p_l, mut d_l) = (1.0, 1.0);
    for l in 0..=l_max {
        p.push(p_l);
        let lf = l as f64;
        d_l = (lf * d_l - (2.0 * lf + 1.0) * v * p_l) / (lf + 1.0);
        p_l += d_l;
    }
    p
}

/// ∫_{θ_a}^{θ_b} P_l(cos θ) sin θ dθ = ∫_bin P_l dμ for l = 0..=l_max, by Gauss–Legendre
/// (x, w from [`gauss_legendre`]) in θ on [θ_a, θ_b]. O(l_max · x.len()).
///
/// The integrand is analytic, so the rule converges geometrically; with x.len() ≥ l_max/2 + 2
/// nodes and a bin of l_max (θ_b − θ_a) ≲ 10 it is converged to rounding. Integrating in θ rather
/// than μ keeps the bin edges exact: a rounded edge cosine near μ = 1 moves 1 − μ by up to
/// 1e-10 relative at the forward edge of a 0.18° grid. For the same reason a bin beyond 90° is
/// integrated as its mirror image (and P_l comes from [`legendre_p_all_versine`]) [π − θ_b, π − θ_a] with P_l(−μ) = (−1)^l P_l(μ): sin θ from a
/// rounded θ near π is off by ~4e-16/sin θ relative.
pub fn bin_integrals_by_quadrature(
    theta_a: f64,
    theta_b: f64,
    l_max: usize,
    x: &[f64],
    w: &[f64],
) -> Vec<f64> {
    assert!(
        theta_a + theta_b <= std::f64::consts::PI + 1e-12,
        "integrate bins beyond π/2 as their mirror image"
    );
    let half = 0.5 * (theta_b - theta_a);
    let mid = 0.5 * (theta_b + theta_a);
    let mut s = vec![0.0; l_max + 1];
    for (&xi, &wi) in x.iter().zip(w) {
        let theta = mid + half * xi;
        let p = legendre_p_all_versine(l_max, 2.0 * (0.5 * theta).sin().powi(2));
        let sin_t = theta.sin();
        for (s_l, p_l) in s.iter_mut().zip(&p) {
            *s_l += wi * sin_t * p_l;
        }
    }
    s.iter().map(|s_l| half * s_l).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn legendre_values_match_closed_forms() {
        // P_l(1/2) from the explicit polynomials (A&S 22.3.8, Table 22.9):
        // P_2 = −1/8, P_3 = −7/16, P_4 = −37/128, P_5 = 23/256 — all exact in binary.
        let p = legendre_p_all(5, 0.5);
        let want = [1.0, 0.5, -0.125, -0.4375, -0.2890625, 0.08984375];
        for (l, (x, y)) in p.iter().zip(want).enumerate() {
            assert!((x - y).abs() <= 1e-16, "P_{l}(1/2) = {x}, want {y}");
        }
        // P_l(±1) = (±1)^l at high degree: the recurrence does not drift.
        let p = legendre_p_all(20_000, -1.0);
        for (l, v) in p.iter().enumerate() {
            let want = if l % 2 == 0 { 1.0 } else { -1.0 };
            assert!((v - want).abs() < 1e-12, "{l}");
        }
    }
}
