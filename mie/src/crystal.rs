//! Ice crystals and snow by geometric optics plus Fraunhofer diffraction: the second producer of
//! the phase-function value `tables/` bakes (bin averages, forward-peak fractions, σ_ext,
//! albedo, g), beside the Mie path of [`crate::ensemble`].
//!
//! # Model (docs/physics.md §5; Macke et al. 1996, Takano & Liou 1989)
//! - **Crystal**: a hexagonal prism of aspect ratio AR = L/(2a) (plates AR < 1, columns AR > 1)
//!   and maximum dimension D = max(2a, L); D follows a lognormal distribution (median D_g,
//!   geometric width σ_g; σ_g = 1 is one size).
//! - **Orientation**: random in 3-D: the incident direction is uniform on the sphere in the
//!   crystal's frame; the entry point is uniform on a disc of the bounding radius across it,
//!   misses drawn again, so orientations are weighted by their projected area.
//! - **Geometric optics** ([`trace`]): unpolarized Fresnel (R_s + R_p)/2 with the real part of
//!   the Warren & Brandt 2008 index, total internal reflection, absorption exp(−4πκ ℓ/λ) along
//!   each internal segment. At every interaction the reflected part goes on and the transmitted
//!   part leaves (one path per ray; distorted crystals may score several tilts of a facet,
//!   [`trace`] module docs, "Tilt splitting"); a path stops after 1000 interactions (its
//!   weight reported as lost), and below weight 0.1 it plays Russian roulette ([`trace`]
//!   module docs, "Roulette"): it goes on with probability w/0.1 weighing 0.1, or stops, which
//!   loses no light on average where the earlier cut-off at 10⁻⁴ lost 2.6·10⁻⁵ of it for
//!   columns of AR 2 and 5·10⁻⁵ for rough snow, at 0.62–0.77 of the variance × time.
//!   Light leaving exactly forward (through parallel faces, cos θ > 1 − 10⁻¹²) is the **delta
//!   transmission**, kept as its own number and put into bin 0 only when the table is
//!   assembled.
//! - **Roughness / snow**: Macke's distortion δ: every ray meets its own distorted crystal,
//!   whose facet normals are each tilted once by an angle uniform in [0, δ·90°] about a uniform
//!   azimuth (the facet planes stay where they are). Where the tilts make a ray meet a facet
//!   from the wrong side — an entering ray a facet tilted away from it, the true normal is used;
//!   a ray inside a facet whose tilted surface faces back at it, it cannot leave there and is
//!   totally reflected about the facet's true normal (the slope it would meet next). Snow is
//!   modelled as such distorted prisms (van Diedenhoven et al. 2014's "random ice crystals",
//!   δ = 0.7 by default). Against VD14's g at δ = 0.3 and 0.7 (AR 0.25, 1, 4) all six cases
//!   agree within 0.015 (worst −0.014, AR 4 at δ = 0.7; `tests/crystal.rs` prints the table).
//!   Measured alternatives, each failing at least one case: the true normal (refraction) for
//!   the inside ray too (AR 1, δ = 0.7: +0.024), tilts drawn anew at every interaction (+0.032),
//!   redrawn until they face the ray (+0.039), or tilted anew with total reflection (+0.026).
//! - **Diffraction** carries half of the extinction (Q_ext = 2): the Fraunhofer pattern of the
//!   circle of equal projected area (mean projected area = surface / 4, Cauchy), whose energy
//!   inside angle θ is 1 − J₀(u)² − J₁(u)², u = x sin θ — so its bin averages are exact.
//! - **Combination** per wavelength: σ_ext = 2Ā, σ_sca = Ā (2 − a_GO), P = [Σ_i w_i A_i P_diff,i +
//!   Ā (1 − a_GO) P_GO] / σ_sca, with Ā = Σ_i w_i A_i over the size nodes and a_GO the absorbed
//!   share of the geometric-optics energy, traced at the area-weighted mean dimension (in the
//!   visible κ ≈ 10⁻⁹, so a_GO ≲ 10⁻⁴ and its size dependence is negligible).
//! - **Statistics**: rays come in chunks of 16384 with their own seeded streams, summed in
//!   order (the result is bit-identical for any thread count); standard errors of each bin and
//!   of g come from the spread between chunks.

