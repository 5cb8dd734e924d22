//! What an engine links to use photometeor's tables: [`Tables::open`] reads a bake directory
//! and checks it beyond the file formats — every field's EXR against its manifest entry (name,
//! Δθ, N, F_i), the grid, each row's normalization and sign, and F_i's range and order — and
//! [`sample`] evaluates the tables exactly as the WGSL sampling functions are specified to:
//! `ams(field, n, cos θ)` linear in θ and in fractional n, `forward_fraction(field, n)`, and the
//! spatial mix of several fields (Riley et al. 2004 Eq. 6).
//!
//! [`gpu`] uploads the tables with the WGSL module (`tables.wgsl`); [`shaders`] translates it
//! to HLSL, GLSL, MSL and SPIR-V; [`export`] writes the tables in other engines' formats
//! (Bevy, Mitsuba, KTX2, NPY); [`uniform`] mirrors WGSL uniform structs as Pod structs whose
//! layout is checked against the shader. The renderers built on this are `photometeor-render`;
//! the bake that writes the tables is `photometeor-bake`, which an engine does not link.

#![warn(missing_docs)]

pub mod export;
pub mod gpu;
pub mod load;
pub mod sample;
pub mod shaders;
pub mod uniform;

pub use load::{FieldTable, LoadError, Spectrum, Tables};
