//! Mie coefficients a_n, b_n of a homogeneous sphere and the efficiencies built from them.
//!
//! # Conventions
//! - Refractive index relative to the surrounding medium: m = n + iκ, κ ≥ 0 absorbing
//!   (Bohren & Huffman 1983, time factor e^{-iωt}). κ < 0 is refused, never conjugated.
//! - Size parameter x = 2π r / λ.
//! - Q_back is the radar convention (van de Hulst, Wiscombe): Q_back = 4 |S1(180°)|² / x².
//!
//! # Numerical method (Bohren & Huffman 1983 ch. 4, Wiscombe 1980 Appl. Opt. 19, 1505)
//! - Number of terms N_stop = x + 4.05 x^{1/3} + 2 (Wiscombe).
//! - Logarithmic derivative D_n(mx) by downward recurrence, seeded at n = N_stop with the exact
//!   value from Lentz's continued fraction (Lentz 1976, Appl. Opt. 15, 668). The textbook start
//!   15 orders above max(N_stop, |mx|) from D = 0 is silently wrong for x ≳ 1e3.
//! - Riccati–Bessel ψ_n(x), χ_n(x) by upward recurrence (stable up to N_stop for real x).
//! - For x·|m| ≤ 0.1 the recurrences lose digits to cancellation (ψ_1 ≈ x²/3 is a difference of
//!   two numbers ≈ 1), so a_1, b_1, a_2 come from Wiscombe's small-particle expansions instead.
//! - Sums over n use Neumaier compensated summation; the back-scatter sum cancels strongly.

use num_complex::Complex64;

use crate::error::{MieError, check_range};

/// Largest size parameter the solver is validated for.
pub const X_MAX: f64 = 2.0e5;
/// Smallest size parameter accepted: the validated range starts here (below it Q_sca ∝ x⁴
/// underflows toward 0 and a phase function normalized by it is undefined).
pub const X_MIN: f64 = 1.0e-6;
/// Largest real part of m the solver is validated for.
pub const N_MAX: f64 = 10.0;
/// Smallest real part of m the solver is validated for.
pub const N_MIN: f64 = 0.5;
/// Largest imaginary part of m the solver is validated for.
pub const KAPPA_MAX: f64 = 10.0;

/// A validated (m, x) pair.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sphere {
    m: Complex64,
    x: f64,
}

impl Sphere {
    /// Checks m = n + iκ and x against the validated ranges:
    /// x ∈ [1e-6, 2e5], n ∈ [0.5, 10], κ ∈ [0, 10], m ≠ 1.
    pub fn new(m: Complex64, x: f64) -> Result<Self, MieError> {
        if !(x.is_finite() && (X_MIN..=X_MAX).contains(&x)) {
            return Err(MieError::OutOfRange {
                name: "size parameter x",
                value: x,
                range: "[1e-6, 2e5]",
            });
        }
        if m.im.is_finite() && m.im < 0.0 {
            return Err(MieError::NegativeKappa(m.im));
        }
        check_range("refractive index n = Re m", m.re, N_MIN, N_MAX, "[0.5, 10]")?;
        check_range(
            "imaginary refractive index κ = Im m",
            m.im,
            0.0,
            KAPPA_MAX,
            "[0, 10]",
        )?;
        if m.re == 1.0 && m.im == 0.0 {
            return Err(MieError::NoScattering);
        }
        Ok(Self { m, x })
    }

    /// Relative refractive index m = n + iκ.
    pub fn m(&self) -> Complex64 {
        self.m
    }

    /// Size parameter x = 2π r / λ.
    pub fn x(&self) -> f64 {
        self.x
    }

    /// Wiscombe's number of terms: N_stop = x + 4.05 x^{1/3} + 2, at least 2.
    pub fn n_stop(&self) -> usize {
        n_stop(self.x)
    }

    /// Computes a_n, b_n for n = 1..N_stop.
    pub fn coefficients(&self) -> MieCoefficients {
        if use_small_particle_expansion(self.m, self.x) {
            small_particle_coefficients(self.m, self.x)
        } else {
            recurrence_coefficients(self.m, self.x)
        }
    }
}

/// Wiscombe's number of terms N_stop = x + 4.05 x^{1/3} + 2 (rounded down, at least 2).
pub fn n_stop(x: f64) -> usize {
    ((x + 4.05 * x.cbrt() + 2.0).floor() as usize).max(2)
}