pub mod geometry;
pub mod trace;

use serde::{Deserialize, Serialize};

pub use geometry::Prism;
pub use trace::{Sampling, Trace, TraceResult, TraceSettings, trace};

use crate::distribution::SizeDistribution;
use crate::error::MieError;
use crate::grid::ThetaGrid;
use crate::phase::{CrystalOrigin, Origin, PhaseFunction};
use crate::refractive::Material;

/// A population of ice crystals.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CrystalField {
    /// L/(2a): < 1 plates, > 1 columns.
    pub aspect_ratio: f64,
    /// Median maximum dimension D_g (µm).
    pub max_dimension_um: f64,
    /// Geometric standard deviation of D (1 = one size).
    pub sigma_g: f64,
    /// Macke distortion δ ∈ [0, 1] (0 pristine; snow 0.7).
    pub roughness: f64,
}

impl CrystalField {
    /// Checks every parameter against its allowed range.
    pub fn validated(self) -> Result<Self, MieError> {
        let check = |name, value: f64, ok: bool, range| {
            if ok && value.is_finite() {
                Ok(())
            } else {
                Err(MieError::OutOfRange { name, value, range })
            }
        };
        check(
            "aspect ratio L/(2a)",
            self.aspect_ratio,
            (0.01..=100.0).contains(&self.aspect_ratio),
            "[0.01, 100]",
        )?;
        check(
            "maximum dimension (µm)",
            self.max_dimension_um,
            (1.0..=1e5).contains(&self.max_dimension_um),
            "[1, 100000] µm (geometric optics needs crystals ≫ λ)",
        )?;
        check(
            "σ_g of the maximum dimension",
            self.sigma_g,
            (1.0..=4.0).contains(&self.sigma_g),
            "[1, 4] (1 = one size)",
        )?;
        check(
            "roughness δ",
            self.roughness,
            (0.0..=1.0).contains(&self.roughness),
            "[0, 1]",
        )?;
        Ok(self)
    }

    /// Size nodes (D in µm) and number fractions.
    fn sizes(&self, count: usize) -> (Vec<f64>, Vec<f64>) {
        if self.sigma_g <= 1.0 {
            return (vec![self.max_dimension_um], vec![1.0]);
        }
        let q = SizeDistribution::Lognormal {
            median_radius_um: self.max_dimension_um,
            sigma_g: self.sigma_g,
        }
        .quadrature(count, 1e-3);
        (q.radius_um, q.weight)
    }
}

/// The energy bookkeeping of the trace, without the histogram.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TraceSummary {
    /// Rays that hit the crystal.
    pub rays: u64,
    /// Energy fraction reflected at the first (external) interaction.
    pub external_reflection: f64,
    /// Energy fraction leaving exactly forward through parallel faces (delta transmission).
    pub delta: f64,
    /// Energy fraction absorbed inside the crystal.
    pub absorbed: f64,
    /// Energy fraction of paths stopped by the interaction cut-off.
    pub lost: f64,
    /// Energy fraction the bins and the delta hold, as traced.
    pub scattered: f64,
    /// Energy the Russian roulette added less what it took (zero in expectation; bins, delta,
    /// absorbed and lost sum to 1 plus this).
    pub roulette: f64,
    /// Asymmetry parameter g of the geometric-optics part alone (delta included).
    pub g_geometric: f64,
}

/// Fraunhofer energy of a circle (u = x sin θ) inside u: 1 − J₀(u)² − J₁(u)².
fn encircled_energy(u: f64) -> f64 {
    let (j0, j1) = (libm::j0(u), libm::j1(u));
    1.0 - j0 * j0 - j1 * j1
}

