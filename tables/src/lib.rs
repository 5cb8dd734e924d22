//! Multiple-scattering tables (Riley et al. 2004 §4.2): one [`mie::PhaseFunction`] per
//! wavelength → Legendre coefficients χ_l → Ams_n (χ_l^n, Funk–Hecke) and F_n → RGB channels.
//!
//! - [`legendre`]: exact bin integrals of P_l on the [`grid::ThetaGrid`], χ_l from bin averages
//!   and bin averages from χ_l, with their slow references.
//! - [`ams`]: [`ams::AmsSeries`] (Ams_n and F_n of one phase function by a forward-delta split
//!   and a blurred Legendre series, n_iso(ε)) and [`ams::AmsMixture`], the per-wavelength
//!   mixture an RGB channel is.
//! - [`spectral`]: the wavelengths of a bake and their CIE × solar → linear sRGB weights.
//! - [`biri`]: Biri et al. 2006's point-light in-scattering kernel for a tabulated phase
//!   function — its exact primitive over the angle and the paper's quartic fit.
//!
//! The file format of a bake is `photometeor-format`; scenes, the bake planner and its cache
//! are `photometeor-bake`.

#![warn(missing_docs)]

pub mod ams;
pub mod biri;
pub mod legendre;
pub mod spectral;

use thiserror::Error;

/// What the table layer refuses.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum TablesError {
    /// A mixture of no phase functions.
    #[error("a mixture of Ams tables needs at least one part")]
    EmptyMixture,
    /// A mixture weight that is negative or not finite (or a zero total).
    #[error(
        "mixture weight {weight} of part {index} is outside the allowed range: finite, ≥ 0, with a positive sum"
    )]
    MixtureWeight {
        /// The part.
        index: usize,
        /// Its weight (or the total, for a zero sum).
        weight: f64,
    },
    /// Parts of a mixture on different θ grids.
    #[error("mixture part {index} has Δθ = {step_deg}°, expected the first part's {expected_deg}°")]
    GridMismatch {
        /// The part.
        index: usize,
        /// Its grid step.
        step_deg: f64,
        /// The first part's step.
        expected_deg: f64,
    },
}