/// Mie coefficients of one sphere; `a[0]` is a_1.
#[derive(Debug, Clone, PartialEq)]
pub struct MieCoefficients {
    /// Relative refractive index m = n + iκ.
    pub m: Complex64,
    /// Size parameter x = 2πr/λ.
    pub x: f64,
    /// Electric coefficients a_n, n = 1..N_stop.
    pub a: Vec<Complex64>,
    /// Magnetic coefficients b_n, n = 1..N_stop.
    pub b: Vec<Complex64>,
    /// True when a_n, b_n come from Wiscombe's small-particle expansions.
    pub small_particle: bool,
}

/// Efficiencies and asymmetry parameter of one sphere.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Efficiencies {
    /// Extinction efficiency Q_ext = σ_ext / (πr²).
    pub q_ext: f64,
    /// Scattering efficiency Q_sca = σ_sca / (πr²).
    pub q_sca: f64,
    /// Absorption efficiency Q_abs = Q_ext − Q_sca.
    pub q_abs: f64,
    /// Radar convention: 4 |S1(180°)|² / x².
    pub q_back: f64,
    /// Asymmetry parameter ⟨cos θ⟩.
    pub g: f64,
    /// Number of terms N_stop summed.
    pub n_terms: usize,
}

impl MieCoefficients {
    /// Number of terms kept.
    pub fn n_terms(&self) -> usize {
        self.a.len()
    }

    /// Q_ext, Q_sca, Q_abs, Q_back and g from the coefficient sums (Bohren & Huffman Eqs. 4.61, 4.62;
    /// g from B&H p. 120; Q_back radar convention).
    pub fn efficiencies(&self) -> Efficiencies {
        let x2 = self.x * self.x;
        let n_terms = self.n_terms();
        let mut ext = Neumaier::default();
        let mut sca = Neumaier::default();
        let mut asym = Neumaier::default();
        let mut back_re = Neumaier::default();
        let mut back_im = Neumaier::default();
        for i in 0..n_terms {
            let n = (i + 1) as f64;
            let (a_n, b_n) = (self.a[i], self.b[i]);
            let weight = 2.0 * n + 1.0;
            // Q_ext = (2/x²) Σ (2n+1) Re(a_n + b_n)
            ext.add(weight * (a_n.re + b_n.re));
            // Q_sca = (2/x²) Σ (2n+1)(|a_n|² + |b_n|²)
            sca.add(weight * (a_n.norm_sqr() + b_n.norm_sqr()));
            // g Q_sca = (4/x²) Σ [n(n+2)/(n+1) Re(a_n a*_{n+1} + b_n b*_{n+1}) + (2n+1)/(n(n+1)) Re(a_n b*_n)]
            if i + 1 < n_terms {
                let (a_next, b_next) = (self.a[i + 1], self.b[i + 1]);
                asym.add(
                    n * (n + 2.0) / (n + 1.0)
                        * ((a_n * a_next.conj()).re + (b_n * b_next.conj()).re),
                );
            }
            asym.add(weight / (n * (n + 1.0)) * (a_n * b_n.conj()).re);
            // Σ (2n+1)(−1)^n (a_n − b_n)
            let sign = if (i + 1) % 2 == 0 { 1.0 } else { -1.0 };
            let d = (a_n - b_n) * (sign * weight);
            back_re.add(d.re);
            back_im.add(d.im);
        }
        let q_sca = 2.0 / x2 * sca.sum();
        // For κ = 0 nothing is absorbed, so Q_ext = Q_sca exactly. The small-particle
        // expansions carry Re(a_1) (and so Q_ext) less accurately than |a_1|², so there the
        // identity is used, as in Wiscombe's MIEV0.
        let q_ext = if self.small_particle && self.m.im == 0.0 {
            q_sca
        } else {
            2.0 / x2 * ext.sum()
        };
        let g = 4.0 / x2 * asym.sum() / q_sca;
        let q_back = Complex64::new(back_re.sum(), back_im.sum()).norm_sqr() / x2;
        Efficiencies {
            q_ext,
            q_sca,
            q_abs: q_ext - q_sca,
            q_back,
            g,
            n_terms,
        }
    }
}

/// Neumaier's compensated summation (an improved Kahan–Babuška sum).
#[derive(Debug, Default, Clone, Copy)]
pub(crate) struct Neumaier {
    sum: f64,
    compensation: f64,
}

impl Neumaier {
    pub(crate) fn add(&mut self, value: f64) {
        let t = self.sum + value;
        if self.sum.abs() >= value.abs() {
            self.compensation += (self.sum - t) + value;
        } else {
            self.compensation += (value - t) + self.sum;
        }
        self.sum = t;
    }