/// Whether a crystal of distortion `roughness` is traced to its noise target without the bins
/// within 1° of 180° (θ_k > 179°), as all are without those within 1° of 0°. Rough crystals
/// keep a narrow backscatter spike there that few rays carry (snow, δ = 0.7, one trace of
/// 48 M rays: the half-bin 179.91–180° at 0.0394 /sr ± 7 %, the two bins below it 0.0281 ±
/// 1.3 %, the next three 0.0262 ± 0.6 %, 177.9–179° 0.0255 ± 0.3 %): a tally of rare heavy
/// hits, whose spread no sample of chunks shows before many have been seen, so at a preset's
/// rays the chunks understate those bins' noise (two draft rgb3 bakes of snow: one bin at
/// 179.64° 79 % apart, the reported rms 3.6 % where the pair's was 4.8 %). Their error is
/// stated beside the presets' (docs/scenes.md, "Presets, measured"). Pristine crystals' spike is strong
/// and well sampled.
pub fn noise_skips_pole(roughness: f64) -> bool {
    roughness > 0.0
}

/// The bins a noise figure counts: 1° ≤ θ_k, and θ_k ≤ 179° if `skip_pole`
/// ([`noise_skips_pole`]).
pub fn noise_bins(grid: ThetaGrid, skip_pole: bool) -> impl Iterator<Item = usize> {
    let last = if skip_pole { 179.0 } else { 180.0 };
    (0..grid.len()).filter(move |&k| (1.0..=last).contains(&grid.theta_deg(k)))
}

/// The rms over the [`noise_bins`] of each bin's relative standard error (a bin with no value
/// counts as 1: nothing reached it yet).
pub fn relative_noise(grid: ThetaGrid, bins: &[f64], std_error: &[f64], skip_pole: bool) -> f64 {
    let rel: Vec<f64> = noise_bins(grid, skip_pole)
        .map(|k| {
            if bins[k] > 0.0 && std_error[k].is_finite() {
                std_error[k] / bins[k]
            } else {
                1.0
            }
        })
        .collect();
    (rel.iter().map(|r| r * r).sum::<f64>() / rel.len().max(1) as f64).sqrt()
}

/// Energy fraction of the diffraction of a circle with size parameter x in each bin of `grid`
/// (forward hemisphere, normalized there).
fn diffraction_bin_energy(x: f64, grid: ThetaGrid) -> Vec<f64> {
    let total = encircled_energy(x);
    // The encircled energy at each bin edge once (two Bessel functions apiece), up to 90°:
    // bins beyond hold none.
    let quarter = std::f64::consts::FRAC_PI_2;
    let at_edges: Vec<f64> = grid
        .edge_theta_rad()
        .iter()
        .map(|&t| {
            if t < quarter {
                encircled_energy(x * t.sin())
            } else {
                total
            }
        })
        .collect();
    at_edges
        .windows(2)
        .map(|e| ((e[1] - e[0]) / total).max(0.0))
        .collect()
}

/// How many rays a crystal phase function is traced with, and how they are drawn
/// ([`trace`] module docs, "Sampling").
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rays {
    /// Rays that hit the crystal; with a `target`, the first round's.
    pub count: u64,
    /// If set: after the first round, [`crystal_phase`] carries the trace on
    /// ([`CrystalTracer::carry_on`]) until the rms over the bins θ ≥ 1° of each bin's relative
    /// standard error (from the spread between chunks; a bin no ray reached counts as 100 %)
    /// is at most this, or until `max_count` rays.
    pub target: Option<f64>,
    /// The most rays a `target` may take.
    pub max_count: u64,
    /// Seed of the random streams or scrambles.
    pub seed: u64,
    /// Pseudo-random or scrambled Sobol'.
    pub sampling: Sampling,
    /// Directions in the prism's fundamental domain only.
    pub symmetric: bool,
    /// Tilts scored per facet a path first meets, distorted crystals only ([`trace`] module
    /// docs, "Tilt splitting"); 1 = one.
    pub tilt_splits: u32,
    /// Rays per chunk of the trace ([`crate::crystal::trace::TraceSettings::chunk_rays`]):
    /// two chunks are the fewest rays a trace to a `target` takes.
    pub chunk_rays: u64,
}

impl Rays {
    /// `count` plain Monte Carlo rays over the whole sphere of directions.
    pub fn random(count: u64, seed: u64) -> Self {
        Self {
            count,
            target: None,
            max_count: count,
            seed,
            sampling: Sampling::Random,
            symmetric: false,
            tilt_splits: 1,
            chunk_rays: Trace::CHUNK_RAYS,
        }
    }
}

