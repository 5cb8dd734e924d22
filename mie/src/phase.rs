//! [`PhaseFunction`]: the optics of one particle population at one wavelength, as both producers
//! (the Mie path of [`crate::ensemble`] and the crystal tracer of [`crate::crystal`]) return it
//! and as `photometeor-tables` consumes it.
//!
//! # Conventions (docs/physics.md §1)
//! - `bins[k]` is the average of p over bin k of [`PhaseFunction::grid`] in solid angle, in 1/sr,
//!   normalized Σ_k bins_k Ω_k = 1 (to the quadrature's closure for spheres, exactly for crystals).
//! - Energy that leaves exactly forward (the crystals' delta transmission) is inside bin 0;
//!   [`PhaseFunction::forward_delta_fraction`] says how much of the scattered energy that is.
//! - Cross-sections are per particle, in m²; albedo = σ_sca/σ_ext; g = ⟨cos θ⟩.

use serde::{Serialize, Serializer};

use crate::crystal::TraceSummary;
use crate::grid::ThetaGrid;

/// The single-scattering optics of a particle population at one wavelength.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PhaseFunction {
    /// Vacuum wavelength (nm).
    pub wavelength_nm: f64,
    /// Real part n of the refractive index m = n + iκ.
    pub m_re: f64,
    /// Imaginary part κ ≥ 0 of the refractive index.
    pub m_im: f64,
    /// Mean extinction cross-section per particle (m²).
    pub sigma_ext_m2: f64,
    /// Mean scattering cross-section per particle (m²).
    pub sigma_sca_m2: f64,
    /// Single-scattering albedo σ_sca/σ_ext.
    pub albedo: f64,
    /// Asymmetry parameter g = ⟨cos θ⟩.
    pub g: f64,
    /// The θ grid of [`Self::bins`] (serialized as its step, `theta_step_deg`).
    #[serde(rename = "theta_step_deg", serialize_with = "step_of")]
    pub grid: ThetaGrid,
    /// Bin averages of p (1/sr), bin k centred on θ_k = k·Δθ.
    pub bins: Vec<f64>,
    /// Share of the scattered energy that leaves exactly forward (a δ at θ = 0, held in bin 0);
    /// 0 for spheres.
    pub forward_delta_fraction: f64,
    /// p (1/sr) at requested point cosines, in their order (may be empty).
    pub points: Vec<f64>,
    /// How it was computed: node counts and closure for spheres, ray statistics for crystals.
    #[serde(flatten)]
    pub origin: Origin,
}

/// Where a [`PhaseFunction`] came from, with the numbers that say how well it is resolved.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum Origin {
    /// Lorenz–Mie theory averaged over a size distribution.
    Mie(MieOrigin),
    /// Geometric-optics ray tracing plus Fraunhofer diffraction of hexagonal prisms.
    Crystal(CrystalOrigin),
    /// A given lobe (`kind = "hg"`), in closed form.
    Given(GivenOrigin),
    /// A given table (`kind = "tabulated"`), linear in θ between its rows.
    Table(TableOrigin),
}

/// The lobe behind a given [`PhaseFunction`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct GivenOrigin {
    /// The Henyey–Greenstein lobe.
    pub hg: crate::hg::HgLobe,
}

/// The table behind a given [`PhaseFunction`].
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TableOrigin {
    /// The file, as the scene names it.
    pub file: String,
    /// The column read (1-based, after θ).
    pub column: usize,
    /// The table's rows.
    pub rows: usize,
    /// The column's integral over the sphere as given (the normalization found; the bins are
    /// divided by it).
    pub sphere_integral: f64,
}

/// The quadrature behind a sphere population's [`PhaseFunction`].
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MieOrigin {
    /// Σ_k bins_k Ω_k − 1: the quadrature's energy closure (0 when exact).
    pub energy_closure: f64,
    /// Size nodes (in ln r).
    pub sizes: usize,
    /// Gauss nodes per angular panel inside each bin.
    pub nodes_per_panel: usize,
    /// Last relative change seen by the adaptive refinement (0 for fixed counts).
    pub last_change: f64,
}

/// The statistics behind a crystal population's [`PhaseFunction`].
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CrystalOrigin {
    /// Standard error of g from the ray statistics.
    pub g_std_error: f64,
    /// Standard error of each bin (1/sr).
    pub bins_std_error: Vec<f64>,
    /// Share of the scattered energy in the diffraction pattern.
    pub diffraction_fraction: f64,
    /// The geometric-optics trace's energy bookkeeping.
    pub trace: TraceSummary,
}

fn step_of<S: Serializer>(grid: &ThetaGrid, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_f64(grid.step_deg())
}

impl PhaseFunction {
    /// Σ_k bins_k Ω_k: the normalization (1 when exact).
    pub fn integral(&self) -> f64 {
        self.bins
            .iter()
            .zip(self.grid.bin_solid_angles())
            .map(|(p, omega)| p * omega)
            .sum()
    }

    /// A given phase function's optics (a lobe's or a table's, `origin`): `bins` and `g` on
    /// `grid` at `wavelength_nm`, no refractive index (1 + 0i), σ_ext = σ_sca = `extinction_m2`
    /// (albedo 1: a field's given albedo replaces it, as any field's).
    pub fn given(
        wavelength_nm: f64,
        extinction_m2: f64,
        (g, bins, grid): (f64, Vec<f64>, ThetaGrid),
        origin: Origin,
    ) -> Self {
        Self {
            wavelength_nm,
            m_re: 1.0,
            m_im: 0.0,
            sigma_ext_m2: extinction_m2,
            sigma_sca_m2: extinction_m2,
            albedo: 1.0,
            g,
            bins,
            grid,
            forward_delta_fraction: 0.0,
            points: Vec::new(),
            origin,
        }
    }

    /// The sphere quadrature's details, if this came from Mie theory.
    pub fn mie(&self) -> Option<&MieOrigin> {
        match &self.origin {
            Origin::Mie(m) => Some(m),
            Origin::Crystal(_) | Origin::Given(_) | Origin::Table(_) => None,
        }
    }

    /// The ray statistics, if this came from the crystal tracer.
    pub fn crystal(&self) -> Option<&CrystalOrigin> {
        match &self.origin {
            Origin::Crystal(c) => Some(c),
            Origin::Mie(_) | Origin::Given(_) | Origin::Table(_) => None,
        }
    }
}