    pub(crate) fn sum(&self) -> f64 {
        self.sum + self.compensation
    }
}

/// Chooses the path with the smaller error model, both measured against 50-digit values
/// (data/reference/mpmath_small_spheres.csv):
/// - the expansions' truncation error in g grows like 2e-2 (x·max(1,|m|))⁴ √min(1, |m² − 1|)
///   (2.5e-6 at x = 0.099, m = 1.33 — Wiscombe's switch at x·|m| = 0.1 is too late for 1e-6);
/// - the recurrences lose digits to cancellation like 2e-16 / (x⁴ min(1, |m² − 1|)²)
///   (3e-3 at x = 1e-3, m = 1.33; far worse as m → 1 because a_n ∝ m² − 1).
///
/// At the crossover the larger of the two is below 5e-7 for |m| ≤ 14.
fn use_small_particle_expansion(m: Complex64, x: f64) -> bool {
    let size = x * m.norm().max(1.0);
    let contrast = (m * m - 1.0).norm().min(1.0);
    let truncation = 2e-2 * size.powi(4) * contrast.sqrt();
    let cancellation = 2e-16 / (x.powi(4) * contrast * contrast);
    truncation <= cancellation
}

/// Wiscombe's small-particle expansions (NCAR TN-140, 1979; MIEV0 routine SMALL2), rewritten for m = n + iκ (Wiscombe writes m = n − iκ, which conjugates every
/// explicit i). They give a_1, b_1, a_2 to O(x^7) relative accuracy; b_2 and higher are
/// negligible (O(x^7)).
fn small_particle_coefficients(m: Complex64, x: f64) -> MieCoefficients {
    let i = Complex64::new(0.0, -1.0); // Wiscombe's i, conjugated for our sign of Im m
    let m2 = m * m;
    let x2 = x * x;
    let x3 = x2 * x;
    let x4 = x2 * x2;
    let m2m1 = m2 - 1.0;
    // Denominator of â_1.
    let d = m2 + 2.0 + (1.0 - 0.7 * m2) * x2 - (8.0 * m2 * m2 - 385.0 * m2 + 350.0) * x4 / 1400.0
        + 2.0 * i * m2m1 * x3 * (1.0 - 0.1 * x2) / 3.0;
    let a1_hat = 2.0 * i * m2m1 / 3.0 * (1.0 - 0.1 * x2 + (4.0 * m2 + 5.0) * x4 / 1400.0) / d;
    let b1_hat = i * x2 * m2m1 / 45.0 * (1.0 + (2.0 * m2 - 5.0) / 70.0 * x2)
        / (1.0 - (2.0 * m2 - 5.0) / 30.0 * x2);
    let a2_hat =
        i * x2 * m2m1 / 15.0 * (1.0 - x2 / 14.0) / (2.0 * m2 + 3.0 - (2.0 * m2 - 7.0) / 14.0 * x2);
    // a_n = x³ â_n (Wiscombe's scaling).
    MieCoefficients {
        m,
        x,
        a: vec![a1_hat * x3, a2_hat * x3],
        b: vec![b1_hat * x3, Complex64::new(0.0, 0.0)],
        small_particle: true,
    }
}

/// a_n, b_n from D_n(mx) (downward, Lentz-seeded) and ψ_n, χ_n (upward), B&H Eq. 4.88.
fn recurrence_coefficients(m: Complex64, x: f64) -> MieCoefficients {
    let n_terms = n_stop(x);
    let mx = m * x;
    let d = log_derivative_down(mx, n_terms);

    let mut a = Vec::with_capacity(n_terms);
    let mut b = Vec::with_capacity(n_terms);
    // ψ_{-1} = cos x, ψ_0 = sin x, χ_{-1} = −sin x, χ_0 = cos x; ξ_n = ψ_n − i χ_n.
    let (sin_x, cos_x) = x.sin_cos();
    let (mut psi_prev2, mut psi_prev) = (cos_x, sin_x);
    let (mut chi_prev2, mut chi_prev) = (-sin_x, cos_x);
    let inv_x = 1.0 / x;
    let inv_m = 1.0 / m;
    for i in 0..n_terms {
        let n = (i + 1) as f64;
        // f_n = (2n − 1)/x f_{n−1} − f_{n−2}
        let psi = (2.0 * n - 1.0) * inv_x * psi_prev - psi_prev2;
        let chi = (2.0 * n - 1.0) * inv_x * chi_prev - chi_prev2;
        let xi = Complex64::new(psi, -chi);
        let xi_prev = Complex64::new(psi_prev, -chi_prev);
        let n_over_x = n * inv_x;
        // a_n = [(D_n/m + n/x) ψ_n − ψ_{n−1}] / [(D_n/m + n/x) ξ_n − ξ_{n−1}]
        let ta = d[i] * inv_m + n_over_x;
        a.push((ta * psi - psi_prev) / (ta * xi - xi_prev));
        // b_n = [(m D_n + n/x) ψ_n − ψ_{n−1}] / [(m D_n + n/x) ξ_n − ξ_{n−1}]
        let tb = m * d[i] + n_over_x;
        b.push((tb * psi - psi_prev) / (tb * xi - xi_prev));
        psi_prev2 = psi_prev;
        psi_prev = psi;
        chi_prev2 = chi_prev;
        chi_prev = chi;
    }
    MieCoefficients {
        m,
        x,
        a,
        b,
        small_particle: false,
    }
}