/// Phase function of `field` at `wavelength_nm` on `grid`, from the traced `rays` (carried on
/// to `rays.target` if it is set).
pub fn crystal_phase(
    field: &CrystalField,
    wavelength_nm: f64,
    grid: ThetaGrid,
    rays: Rays,
) -> Result<PhaseFunction, MieError> {
    let mut tracer = CrystalTracer::new(field, wavelength_nm, grid, rays)?;
    loop {
        let phase = tracer.phase();
        let Some(target) = rays.target else {
            return Ok(phase);
        };
        let origin = phase.crystal().expect("a crystal's phase function");
        let skip_pole = noise_skips_pole(field.roughness);
        let noise = relative_noise(grid, &phase.bins, &origin.bins_std_error, skip_pole);
        if noise <= target || !tracer.carry_on(noise / target) {
            return Ok(phase);
        }
    }
}

/// One wavelength's trace of a crystal field, with its diffraction: a phase function at any
/// point of the trace ([`CrystalTracer::phase`]), so a caller can trace several wavelengths on
/// until a statistic of their mixture is reached (the bake's noise target per RGB channel).
pub struct CrystalTracer {
    wavelength_nm: f64,
    grid: ThetaGrid,
    m: num_complex::Complex64,
    mean_area: f64,
    diffraction: Vec<f64>,
    g_diffraction: f64,
    trace: Trace,
    max_chunks: u64,
}

impl CrystalTracer {
    /// Checks the field, computes the diffraction and traces the first `rays.count` rays (its
    /// target is not used here: see [`CrystalTracer::carry_on`]).
    pub fn new(
        field: &CrystalField,
        wavelength_nm: f64,
        grid: ThetaGrid,
        rays: Rays,
    ) -> Result<Self, MieError> {
        let field = field.validated()?;
        let m = Material::Ice.refractive_index(wavelength_nm, -20.0)?;
        let wavelength_um = wavelength_nm / 1000.0;
        let (dims, weights) = field.sizes(32);
        let areas: Vec<f64> = dims
            .iter()
            .map(|&d| Prism::new(field.aspect_ratio, d).surface_area() / 4.0)
            .collect();
        let mean_area: f64 = areas.iter().zip(&weights).map(|(a, w)| a * w).sum();
        let d_ref: f64 = dims
            .iter()
            .zip(&areas)
            .zip(&weights)
            .map(|((d, a), w)| d * a * w)
            .sum::<f64>()
            / mean_area;

        // Diffraction, size by size, weighted by projected area.
        let mut diffraction = vec![0.0; grid.len()];
        let mut g_diffraction = 0.0;
        for (&a, &w) in areas.iter().zip(&weights) {
            let radius = (a / std::f64::consts::PI).sqrt();
            let x = 2.0 * std::f64::consts::PI * radius / wavelength_um;
            for (k, e) in diffraction_bin_energy(x, grid).into_iter().enumerate() {
                diffraction[k] += w * a / mean_area * e;
                g_diffraction += w * a / mean_area * e * grid.theta_deg(k).to_radians().cos();
            }
        }

        // Geometric optics at the area-weighted mean dimension (µm), absorption 4πκ/λ per µm.
        let prism = Prism::new(field.aspect_ratio, d_ref);
        let alpha = 4.0 * std::f64::consts::PI * m.im / wavelength_um;
        let settings = TraceSettings::new(rays.count, rays.seed, field.roughness)
            .sampled(rays.sampling, rays.symmetric)
            .split(rays.tilt_splits)
            .chunked(rays.chunk_rays);
        let mut trace = Trace::new(prism, m.re, alpha, grid, settings);
        let chunk = trace.chunk_rays();
        trace.run_to(rays.count.div_ceil(chunk).max(1));
        Ok(Self {
            wavelength_nm,
            grid,
            m,
            mean_area,
            diffraction,
            g_diffraction,
            trace,
            max_chunks: rays.max_count.max(rays.count).div_ceil(chunk),
        })
    }

