//! Slow, obviously-correct references for the kernels in [`super::bins`] and [`super::fast`].
//! They are the test oracles; production code does not call them.
//!
//! - [`legendre_series_direct`]: Σ_l a_l P_l(μ) by running Bonnet's recurrence at every μ,
//!   O(L·J).
//! - [`gauss_legendre`]: n-point Gauss–Legendre nodes and weights by Newton's method on P_n,
//!   O(n²) per sweep; exact for polynomials of degree ≤ 2n − 1.
//! - [`coefficients_by_gauss_quadrature`]: a_l = (2l + 1)/2 ∫ f P_l dμ by Gauss–Legendre, exact
//!   for f of degree ≤ 2n − 1 − l_max, O(l_max·n).
//! - [`bin_integrals_by_quadrature`]: ∫_bin P_l dμ = ∫ P_l(cos θ) sin θ dθ by Gauss–Legendre in
//!   θ over the bin, converged to rounding with ~l/2 + 2 nodes on bins of lΔθ ≲ 10.

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

/// f(μ_j) = Σ_l a_l P_l(μ_j) by direct recurrence summation at each μ_j. O(L·J).
pub fn legendre_series_direct(a: &[f64], mu: &[f64]) -> Vec<f64> {
    mu.iter()
        .map(|&mu| {
            let (mut p_prev, mut p_l) = (0.0, 1.0);
            let mut f = 0.0;
            for (l, a_l) in a.iter().enumerate() {
                f += a_l * p_l;
                let lf = l as f64;
                let p_next = ((2.0 * lf + 1.0) * mu * p_l - lf * p_prev) / (lf + 1.0);
                p_prev = p_l;
                p_l = p_next;
            }
            f
        })
        .collect()
}

/// f(μ_j) = Σ_l a_l P_l(μ_j) on the cosine grid μ_j = cos(jπ/N), j = 0..=N, by direct
/// summation with [`legendre_p_all_versine`]'s recurrence at exact θ_j = jπ/N (j ≤ N/2) and
/// P_l(−μ) = (−1)^l P_l(μ) for the backward half. O(L·N). Unlike [`legendre_series_direct`] at
/// rounded cosines it carries no node-rounding error (|f'(±1)| ~ Σ l²|a_l|/2 times one ulp of
/// μ) and no l^{3/2} growth near the poles.
pub fn legendre_series_direct_cosine_grid(a: &[f64], n_intervals: usize) -> Vec<f64> {
    let n = n_intervals;
    let mut f = vec![0.0; n + 1];
    for j in 0..=n / 2 {
        let theta = j as f64 * std::f64::consts::PI / n as f64;
        let v = 2.0 * (0.5 * theta).sin().powi(2);
        let (mut p_l, mut d_l) = (1.0, 1.0);
        let (mut f_even, mut f_odd) = (0.0, 0.0);
        for (l, a_l) in a.iter().enumerate() {
            if l % 2 == 0 {
                f_even += a_l * p_l;
            } else {
                f_odd += a_l * p_l;
            }
            let lf = l as f64;
            d_l = (lf * d_l - (2.0 * lf + 1.0) * v * p_l) / (lf + 1.0);
            p_l += d_l;
        }
        f[j] = f_even + f_odd;
        f[n - j] = f_even - f_odd;
    }
    f
}

/// (P_n(x), P'_n(x)) for |x| < 1.
fn legendre_and_derivative(n: usize, x: f64) -> (f64, f64) {
    let (mut p_prev, mut p_l) = (0.0, 1.0);
    for l in 0..n {
        let lf = l as f64;
        let p_next = ((2.0 * lf + 1.0) * x * p_l - lf * p_prev) / (lf + 1.0);
        p_prev = p_l;
        p_l = p_next;
    }
    // (1 − x²) P'_n = n (P_{n−1} − x P_n).
    let dp = n as f64 * (p_prev - x * p_l) / ((1.0 - x) * (1.0 + x));
    (p_l, dp)
}

