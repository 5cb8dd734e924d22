//! Gauss–Legendre quadrature on [−1, 1] and on any interval: the bins' and the size
//! distributions' integrals (`photometeor-mie`, `photometeor-tables`) and the skylight's
//! directions (`photometeor-render`).

/// Nodes and weights of the n-point Gauss–Legendre rule on [−1, 1], nodes ascending.
///
/// Roots of P_n by Newton's method from Tricomi's initial guess; P_n and P'_n by the
/// three-term recurrence. Accurate to a few ulps for n up to ~1e5 (O(n²) work).
pub fn gauss_legendre(n: usize) -> (Vec<f64>, Vec<f64>) {
    assert!(n > 0, "a quadrature rule needs at least one node");
    let mut nodes = vec![0.0; n];
    let mut weights = vec![0.0; n];
    let nf = n as f64;
    for i in 0..n.div_ceil(2) {
        // Initial guess for the (i+1)-th largest root.
        let theta = std::f64::consts::PI * (i as f64 + 0.75) / (nf + 0.5);
        let mut x = (1.0 - (nf - 1.0) / (8.0 * nf * nf * nf)) * theta.cos();
        let mut derivative = 0.0;
        for _ in 0..100 {
            let (p, dp) = legendre_and_derivative(n, x);
            derivative = dp;
            let dx = p / dp;
            x -= dx;
            if dx.abs() <= 1e-16 * x.abs().max(1e-300) {
                break;
            }
        }
        let (_, dp) = legendre_and_derivative(n, x);
        if dp != 0.0 {
            derivative = dp;
        }
        let w = 2.0 / ((1.0 - x * x) * derivative * derivative);
        nodes[n - 1 - i] = x;
        weights[n - 1 - i] = w;
        nodes[i] = -x;
        weights[i] = w;
    }
    if n % 2 == 1 {
        nodes[n / 2] = 0.0;
    }
    (nodes, weights)
}

/// P_n(x) and P'_n(x) by Bonnet's recurrence.
fn legendre_and_derivative(n: usize, x: f64) -> (f64, f64) {
    let (mut p_prev, mut p) = (1.0, x);
    for k in 2..=n {
        let kf = k as f64;
        let next = ((2.0 * kf - 1.0) * x * p - (kf - 1.0) * p_prev) / kf;
        p_prev = p;
        p = next;
    }
    if n == 0 {
        return (1.0, 0.0);
    }
    let dp = n as f64 * (x * p - p_prev) / (x * x - 1.0);
    (p, dp)
}

/// Gauss–Legendre rule mapped to [a, b].
pub fn gauss_legendre_on(n: usize, a: f64, b: f64) -> (Vec<f64>, Vec<f64>) {
    let (x, w) = gauss_legendre(n);
    let half = 0.5 * (b - a);
    let mid = 0.5 * (b + a);
    (
        x.iter().map(|&t| mid + half * t).collect(),
        w.iter().map(|&v| v * half).collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integrates_polynomials_exactly() {
        for n in [1, 2, 5, 16, 101, 1000] {
            let (x, w) = gauss_legendre(n);
            assert!((w.iter().sum::<f64>() - 2.0).abs() < 1e-13, "n = {n}");
            // ∫ t^{2n−2} dt = 2/(2n−1)
            let k = 2 * n - 2;
            let integral: f64 = x.iter().zip(&w).map(|(t, v)| v * t.powi(k as i32)).sum();
            assert!(
                (integral - 2.0 / (k as f64 + 1.0)).abs() < 1e-12,
                "n = {n}: {integral}"
            );
        }
    }

    #[test]
    fn gauss_legendre_matches_published_five_point_rule() {
        // A&S 25.4 Table, n = 5; closed forms x = ⅓√(5 ∓ 2√(10/7)), w = (322 ± 13√70)/900,
        // centre 0 with weight 128/225.
        // Descending order, largest node first.
        let (x, w) = gauss_legendre(5);
        let x: Vec<f64> = x.into_iter().rev().collect();
        let w: Vec<f64> = w.into_iter().rev().collect();
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
