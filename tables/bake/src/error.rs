//! Everything a bake, a comparison or a validation can refuse; each variant names the value,
//! field or file.

use std::path::PathBuf;

use thiserror::Error;

use crate::scene::SceneError;

/// What went wrong in the bake crate.
#[derive(Debug, Error)]
pub enum BakeError {
    /// The scene file is malformed or out of range.
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// The spectral sampling cannot be built.
    #[error("building the RGB channel weights: {0}")]
    Spectral(#[from] tables::spectral::SpectralError),
    /// The θ grid step is not valid.
    #[error(transparent)]
    Grid(#[from] grid::GridError),
    /// The solver refused a field's inputs.
    #[error("field {field:?}{context}: {source}")]
    Mie {
        /// The field.
        field: String,
        /// Where: wavelength, radii.
        context: String,
        /// The solver's error.
        source: mie::MieError,
    },
    /// A field's wavelengths cannot be mixed into a channel.
    #[error("field {field:?}: {source}")]
    Mixture {
        /// The field.
        field: String,
        /// The table layer's error.
        source: tables::TablesError,
    },
    /// An EXR could not be written or read.
    #[error(transparent)]
    Exr(#[from] format::IoError),
    /// The manifest could not be written or read.
    #[error(transparent)]
    Manifest(#[from] format::ManifestError),
    /// The bake directory is locked by another bake, or its commit failed.
    #[error(transparent)]
    Commit(#[from] format::CommitError),
    /// The operating system refused a file operation.
    #[error("{}: {op}: {source}", path.display())]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// What was being done.
        op: &'static str,
        /// The underlying error.
        source: std::io::Error,
    },
    /// Shard directories that cannot be merged (one missing, foreign, repeated or damaged).
    #[error("{0}")]
    Shards(String),
    /// Two bakes, or a bake and its manifest, do not fit together.
    #[error("{0}")]
    Incompatible(String),
    /// An argument outside its allowed range.
    #[error("{name} = {value} is outside the allowed range {range}")]
    OutOfRange {
        /// The argument.
        name: &'static str,
        /// Its value.
        value: f64,
        /// The allowed range.
        range: &'static str,
    },
}
