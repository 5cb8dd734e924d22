//! Multiple-scattering tables (Riley et al. 2004 §4.2): a phase function given as bin averages
//! on a uniform θ grid → Legendre coefficients χ_l → Ams_n (χ_l^n, Funk–Hecke) and F_i.
//!
//! - [`grid`]: [`grid::ThetaGrid`], the uniform θ grid (K = 180°/Δθ + 1 bins), its edges and
//!   bin solid angles.
//! - [`legendre`]: exact bin integrals of P_l, χ_l from bin averages and bin averages from
//!   χ_l, and a fast Legendre ↔ point-value transform (Chebyshev conversion + DCT via rustfft)
//!   with its slow reference.
//! - [`ams`]: Ams_n and F_n by a forward-delta split and a blurred Legendre series, n_iso(ε),
//!   and the per-wavelength mixture an RGB channel is.
//! - [`spectral`]: the wavelengths of a bake and their CIE × solar → linear sRGB weights.
//! - [`exr_io`], [`manifest`]: the EXR contract and `manifest.json`, read and written.
//! - [`scene`], [`bake`]: TOML scenes (only what a scene names is modelled) and the cached,
//!   atomic bake of their tables.

pub mod ams;
pub mod bake;
pub mod exr_io;
pub mod grid;
pub mod legendre;
pub mod manifest;
pub mod scene;
pub mod spectral;
pub mod validate;
