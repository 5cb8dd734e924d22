//! Single-particle optics for photometeor: Mie spheres (water drops, ice spheres) and ice
//! crystals and snow by geometric-optics ray tracing, each returned as one [`PhaseFunction`]
//! per wavelength.
//!
//! The flow: a refractive index ([`refractive`]) and a size give a [`Sphere`] (m, x); its
//! [`MieCoefficients`] a_n, b_n give efficiencies ([`Efficiencies`]) and, through the batched
//! kernel in [`amplitude`], the amplitudes S1, S2 at any angles. A size distribution
//! ([`distribution`]) and a wavelength list turn many spheres into one [`PhaseFunction`] per
//! wavelength ([`ensemble`]): σ_ext, σ_sca, albedo, g and the phase function averaged inside
//! the bins of a [`ThetaGrid`] — what `photometeor-tables` consumes.
//!
//! Ice crystals and snow come from [`crystal`]: geometric-optics ray tracing of hexagonal prisms
//! plus Fraunhofer diffraction, yielding the same [`PhaseFunction`]. Closed forms that need no
//! Mie sum (size parameter, rainbow and halo angles) are in [`theory`].
//!
//! Conventions (docs/physics.md §1): θ = 0 is forward, μ = cos θ; m = n + iκ with κ ≥ 0;
//! x = 2πr/λ; phase functions are normalized ∫ p dΩ = 1 (1/sr); units live in names.

#![warn(missing_docs)]

pub mod amplitude;
pub mod crystal;
pub mod distribution;
pub mod ensemble;
pub mod error;
pub mod grid;
pub mod hg;
pub mod phase;
pub use ::grid::quadrature;
pub mod reference;
pub mod refractive;
pub mod sphere;
pub mod tabulated;
pub mod theory;

pub use amplitude::{FoldedAngles, SphereTerms, amplitudes, exact_cosine_deg};
pub use distribution::{DistributionOptions, SizeDistribution, SizeQuadrature};
pub use ensemble::{BulkRequest, NodeCounts, bulk_phase};
pub use error::MieError;
pub use grid::{GridError, ThetaGrid};
pub use phase::{CrystalOrigin, GivenOrigin, MieOrigin, Origin, PhaseFunction, TableOrigin};
pub use refractive::Material;
pub use sphere::{Efficiencies, MieCoefficients, Sphere};
pub use theory::size_parameter;

/// Normalized phase function p = (|S1|² + |S2|²) / (2π x² Q_sca) in 1/sr.
pub fn phase_from_amplitudes(
    s1: num_complex::Complex64,
    s2: num_complex::Complex64,
    x: f64,
    q_sca: f64,
) -> f64 {
    (s1.norm_sqr() + s2.norm_sqr()) / (2.0 * std::f64::consts::PI * x * x * q_sca)
}
