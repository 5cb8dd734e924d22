//! Fast Legendre ↔ point-value transform on the cosine grid μ_j = cos(jπ/N), j = 0..=N
//! (Chebyshev–Lobatto nodes; uniform in θ, forward first, so with N = 180°/Δθ they are the θ_k
//! of the table grid).
//!
//! # Method
//! Forward, [`evaluate_on_cosine_grid`]: a_l (l = 0..=L) → Chebyshev coefficients c_n
//! ([`legendre_to_chebyshev`]) → fold c_n onto n ∈ [0, N] (cos(nθ_j) depends only on n mod 2N
//! and is even in n, so the fold is exact on the grid, which lets L exceed N) → DCT-I
//! f(θ_j) = Σ_n c_n cos(n j π/N), done as one complex FFT of length 2N of the even extension.
//!
//! Inverse, [`coefficients_from_cosine_grid`]: N + 1 samples → DCT-I → Chebyshev coefficients of
//! the degree-N interpolant → Legendre coefficients ([`chebyshev_to_legendre`]). Exact (to
//! rounding) when the samples come from a polynomial of degree ≤ N.
//!
//! The conversions use the closed-form matrix entries (Alpert & Rokhlin 1991, SIAM J. Sci.
//! Stat. Comput. 12, 158, Eqs. 2.18–2.19), with Λ(z) = Γ(z + 1/2)/Γ(z + 1):
//!
//!   Legendre → Chebyshev, n ≤ l, l − n even:
//!     M_nl = (2/π) Λ((l − n)/2) Λ((l + n)/2), halved for n = 0;
//!   Chebyshev → Legendre, l ≤ n, n − l even:
//!     L_ll = √π / (2 Λ(l)) (L_00 = 1),
//!     L_ln = −n (l + 1/2) / ((n + l + 1)(n − l)) · Λ((n − l − 2)/2) Λ((n + l − 1)/2)
//!          = −½ [l/(n − l) + (l + 1)/(n + l + 1)] · Λ((n − l − 2)/2) Λ((n + l − 1)/2).
//!
//! Entries are generated on the fly from O(L) tables of Λ at integers and half-integers; no
//! matrix is stored.
//!
//! # Complexity
//! Conversion: (L + 1)²/4 fused multiply-adds (triangular, half the entries vanish by parity),
//! O(L) memory. DCT: O(N log N). So the transform is O(L²/4 + N log N), against O(L·(N + 1))
//! recurrence steps (each ~5 flops and a dependency chain) for direct summation
//! ([`super::reference::legendre_series_direct`]). Measured (test profile, one core): L = 5000,
//! N = 5000: 5 ms fast vs 107 ms direct; N = 1000: 4 ms vs 22 ms; L = 1000, N = 1000: 0.3 ms vs
//! 4 ms. For a handful of points direct summation is cheaper. An O(L log² L) conversion (Townsend, Webb & Olver 2018,
//! Toeplitz-dot-Hankel) would replace the quadratic term if L ≫ 10⁴ ever matters.
//!
//! # Numerical hazards
//! - Λ comes from its two-term recurrence Λ(z + 1) = Λ(z)(z + 1/2)/(z + 1); the rounding
//!   random-walks, ~√z ulp (≈ 1e-14 at z = 10⁴), measured through the transform tests.
//! - M has positive entries, so Legendre → Chebyshev adds no cancellation of its own. Point
//!   values near μ = ±1 are ill-conditioned in μ itself: |f'(±1)| ~ Σ l² |a_l|/2, so one ulp of
//!   μ (1.1e-16) moves f by ~L²·1e-16 relative to its size. This transform evaluates at the exact
//!   nodes cos(jπ/N); a reference summing the plain recurrence at the rounded cosines differed
//!   from it by 9e-11 (of max |f|) at L = 5000, so the reference
//!   ([`super::reference::legendre_series_direct_cosine_grid`]) runs Reinsch's form at the exact
//!   θ_j; fast and slow then agree to 3e-14 (tests/legendre_fast.rs).

use rustfft::FftPlanner;
use rustfft::num_complex::Complex;

use super::LegendreError;

/// Λ(k) = Γ(k + 1/2)/Γ(k + 1) for k = 0..len.
fn lambda_at_integers(len: usize) -> Vec<f64> {
    let mut lam = Vec::with_capacity(len);
    let mut v = std::f64::consts::PI.sqrt();
    for k in 0..len {
        lam.push(v);
        // Λ(k + 1) = Λ(k) (k + 1/2)/(k + 1).
        v *= (k as f64 + 0.5) / (k as f64 + 1.0);
    }
    lam
}

/// Λ(k + 1/2) = Γ(k + 1)/Γ(k + 3/2) for k = 0..len.
fn lambda_at_half_integers(len: usize) -> Vec<f64> {
    let mut lam = Vec::with_capacity(len);
    let mut v = 2.0 / std::f64::consts::PI.sqrt();
    for k in 0..len {
        lam.push(v);
        // Λ(k + 3/2) = Λ(k + 1/2) (k + 1)/(k + 3/2).
        v *= (k as f64 + 1.0) / (k as f64 + 1.5);
    }
    lam
}