/// n-point Gauss–Legendre nodes (descending, x_0 closest to +1) and weights on [−1, 1].
/// Newton's method on P_n from Tricomi's initial guess cos(π(i + 3/4)/(n + 1/2)); weights
/// w_i = 2/((1 − x_i²) P'_n(x_i)²) (Abramowitz & Stegun 25.4.29). Nodes are mirror-symmetric.
pub fn gauss_legendre(n: usize) -> (Vec<f64>, Vec<f64>) {
    let mut x = vec![0.0; n];
    let mut w = vec![0.0; n];
    let nf = n as f64;
    for i in 0..n.div_ceil(2) {
        let mut xi = (std::f64::consts::PI * (i as f64 + 0.75) / (nf + 0.5)).cos();
        for _ in 0..100 {
            let (p, dp) = legendre_and_derivative(n, xi);
            let dx = p / dp;
            xi -= dx;
            if dx.abs() <= 1e-16 {
                break;
            }
        }
        if n % 2 == 1 && i == n / 2 {
            xi = 0.0;
        }
        let (_, dp) = legendre_and_derivative(n, xi);
        let wi = 2.0 / ((1.0 - xi) * (1.0 + xi) * dp * dp);
        x[i] = xi;
        x[n - 1 - i] = -xi;
        w[i] = wi;
        w[n - 1 - i] = wi;
    }
    (x, w)
}

/// a_l = (2l + 1)/2 Σ_i w_i f(x_i) P_l(x_i), l = 0..=l_max, from samples at Gauss–Legendre
/// nodes `x` with weights `w`. O(l_max·n).
pub fn coefficients_by_gauss_quadrature(x: &[f64], w: &[f64], f: &[f64], l_max: usize) -> Vec<f64> {
    let mut a = vec![0.0; l_max + 1];
    for ((&xi, &wi), &fi) in x.iter().zip(w).zip(f) {
        let (mut p_prev, mut p_l) = (0.0, 1.0);
        for (l, a_l) in a.iter_mut().enumerate() {
            *a_l += wi * fi * p_l;
            let lf = l as f64;
            let p_next = ((2.0 * lf + 1.0) * xi * p_l - lf * p_prev) / (lf + 1.0);
            p_prev = p_l;
            p_l = p_next;
        }
    }
    for (l, a_l) in a.iter_mut().enumerate() {
        *a_l *= (2 * l + 1) as f64 / 2.0;
    }
    a
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

    #[test]
    fn gauss_legendre_matches_published_five_point_rule() {
        // A&S 25.4 Table, n = 5; closed forms x = ⅓√(5 ∓ 2√(10/7)), w = (322 ± 13√70)/900,
        // centre 0 with weight 128/225.
        let (x, w) = gauss_legendre(5);
        let s = (10.0f64 / 7.0).sqrt();
        let x_want = [
            (5.0 + 2.0 * s).sqrt() / 3.0,
            (5.0 - 2.0 * s).sqrt() / 3.0,
            0.0,
        ];
        let r70 = 70.0f64.sqrt();
        let w_want = [
            (322.0 - 13.0 * r70) / 900.0,
            (322.0 + 13.0 * r70) / 900.0,
            128.0 / 225.0,
        ];
        for i in 0..3 {
            assert!((x[i] - x_want[i]).abs() < 2e-16, "x_{i} = {}", x[i]);
            assert!((w[i] - w_want[i]).abs() < 4e-16, "w_{i} = {}", w[i]);
            assert_eq!(x[4 - i], -x[i]);
        }
        // Table digits, A&S 25.4: 0.906179845938664, 0.236926885056189.
        assert!((x[0] - 0.906_179_845_938_664).abs() < 1e-15);
        assert!((w[0] - 0.236_926_885_056_189).abs() < 1e-15);
        // Σ w = 2 and exactness on x^{2n−2} at a large n.
        let (x, w) = gauss_legendre(1001);
        let total: f64 = w.iter().sum();
        assert!((total - 2.0).abs() < 1e-13, "{total}");
        let m2: f64 = x.iter().zip(&w).map(|(x, w)| w * x * x).sum();
        assert!((m2 - 2.0 / 3.0).abs() < 1e-13, "{m2}");
    }
}
