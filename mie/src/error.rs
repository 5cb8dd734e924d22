//! Typed errors: each names the offending value and the range that was expected.

use thiserror::Error;

pub use ::grid::Shown;

/// Everything the single-particle layer can refuse.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum MieError {
    /// A real-valued input lies outside the range the solver is validated for.
    #[error("{name} = {} is outside the allowed range {range}", Shown(*value))]
    OutOfRange {
        /// Name of the input, with its unit where it has one.
        name: &'static str,
        /// The value given.
        value: f64,
        /// The allowed range, as text.
        range: &'static str,
    },
    /// Options that do not choose exactly one size distribution (see
    /// [`crate::distribution::DistributionOptions`]).
    #[error("{0}")]
    Options(String),
    /// The absorbing part of the refractive index was negative.
    #[error(
        "imaginary refractive index κ = {0} is negative; photometeor uses m = n + iκ with κ ≥ 0 (absorbing)"
    )]
    NegativeKappa(f64),
    /// m = 1 exactly scatters nothing, so no phase function exists.
    #[error("refractive index m = 1 + 0i scatters no light; the phase function is undefined")]
    NoScattering,
    /// A wavelength outside a refractive-index table.
    #[error(
        "{material} refractive index: wavelength {wavelength_nm} nm is outside the tabulated range [{min_nm}, {max_nm}] nm"
    )]
    WavelengthOutOfTable {
        /// The material and its data source.
        material: &'static str,
        /// The wavelength asked for, nm.
        wavelength_nm: f64,
        /// Shortest tabulated wavelength, nm.
        min_nm: f64,
        /// Longest tabulated wavelength, nm.
        max_nm: f64,
    },
    /// A list that must not be empty was.
    #[error("{0} is empty; give at least one value")]
    Empty(&'static str),
    /// Adaptive refinement did not reach the requested tolerance.
    #[error(
        "{what} did not converge to tolerance {tolerance} within the node limit (last change {last_change})"
    )]
    NotConverged {
        /// The quadrature that was refined.
        what: &'static str,
        /// The requested tolerance on the relative change.
        tolerance: f64,
        /// The relative change of the last doubling.
        last_change: f64,
    },
}

impl From<grid::GridError> for MieError {
    fn from(e: grid::GridError) -> Self {
        match e {
            grid::GridError::BadStep { step_deg, range } => MieError::OutOfRange {
                name: "angle step Δθ (degrees)",
                value: step_deg,
                range,
            },
        }
    }
}

/// Returns `Ok(value)` when `value` is finite and inside `[lo, hi]`.
pub(crate) fn check_range(
    name: &'static str,
    value: f64,
    lo: f64,
    hi: f64,
    range: &'static str,
) -> Result<f64, MieError> {
    if value.is_finite() && value >= lo && value <= hi {
        Ok(value)
    } else {
        Err(MieError::OutOfRange { name, value, range })
    }
}
