//! The error every check of a frame's or a model's parameters returns ([`FrameError`], its
//! message naming the value and the allowed range) and how such a message shows a number
//! ([`Shown`]).

/// Bad frame parameters, named with their allowed range.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct FrameError(pub String);

pub(crate) use grid::Shown;
