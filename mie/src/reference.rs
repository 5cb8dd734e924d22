//! Slow, obviously correct reference evaluations kept beside the fast kernels.
//!
//! `amplitudes_direct` is the textbook per-angle loop (B&H Eq. 4.74 with the π_n, τ_n
//! recurrences of Eq. 4.47); the batched GEMM kernel in [`crate::amplitude`] is tested against it.

use num_complex::Complex64;

use crate::sphere::MieCoefficients;

/// S1(μ), S2(μ) by direct summation, one angle at a time.
pub fn amplitudes_direct(coefficients: &MieCoefficients, mu: f64) -> (Complex64, Complex64) {
    let mut s1 = Complex64::new(0.0, 0.0);
    let mut s2 = Complex64::new(0.0, 0.0);
    let (mut pi_prev, mut pi) = (0.0, 1.0); // π_0, π_1
    for i in 0..coefficients.n_terms() {
        let n = (i + 1) as f64;
        // τ_n = n μ π_n − (n+1) π_{n−1}
        let tau = n * mu * pi - (n + 1.0) * pi_prev;
        let c = (2.0 * n + 1.0) / (n * (n + 1.0));
        s1 += (coefficients.a[i] * pi + coefficients.b[i] * tau) * c;
        s2 += (coefficients.a[i] * tau + coefficients.b[i] * pi) * c;
        // π_{n+1} = ((2n+1)/n) μ π_n − ((n+1)/n) π_{n−1}
        let next = ((2.0 * n + 1.0) * mu * pi - (n + 1.0) * pi_prev) / n;
        pi_prev = pi;
        pi = next;
    }
    (s1, s2)
}