/// Splits x into (x_0, x_2, x_4, …) and (x_1, x_3, …).
fn split_parity(x: &[f64]) -> [Vec<f64>; 2] {
    [
        x.iter().step_by(2).copied().collect(),
        x.iter().skip(1).step_by(2).copied().collect(),
    ]
}

/// Σ_i x_i y_i z_i over the common length, with four partial sums.
fn dot3(x: &[f64], y: &[f64], z: &[f64]) -> f64 {
    let len = x.len().min(y.len()).min(z.len());
    let (x, y, z) = (&x[..len], &y[..len], &z[..len]);
    let mut s = [0.0f64; 4];
    let chunks = len / 4;
    for c in 0..chunks {
        for i in 0..4 {
            let j = 4 * c + i;
            s[i] += x[j] * y[j] * z[j];
        }
    }
    let mut tail = 0.0;
    for j in 4 * chunks..len {
        tail += x[j] * y[j] * z[j];
    }
    (s[0] + s[1]) + (s[2] + s[3]) + tail
}

/// Chebyshev coefficients c_n (n = 0..=L) of Σ_l a_l P_l(μ) = Σ_n c_n T_n(μ).
/// O(L²/4) operations, O(L) memory.
pub fn legendre_to_chebyshev(a: &[f64]) -> Vec<f64> {
    let len = a.len();
    if len == 0 {
        return Vec::new();
    }
    let lam = lambda_at_integers(len);
    let a_par = split_parity(a);
    let mut c = vec![0.0; len];
    for n in 0..len {
        // c_n = (2/π) Σ_{i ≥ 0} Λ(i) Λ(n + i) a_{n+2i}   (n + 2i = l; halved for n = 0).
        let (q, p) = (n / 2, n % 2);
        let s = dot3(&lam, &lam[n..], &a_par[p][q..]);
        let scale = if n == 0 {
            std::f64::consts::FRAC_1_PI
        } else {
            std::f64::consts::FRAC_2_PI
        };
        c[n] = scale * s;
    }
    c
}

/// Legendre coefficients a_l (l = 0..=N) of Σ_n c_n T_n(μ) = Σ_l a_l P_l(μ).
/// O(N²/4) operations, O(N) memory.
pub fn chebyshev_to_legendre(c: &[f64]) -> Vec<f64> {
    let len = c.len();
    if len == 0 {
        return Vec::new();
    }
    let lam_int = lambda_at_integers(len);
    let lam_half = lambda_at_half_integers(len);
    // 1/(2i) for i ≥ 1 (index i) and 1/(2j + 1) (index j).
    let recip_even: Vec<f64> = (0..len)
        .map(|i| if i == 0 { 0.0 } else { 0.5 / i as f64 })
        .collect();
    let recip_odd: Vec<f64> = (0..len + len / 2 + 1)
        .map(|j| 1.0 / (2 * j + 1) as f64)
        .collect();
    let c_par = split_parity(c);
    let mut a = vec![0.0; len];
    let sqrt_pi = std::f64::consts::PI.sqrt();
    for l in 0..len {
        let (q, p) = (l / 2, l % 2);
        let c_l = &c_par[p][q..]; // c_{l+2i}, i = 0, 1, …
        let diag = if l == 0 {
            1.0
        } else {
            sqrt_pi / (2.0 * lam_int[l])
        };
        // Off-diagonal, n = l + 2i, i ≥ 1:
        //   L_ln = −½ [l/(2i) + (l + 1)/(2l + 2i + 1)] Λ(i − 1) Λ(l + i − 1/2).
        let lf = l as f64;
        let terms = c_l.len().saturating_sub(1);
        let mut s = [0.0f64; 4];
        let chunks = terms / 4;
        let term = |i: usize| {
            let coef = lf * recip_even[i] + (lf + 1.0) * recip_odd[l + i];
            coef * lam_int[i - 1] * lam_half[l + i - 1] * c_l[i]
        };
        for ch in 0..chunks {
            for u in 0..4 {
                s[u] += term(1 + 4 * ch + u);
            }
        }
        let mut tail = 0.0;
        for i in 1 + 4 * chunks..=terms {
            tail += term(i);
        }
        a[l] = diag * c_l[0] - 0.5 * ((s[0] + s[1]) + (s[2] + s[3]) + tail);
    }
    a
}

/// DCT-I: y_k = x_0 + (−1)^k x_N + 2 Σ_{j=1}^{N−1} x_j cos(π j k / N), k = 0..=N, via one complex
/// FFT of the even extension (x_0, …, x_N, x_{N−1}, …, x_1) of length 2N. Needs N ≥ 1.
fn dct1(x: &[f64]) -> Vec<f64> {
    let n = x.len() - 1;
    let mut buf: Vec<Complex<f64>> = Vec::with_capacity(2 * n);
    buf.extend(x.iter().map(|&v| Complex::new(v, 0.0)));
    buf.extend(x[1..n].iter().rev().map(|&v| Complex::new(v, 0.0)));
    let fft = FftPlanner::<f64>::new().plan_fft_forward(2 * n);
    fft.process(&mut buf);
    buf[..=n].iter().map(|z| z.re).collect()
}