/// D_n(z) = ψ'_n(z)/ψ_n(z) for n = 1..n_max; `d[0]` is D_1.
///
/// Seeded exactly at n_max by Lentz's continued fraction, then
/// D_{n−1} = n/z − 1/(D_n + n/z) downward, which is stable for every z.
pub(crate) fn log_derivative_down(z: Complex64, n_max: usize) -> Vec<Complex64> {
    let mut d = vec![Complex64::new(0.0, 0.0); n_max];
    d[n_max - 1] = lentz_log_derivative(z, n_max);
    let inv_z = 1.0 / z;
    for n in (2..=n_max).rev() {
        let n_over_z = n as f64 * inv_z;
        d[n - 2] = n_over_z - 1.0 / (d[n - 1] + n_over_z);
    }
    d
}

/// D_n(z) = −n/z + J_{n−1/2}(z)/J_{n+1/2}(z), the Bessel ratio by Lentz's method (1976):
/// J_{ν−1}/J_ν = a_1 + 1/(a_2 + 1/(a_3 + …)), a_k = (−1)^{k+1} 2(ν + k − 1)/z, ν = n + 1/2.
fn lentz_log_derivative(z: Complex64, n: usize) -> Complex64 {
    let nu = n as f64 + 0.5;
    let two_over_z = 2.0 / z;
    let a_k = |k: usize| -> Complex64 {
        let sign = if k % 2 == 1 { 1.0 } else { -1.0 };
        two_over_z * (sign * (nu + k as f64 - 1.0))
    };
    let a1 = a_k(1);
    let mut ratio = a1;
    // Lentz: numerator and denominator continuants, ratio = Π (num_k / den_k).
    let mut num = a_k(2) + 1.0 / a1;
    let mut den = a_k(2);
    let mut k = 2;
    loop {
        let step = num / den;
        ratio *= step;
        if (step - 1.0).norm() < 1e-15 {
            break;
        }
        k += 1;
        let a = a_k(k);
        num = a + 1.0 / num;
        den = a + 1.0 / den;
        // Lentz's guard against a vanishing continuant: restart from a tiny value.
        if num.norm() < 1e-300 {
            num = Complex64::new(1e-300, 0.0);
        }
        if den.norm() < 1e-300 {
            den = Complex64::new(1e-300, 0.0);
        }
        if k > 50_000_000 {
            break;
        }
    }
    -(n as f64) / z + ratio
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lentz_matches_long_downward_recurrence() {
        // Downward recurrence started far above |z| from D = 0 converges to the true values;
        // Lentz must agree with it at the seed index.
        for &(re, im, x) in &[(1.333, 1e-8, 50.0), (1.5, 1.0, 20.0), (10.0, 10.0, 3.0)] {
            let z = Complex64::new(re, im) * x;
            let n = 40;
            let mut dn = Complex64::new(0.0, 0.0);
            for k in (n + 1..=n + 2000).rev() {
                let k_over_z = k as f64 / z;
                dn = k_over_z - 1.0 / (dn + k_over_z);
            }
            let lentz = lentz_log_derivative(z, n);
            assert!(
                (lentz - dn).norm() / dn.norm() < 1e-12,
                "z = {z}: {lentz} vs {dn}"
            );
        }
    }

    #[test]
    fn neumaier_recovers_cancelled_sum() {
        let mut s = Neumaier::default();
        for v in [1.0, 1e100, 1.0, -1e100] {
            s.add(v);
        }
        assert_eq!(s.sum(), 2.0);
    }
}
