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
//! - [`fast`]: point values of Σ_l a_l P_l(μ) on the cosine grid μ_j = cos(jπ/N) and the inverse
//!   (interpolation at those nodes), by Legendre ↔ Chebyshev conversion plus a DCT-I done with
//!   rustfft.
//! - [`reference`]: the slow, obviously-correct counterparts the fast and exact kernels are
//!   tested against: direct recurrence summation, Gauss–Legendre quadrature, and per-bin
//!   Gauss–Legendre integration of P_l.
//!
//! # Normalization
//! θ is the scattering angle, μ = cos θ. A phase function p(μ) is normalized
//! ∫_{4π} p dΩ = 2π ∫_{-1}^{1} p dμ = 1 (units 1/sr; isotropic p = 1/(4π)). Its expansion is
//!
//!   p(μ) = Σ_l (2l + 1)/(4π) χ_l P_l(μ),   χ_l = 2π ∫_{-1}^{1} p(μ) P_l(μ) dμ,
//!
//! so χ_0 = 1 and χ_1 = g (the asymmetry parameter); Henyey–Greenstein has χ_l = g^l.
//! Funk–Hecke: the spherical convolution of two zonal functions has χ_l = χ_l^a χ_l^b, hence
//! Ams_n ↔ χ_l^n (Riley et al. 2004 §4.2). Plain series in [`fast`] and [`reference`] are
//! written f(μ) = Σ_l a_l P_l(μ) with no weights; a_l = (2l + 1)/(4π) χ_l.
//!
//! # Angle order
//! Bins follow [`ThetaGrid`]: k = 0 forward (μ = 1) to k = K − 1 backward (μ = −1); bin k
//! covers [θ_k − Δθ/2, θ_k + Δθ/2] ∩ [0°, 180°], and a bin value is the average of p over the
//! bin's solid angle Ω_k = 2π Δμ_k. The cosine grid of [`fast`] runs the same way:
//! μ_j = cos(jπ/N), j = 0 forward; with N = 180°/Δθ its nodes are the θ_k of the table grid.
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
//! - See [`fast`] for the Legendre ↔ Chebyshev conversion and the conditioning of point values
//!   near μ = ±1.

pub mod bins;
pub mod fast;
pub mod reference;

pub use bins::{
    BinIntegrals, bin_averages_from_coefficients, bin_integrals, coefficients_from_bin_rows,
    coefficients_from_bins,
};
pub use fast::{
    chebyshev_to_legendre, coefficients_from_cosine_grid, evaluate_on_cosine_grid,
    legendre_to_chebyshev,
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
    /// A cosine grid needs at least two nodes (N ≥ 1).
    #[error("cosine grid needs N ≥ 1 intervals (at least 2 samples), got {samples} samples")]
    TooFewSamples {
        /// Samples supplied (N + 1).
        samples: usize,
    },
}