    /// Carries the trace on by `ratio`² of its rays, 10 % over (noise ∝ 1/√rays, `ratio` the
    /// noise over its target), at least one chunk and at most 4× per call (a first round's empty
    /// bins count as 100 % and overstate the need), up to `Rays::max_count`. False once the
    /// trace is at that limit and nothing was traced.
    pub fn carry_on(&mut self, ratio: f64) -> bool {
        let chunks = self.trace.chunks();
        if chunks >= self.max_chunks {
            return false;
        }
        let need = (chunks as f64 * 1.1 * ratio * ratio).ceil() as u64;
        self.trace
            .run_to(need.clamp(chunks + 1, 4 * chunks).min(self.max_chunks));
        true
    }

    /// Chunks of [`Rays::chunk_rays`] rays traced so far.
    pub fn chunks(&self) -> u64 {
        self.trace.chunks()
    }

    /// Carries the trace on to `chunks` in all, up to `Rays::max_count`; false if it traced
    /// nothing (already there, or at that limit).
    pub fn run_to(&mut self, chunks: u64) -> bool {
        let to = chunks.min(self.max_chunks);
        if to <= self.trace.chunks() {
            return false;
        }
        self.trace.run_to(to);
        true
    }

    /// The phase function of the rays traced so far: geometric optics and diffraction combined
    /// per wavelength (module docs, "Combination"), with each bin's standard error.
    pub fn phase(&self) -> PhaseFunction {
        let grid = self.grid;
        let k_len = grid.len();
        let t = self.trace.result();
        let go_scattered = t.scattered();
        let sigma_diff = self.mean_area;
        // The light the crystal scatters is what it does not absorb: 1 − absorbed − lost, where
        // the bins' own sum also carries the roulette's zero-mean imbalance (`trace` module
        // docs, "Roulette"), which could put the albedo above 1. The bins give the shape.
        let sigma_go = self.mean_area * (1.0 - t.absorbed - t.lost);
        let sigma_sca = sigma_diff + sigma_go;
        let (f_diff, f_go) = (sigma_diff / sigma_sca, sigma_go / sigma_sca);
        let mut bins = Vec::with_capacity(k_len);
        let mut bins_std_error = Vec::with_capacity(k_len);
        for k in 0..k_len {
            // Ω_k as the cosine difference, not `ThetaGrid::bin_solid_angles` (which avoids its
            // ~1e-13 relative cancellation): the crystal tables of compute version 5 were made
            // this way, and the next change of the crystal tracer's numbers moves both together.
            let (lo, hi) = grid.bin_edges_deg(k);
            let omega =
                2.0 * std::f64::consts::PI * (lo.to_radians().cos() - hi.to_radians().cos());
            let mut go = t.bin_energy[k] / go_scattered;
            if k == 0 {
                go += t.delta / go_scattered;
            }
            bins.push((f_diff * self.diffraction[k] + f_go * go) / omega);
            bins_std_error.push(f_go * t.bin_energy_std_error[k] / go_scattered / omega);
        }
        const UM2_TO_M2: f64 = 1e-12;
        PhaseFunction {
            wavelength_nm: self.wavelength_nm,
            m_re: self.m.re,
            m_im: self.m.im,
            sigma_ext_m2: 2.0 * self.mean_area * UM2_TO_M2,
            sigma_sca_m2: sigma_sca * UM2_TO_M2,
            albedo: sigma_sca / (2.0 * self.mean_area),
            g: f_diff * self.g_diffraction + f_go * t.g,
            grid,
            bins,
            forward_delta_fraction: f_go * t.delta / go_scattered,
            points: Vec::new(),
            origin: Origin::Crystal(CrystalOrigin {
                g_std_error: f_go * t.g_std_error,
                bins_std_error,
                diffraction_fraction: f_diff,
                trace: TraceSummary {
                    rays: t.rays_hit,
                    external_reflection: t.external_reflection,
                    delta: t.delta,
                    absorbed: t.absorbed,
                    lost: t.lost,
                    scattered: go_scattered,
                    roulette: t.roulette,
                    g_geometric: t.g,
                },
            }),
        }
    }
}
