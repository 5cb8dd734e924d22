//! `photometeor._native`: the Rust side of the `photometeor` Python package.
//!
//! A thin layer over the library crates, one module per layer of the data path, each function
//! doing what one CLI command does (so Python and the CLI give the same numbers):
//!
//! - [`sphere`] holds `mie` (one sphere at given angles, vectorised over x; `photometeor mie`),
//!   `refractive_index` and `size_parameter` (the physical layer);
//! - [`phase`] holds `phase` (a size distribution of spheres per wavelength; `photometeor phase`)
//!   and `crystal_phase` (ice crystals and snow by ray tracing; a scene's ice or snow field);
//! - [`bake`] holds `bake_scene` (`photometeor bake`) and `load_bake` (a bake directory read with
//!   every check of `photometeor-format`), which `photometeor/__init__.py` wraps in its
//!   `Bake` class.
//!
//! Every function parses and checks its arguments before any work starts (a `ValueError` naming
//! the value and its allowed range, [`errors`]), releases the GIL while it computes, and hands
//! its results to numpy as owned arrays (moved, not copied). Conventions are the library's: θ
//! in degrees with θ = 0 forward, m = n + iκ with κ ≥ 0, radii in µm, wavelengths in nm,
//! cross-sections in m², phase functions in 1/sr normalized ∫ p dΩ = 1.

mod bake;
mod errors;
mod phase;
mod sphere;

use pyo3::prelude::*;

/// The compiled half of photometeor; import ``photometeor`` instead.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(sphere::mie, m)?)?;
    m.add_function(wrap_pyfunction!(sphere::refractive_index, m)?)?;
    m.add_function(wrap_pyfunction!(sphere::size_parameter, m)?)?;
    m.add_function(wrap_pyfunction!(phase::phase, m)?)?;
    m.add_function(wrap_pyfunction!(phase::crystal_phase, m)?)?;
    m.add_function(wrap_pyfunction!(bake::bake_scene, m)?)?;
    m.add_function(wrap_pyfunction!(bake::load_bake, m)?)?;
    m.add_function(wrap_pyfunction!(bake::scene_toml, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
