//! The error every check of a frame's or a model's parameters returns ([`FrameError`], its
//! message naming the value and the allowed range) and how such a message shows a number
//! ([`Shown`]).

/// Bad frame parameters, named with their allowed range.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct FrameError(pub String);

/// A number as an error message shows it: plain decimals where they are
/// short (`0.5`, `-1`, `2000`), scientific notation where they are not
/// (`1e-300`, `1e308`), `NaN` and `inf` as Rust writes them.
pub(crate) struct Shown(pub f64);

impl std::fmt::Display for Shown {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let x = self.0;
        if !x.is_finite() || x == 0.0 || (1e-4..1e7).contains(&x.abs()) {
            write!(f, "{x}")
        } else {
            write!(f, "{x:e}")
        }
    }
}
