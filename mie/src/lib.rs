//! Single-particle optics for photometeor.
//!
//! The flow: a refractive index ([`refractive`]) and a size give a [`Sphere`] (m, x); its
//! [`MieCoefficients`] a_n, b_n give efficiencies ([`Efficiencies`]) and, through the batched
//! kernel in [`amplitude`], the amplitudes S1, S2 at any angles. A size distribution
//! ([`distribution`]) and a wavelength list turn many spheres into one [`BulkPhase`]
//! per wavelength: σ_ext, albedo, g and the phase function averaged inside the bins of an
//! [`AngleGrid`] — the `PhaseFunction` that `tables/` consumes.
//!
//! Ice crystals and snow come from [`crystal`]: geometric-optics ray tracing of hexagonal prisms
//! plus Fraunhofer diffraction, yielding the same bin-averaged phase-function value.
//!
//! Conventions (physics.md §1): θ = 0 is forward, μ = cos θ; m = n + iκ with κ ≥ 0;
//! x = 2πr/λ; phase functions are normalized ∫ p dΩ = 1 (1/sr); units live in names.

pub mod amplitude;
pub mod crystal;
pub mod distribution;
pub mod ensemble;
pub mod error;
pub mod grid;
pub mod quadrature;
pub mod reference;
pub mod refractive;
pub mod sphere;

pub use amplitude::{FoldedAngles, SphereTerms, amplitudes};
pub use distribution::{SizeDistribution, SizeQuadrature};
pub use ensemble::{BulkPhase, BulkRequest, NodeCounts, bulk_phase};
pub use error::MieError;
pub use grid::AngleGrid;
pub use refractive::Material;
pub use sphere::{Efficiencies, MieCoefficients, Sphere};

/// Normalized phase function p = (|S1|² + |S2|²) / (2π x² Q_sca) in 1/sr.
pub fn phase_from_amplitudes(
    s1: num_complex::Complex64,
    s2: num_complex::Complex64,
    x: f64,
    q_sca: f64,
) -> f64 {
    (s1.norm_sqr() + s2.norm_sqr()) / (2.0 * std::f64::consts::PI * x * x * q_sca)
}
