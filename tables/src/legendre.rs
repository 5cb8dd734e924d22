//! Legendre machinery for zonal phase functions on the sphere.
//!
//! # Overview
//! A phase function reaches `tables` as bin averages on a [`ThetaGrid`]. This module maps it to
//! Legendre coefficients χ_l and back, and evaluates Legendre series at points:
//!
//! - [`bins`]: exact bin integrals W_lk = ∫_bin k P_l(μ) dμ ([`BinIntegrals`] streams them one
//!   degree at a time; [`bin_integrals`] stores them), χ_l of the piecewise-constant function
//!   ([`coefficients_from_bins`], [`coefficients_from_bin_rows`]) and bin averages of a series
//!   ([`bin_averages_from_coefficients`]). This is the exact path the tables use: a table value
//!   is a true bin average of the series, whatever the degree.
//! - [`reference`]: the slow, obviously-correct counterparts the exact kernels are tested
//!   against: P_l by recurrence, Gauss–Legendre quadrature, and per-bin Gauss–Legendre
//!   integration of P_l.
//!
//! # Why no fast transform
//! A Legendre ↔ point-value transform on the cosine grid (Alpert–Rokhlin Legendre ↔ Chebyshev
//! conversion plus a DCT) gives point values, not the bin averages the tables hold, and its
//! conversion costs (L + 1)²/4 per series. Measured on the bake's own step (Henyey–Greenstein
//! g = 0.85 at 0.18°, L = 5630, 26 orders, release build, one run on this 2-core machine): the
//! exact bin averages of all 26 rows took 15 ms (the series stops per order where χ_l^n has
//! vanished), the fast transform 96–99 ms for the point values alone, before they could be
//! turned into bin averages. The renderers never transform: they interpolate the tables. So the
//! fast transform was removed; it does not pay for bin-averaged tables.
//!
//! # Normalization
//! θ is the scattering angle, μ = cos θ. A phase function p(μ) is normalized
//! ∫_{4π} p dΩ = 2π ∫_{-1}^{1} p dμ = 1 (units 1/sr; isotropic p = 1/(4π)). Its expansion is
//!
//!   p(μ) = Σ_l (2l + 1)/(4π) χ_l P_l(μ),   χ_l = 2π ∫_{-1}^{1} p(μ) P_l(μ) dμ,
//!
//! so χ_0 = 1 and χ_1 = g (the asymmetry parameter); Henyey–Greenstein has χ_l = g^l.
//! Funk–Hecke: the spherical convolution of two zonal functions has χ_l = χ_l^a χ_l^b, hence
//! Ams_n ↔ χ_l^n (Riley et al. 2004 §4.2).
//!
//! # Angle order
//! Bins follow [`ThetaGrid`]: k = 0 forward (μ = 1) to k = K − 1 backward (μ = −1); bin k
//! covers [θ_k − Δθ/2, θ_k + Δθ/2] ∩ [0°, 180°], and a bin value is the average of p over the
//! bin's solid angle Ω_k = 2π Δμ_k.
//!
//! # Numerical hazards
//! - Legendre polynomials come from Bonnet's three-term recurrence
//!   (l + 1) P_{l+1} = (2l + 1) μ P_l − l P_{l−1}, which is forward-stable for |μ| ≤ 1 at any
//!   degree (errors grow like √l, not exponentially); derivatives from
//!   P'_{l+1} = (l + 1) P_l + μ P'_l, which damps errors in P' by |μ| ≤ 1 each step.
//! - The textbook antiderivative (P_{l+1} − P_{l−1})/(2l + 1) cancels catastrophically near the
//!   poles: at the first edge of a 0.18° grid (1 − μ = 1.2e-6) it subtracts two numbers ≈ 1 to
//!   get ≈ 3e-6, losing ~6 digits. [`bins`] uses the same identity rearranged,
//!   ∫_μ^1 P_l = (P_{l−1} − P_{l+1})/(2l + 1) = sin²θ P'_l(μ)/(l(l + 1)), which has no
//!   cancellation and is exactly 0 at both poles (so Σ_k W_lk telescopes to 2δ_l0).

pub mod bins;
pub mod reference;

pub use bins::{
    BinIntegrals, bin_averages_from_coefficients, bin_integrals, coefficients_from_bin_rows,
    coefficients_from_bins,
};
pub use grid::{GridError, ThetaGrid};

use thiserror::Error;

/// Inputs of the wrong shape for a Legendre transform.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum LegendreError {
    /// A bin vector whose length is not the grid's K.
    #[error("bin vector {row} has {got} values, expected K = {expected} (one per θ_k of the grid)")]
    BinCount {
        /// Which row (0 for a single vector).
        row: usize,
        /// Values supplied.
        got: usize,
        /// K of the grid.
        expected: usize,
    },
    /// Fewer coefficients than the requested degree needs.
    #[error("{got} coefficients supplied, expected at least l_max + 1 = {expected}")]
    CoefficientCount {
        /// Coefficients supplied.
        got: usize,
        /// l_max + 1.
        expected: usize,
    },
}
