//! Typed errors: each names the offending value and the range that was expected.

use thiserror::Error;

/// Everything the single-particle layer can refuse.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum MieError {
    /// A real-valued input lies outside the range the solver is validated for.
    #[error("{name} = {value} is outside the allowed range {range}")]
    OutOfRange {
        name: &'static str,
        value: f64,
        range: &'static str,
    },
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
        material: &'static str,
        wavelength_nm: f64,
        min_nm: f64,
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
        what: &'static str,
        tolerance: f64,
        last_change: f64,
    },
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
