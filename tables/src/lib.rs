//! Multiple-scattering tables (Riley et al. 2004 §4.2): a phase function given as bin averages
//! on a uniform θ grid → Legendre coefficients χ_l → Ams_n (χ_l^n, Funk–Hecke) and F_i.
//!
//! - [`grid`]: [`grid::ThetaGrid`], the uniform θ grid (K = 180°/Δθ + 1 bins), its edges and
//!   bin solid angles.
//! - [`legendre`]: exact bin integrals of P_l, χ_l from bin averages and bin averages from
//!   χ_l, and a fast Legendre ↔ point-value transform (Chebyshev conversion + DCT via rustfft)
//!   with its slow reference.
//!
//! Work in progress (issue 3): Ams_n, F_i, spectral → RGB and the bake follow.

pub mod ams;
pub mod grid;
pub mod legendre;