/// The cosine-grid nodes μ_j = cos(jπ/N), j = 0..=N, exactly mirror-symmetric
/// (μ_{N−j} = −μ_j), forward (μ = 1) first.
pub fn cosine_grid_mu(n_intervals: usize) -> Vec<f64> {
    let n = n_intervals;
    let mut mu = vec![0.0; n + 1];
    for j in 0..=n / 2 {
        let c = (j as f64 * std::f64::consts::PI / n as f64).cos();
        mu[j] = c;
        mu[n - j] = -c;
    }
    if n.is_multiple_of(2) {
        mu[n / 2] = 0.0;
    }
    mu
}

/// f(μ_j) = Σ_{l=0}^{L} a_l P_l(μ_j) at μ_j = cos(jπ/N), j = 0..=N (`n_intervals` = N ≥ 1).
/// L = a.len() − 1 may exceed N. O(L²/4 + N log N).
pub fn evaluate_on_cosine_grid(a: &[f64], n_intervals: usize) -> Result<Vec<f64>, LegendreError> {
    let n = n_intervals;
    if n == 0 {
        return Err(LegendreError::TooFewSamples { samples: 1 });
    }
    let c = legendre_to_chebyshev(a);
    // Fold: on θ_j = jπ/N, cos(m θ_j) = cos(m' θ_j) with m' = m mod 2N reflected into [0, N].
    let mut c_folded = vec![0.0; n + 1];
    for (m, c_m) in c.iter().enumerate() {
        let r = m % (2 * n);
        let r = if r > n { 2 * n - r } else { r };
        c_folded[r] += c_m;
    }
    // Σ_m c_m cos(mθ_j) = DCT-I of (c_0, c_1/2, …, c_{N−1}/2, c_N).
    for c_m in &mut c_folded[1..n] {
        *c_m *= 0.5;
    }
    Ok(dct1(&c_folded))
}

/// Legendre coefficients a_l, l = 0..=N, of the degree-N polynomial through the N + 1 samples
/// f(μ_j), μ_j = cos(jπ/N) (forward first). O(N²/4 + N log N).
pub fn coefficients_from_cosine_grid(samples: &[f64]) -> Result<Vec<f64>, LegendreError> {
    if samples.len() < 2 {
        return Err(LegendreError::TooFewSamples {
            samples: samples.len(),
        });
    }
    let n = samples.len() - 1;
    // Chebyshev interpolation at the Lobatto nodes: with y = DCT-I(f),
    // c_n = y_n / N for 0 < n < N, c_0 = y_0 / (2N), c_N = y_N / (2N).
    let y = dct1(samples);
    let nf = n as f64;
    let c: Vec<f64> = y
        .iter()
        .enumerate()
        .map(|(m, y_m)| {
            if m == 0 || m == n {
                y_m / (2.0 * nf)
            } else {
                y_m / nf
            }
        })
        .collect();
    Ok(chebyshev_to_legendre(&c))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn low_degree_conversions_match_closed_forms() {
        // P_2 = (3/4) T_2 + (1/4) T_0; P_3 = (5/8) T_3 + (3/8) T_1 (Abramowitz & Stegun 22.3).
        let c = legendre_to_chebyshev(&[0.0, 0.0, 1.0, 0.0]);
        let want = [0.25, 0.0, 0.75, 0.0];
        for (x, y) in c.iter().zip(want) {
            assert!((x - y).abs() < 1e-15, "{c:?}");
        }
        let c = legendre_to_chebyshev(&[0.0, 0.0, 0.0, 1.0]);
        let want = [0.0, 0.375, 0.0, 0.625];
        for (x, y) in c.iter().zip(want) {
            assert!((x - y).abs() < 1e-15, "{c:?}");
        }
        // T_2 = (4/3) P_2 − (1/3) P_0; T_3 = (8/5) P_3 − (3/5) P_1.
        let a = chebyshev_to_legendre(&[0.0, 0.0, 1.0]);
        let want = [-1.0 / 3.0, 0.0, 4.0 / 3.0];
        for (x, y) in a.iter().zip(want) {
            assert!((x - y).abs() < 1e-15, "{a:?}");
        }
        let a = chebyshev_to_legendre(&[0.0, 0.0, 0.0, 1.0]);
        let want = [0.0, -0.6, 0.0, 1.6];
        for (x, y) in a.iter().zip(want) {
            assert!((x - y).abs() < 1e-15, "{a:?}");
        }
    }

    #[test]
    fn dct1_matches_its_definition() {
        let x = [0.3, -1.0, 2.5, 0.7, -0.2, 1.1];
        let n = x.len() - 1;
        let y = dct1(&x);
        for k in 0..=n {
            let mut want = x[0] + if k % 2 == 0 { x[n] } else { -x[n] };
            for j in 1..n {
                want += 2.0 * x[j] * (std::f64::consts::PI * (j * k) as f64 / n as f64).cos();
            }
            assert!((y[k] - want).abs() < 1e-14, "{k}");
        }
    }
}
