//! The photometeor bake: a scene → its multiple-scattering tables on disk.
//!
//! The flow: a TOML [`scene::Scene`] (validated, plain data) and a quality preset make a
//! [`plan::BakePlan`]; [`bake::run`] computes each field's [`mie::PhaseFunction`] per
//! wavelength (Mie spheres, the crystal tracer, or a given lobe or table), turns them into Ams_n and F_n per RGB channel
//! (`photometeor-tables`), and writes four EXRs per field (the tables and the side tables the
//! render models read: single scattering per wavelength, Poisson mixtures, Biri's kernel) and
//! `manifest.json` (`photometeor-format`). Unchanged fields come from the [`cache`]; [`shard`]
//! splits a bake over a batch scheduler's tasks and merges them. [`compare`] measures a bake
//! against a reference bake, [`validate`] against theory it did not come from.
//!
//! This is the only crate that calls the solver. Progress is reported through
//! [`progress::Progress`], which the caller implements (the CLI draws bars; tests stay silent).

#![warn(missing_docs)]

pub mod bake;
pub mod cache;
pub mod compare;
pub mod error;
pub mod phase_table;
pub mod plan;
pub mod progress;
pub mod scene;
pub mod shard;
pub mod validate;

pub use bake::{BakeReport, crystal_stream, run};
pub use error::BakeError;
pub use plan::{BakePlan, Knobs};
pub use progress::{Progress, Silent};
pub use scene::{Field, FieldKind, Quality, Scene, SceneError};
