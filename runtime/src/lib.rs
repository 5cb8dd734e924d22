//! The renderer's side of photometeor's tables (issue 6, first part): [`Tables::open`] reads a
//! bake directory and checks it beyond the file formats — every field's EXR against its manifest
//! entry (name, Δθ, N, F_i), the grid, each row's normalization and sign, and F_i's range and
//! order — and [`sample`] evaluates the tables exactly as the WGSL sampling functions are
//! specified to: `ams(field, n, cos θ)` linear in θ and in fractional n, `forward_fraction(field,
//! n)`, and the spatial mix of several fields (Riley et al. 2004 Eq. 6).
//!
//! [`gpu`] uploads the tables with the WGSL module; [`render`] renders Riley's model with them,
//! on the GPU and as a CPU reference.

pub mod gpu;
pub mod load;
pub mod render;
pub mod sample;

pub use load::{FieldTable, LoadError, Tables};
