//! Max, Schussman, Miyazaki, Iwasaki & Nishita 2004, "Diffusion and Multiple Anisotropic
//! Scattering for Global Illumination in Clouds": the diffusion approximation in the dense
//! core, Poisson-weighted multiple anisotropic scattering at the tenuous edges (`--model max`).
//!
//! # Where it runs
//! Steps 1–4 below ([`cpu::light`]) depend on the sun, the sky, the cloud and the tables, not
//! on the camera: they run on the CPU (all cores) and give a [`cpu::Lighting`]. Steps 5–6, the
//! final gather, are the per-view part: [`cpu::gather`] on the CPU, or [`gpu::Renderer`] (one
//! compute invocation per pixel, the same march in f32, `gather.wgsl`), which a moving camera
//! repeats from the same lighting. `photometeor render --model max` gathers on the GPU unless
//! `--cpu`. The solve and the sweeps stay on the CPU: they are sequential along their
//! direction (the sweeps) or a multigrid hierarchy (the solve), and they run once per light.
//!
//! # The model, as [`cpu::render`] computes it
//! 1. **Reduced sunlight** (Eq. 2): the fraction T_sun(x) of the sunlight left at every voxel
//!    centre after the volume, per channel, by an upwind sweep through the grid along the
//!    light's direction of travel (each voxel's optical depth is that of the point one layer
//!    back, interpolated bilinearly, plus the trapezoid of β_ext over the step), times
//!    S_atm(y), the sunlight the atmosphere leaves at the voxel's height (Riley Eq. 12, as the
//!    other models).
//! 2. **First-scattered sources** (Eqs. 5, 6): Q_0 = β_sca E T_sun/(4π) and
//!    Q_1 = g β_sca E T_sun l/(4π), with E the sun's irradiance and l its direction of travel
//!    (a collimated sun is one direction bin of the paper's 96), plus the skylight: the sky
//!    model's radiance (Eqs. 11–15, seen from the box's mid-height) from
//!    [`crate::lighting::sky::SKY_DIRECTIONS`] equal-solid-angle directions (the paper's 96 cube bins), each
//!    reduced through the grid by its own sweep, adds β_sca S and g β_sca F_sky, S its mean
//!    over the sphere and F_sky its flux over 4π.
//! 3. **Diffusion** (Eqs. 4, 7) per channel on the voxels of optical depth β_ext h ≥
//!    [`crate::lighting::lattice::MIN_DIFFUSION_VOXEL_DEPTH`] ([`crate::lighting::diffusion`]; the thinner fringe a grid's
//!    interpolation leaves, down to 10⁻¹⁹ of the core, would stall the solver), with
//!    κ_tr = β_ext (σ_tr/σ_t), the bake's `transport_factor` mixed over the fields by their
//!    extinction, solved to [`Settings::tolerance`] by multigrid-preconditioned CG.
//! 4. **Clear-air propagation** (§3, `[render.max] clear_air_iterations`, default 1 as the
//!    paper): for each sky direction a second sweep carries the light the clouds send out (α
//!    times I_0, the skylight and the sun scattered into that direction) across empty voxels
//!    into other parts of the cloud, where it joins the incident light; then the diffusion is
//!    solved again. The paper renders viewing cubes at the empty border voxels; the sweep is
//!    the same idea along 32 directions. A part's own light never comes back to it: light
//!    that re-enters after less than [`cpu::MIN_CLEAR_AIR_STEPS`] of clear air is dropped
//!    (the sweep's interpolation smears a silhouette's light that far).
//! 5. **Final gather** (§4) along each pixel's ray in steps of half a voxel, front to back:
//!    - a voxel's share in the *dense* treatment emits α(I_0 + S + Ams_1(θ) E T_sun): the
//!      diffusion solution, the reduced skylight scattered as if isotropic, and exact single
//!      scattering of the reduced sun with the exact phase function (the bake's Ams_1);
//!    - its share in the *edge* treatment joins the ray's current low-density segment of
//!      optical depth D, which scatters (e^{−D(1−α)} − e^{−D}) [M(D, θ) E T_sun + I_0 + S]: the
//!      Poisson-weighted orders i ≥ 1 (Eqs. 8, 9) of the bake's M(D, θ) = Σ q_i Ams_i/(1 − q_0)
//!      applied to the reduced sun, and to the diffuse light I_0 + S as isotropic incident
//!      radiance (M integrates to 1); α^i weights order i, which sums to the factor shown;
//!    - the share is w_edge = clamp(1.5 − τ_v/T, 0, 1), τ_v the voxel's optical depth β_ext h
//!      (green) and T = [`Settings::threshold`]: all edge below T/2, all dense above 3T/2,
//!      linear between (the paper's "density dependent interpolation of the two").
//! 6. The pixel is composed with the air, sun disk and ground as the other slicing models
//!    ([`crate::riley`]); the ground is lit through the volume's T_sun along the sun's ray.
//!
//! # Where this departs from the paper
//! - **The edge segment grows step by step instead of being cut at T.** The paper evaluates
//!   a whole low-density segment at its optical midpoint and notes the artefacts where two
//!   segments join into one. Here each step adds its increment G(D + δ) − G(D) of the segment's
//!   scattered light (G(D) = (e^{−D(1−α)} − e^{−D}) M(D, θ), evaluated with the light at the
//!   step), seen through the transmittance to the segment's entry, and the segment's depth is
//!   carried on scaled by w_edge, so a dense voxel ends it gradually. The image is then
//!   continuous in T and in the density; a segment over one uniform light sums exactly to
//!   the paper's G(D_j).
//! - **Incident light on the edges**: the paper renders a viewing cube of the whole scene at
//!   each segment's centre. Here the edge sees the reduced sun exactly and the rest of the
//!   cloud as the isotropic diffuse radiance I_0 at the point (which the diffusion solution
//!   knows), without a cube; so like the paper it counts part of the multiply-scattered light
//!   both in M and in I_0.
//! - **Skylight** is scattered as if isotropic in the final gather (its directions enter the
//!   diffusion's Q_1); so is the light that crossed clear air.
//!
//! Units: radiance per unit solar irradiance outside the atmosphere (1/sr) per channel.

pub mod cpu;
pub mod gpu;

use std::time::Instant;

use serde::{Deserialize, Serialize};

use runtime::gpu::{Gpu, GpuTables, TexelFormat};

use crate::checks::FrameError;
use crate::frame::Frame;
use crate::gpu::RenderError;
use crate::lighting::Place;
use crate::model::{Device, Job, Model, Need, Pass, RenderResult, Rendered, image_need};

/// `--model max`.
pub struct Max;

/// Bytes the lighting takes per voxel at its peak (the optics, the reduced sun and sky, the
/// diffusion problems and the multigrid solver's vectors, the clear-air sweeps): measured
/// 484 B with the grid's 16 (cumulus_dawn, RSS at 128 × 59 × 128 voxels less 64 × 29 × 64).
pub const MEMORY_PER_VOXEL: u64 = 500;

impl Model for Max {
    const NAME: &'static str = "max";
    const ABOUT: &'static str = "Max et al. 2004: a diffusion solve in the dense core, \
        Poisson-weighted multiple anisotropic scattering from the bake's M(D, θ) at the edges; \
        the lighting on the CPU (all cores), the final gather on the GPU or --cpu";
    const TEXELS: TexelFormat = TexelFormat::F32;
    const GPU: bool = true;
    type Settings = Settings;
    type Renderer = gpu::Renderer;

    fn check(s: &Settings) -> Result<(), FrameError> {
        s.check()
    }

    fn check_frame(s: &Settings, frame: &Frame) -> Result<(), FrameError> {
        frame.sunlight_only(Self::NAME, false)?;
        frame.check_view().and_then(|()| s.check())
    }

    fn memory(_: &Settings, pixels: u64, dims: [usize; 3]) -> Vec<Need> {
        let voxels = crate::model::voxels(dims);
        vec![
            Need {
                what: "the lighting (optics, reduced light, sky, diffusion solve)",
                bytes: voxels * MEMORY_PER_VOXEL,
                setting: "[render] grid_resolution".into(),
            },
            image_need("the gathered image", pixels, 48),
        ]
    }

    fn renderer(gpu: &Gpu, tables: &GpuTables) -> Option<gpu::Renderer> {
        Some(gpu::Renderer::new(gpu, tables))
    }

    fn render_cpu(s: &Settings, job: &Job) -> Result<Rendered, RenderError> {
        let lighting = cpu::light_with(job.tables, job.frame, s, job.progress)?;
        let start = Instant::now();
        let (image, report) = cpu::gather(job.tables, job.frame, s, &lighting)?;
        let gather = start.elapsed().as_secs_f64();
        Ok(rendered(image, &report, gather, "CPU", job.frame))
    }

    fn render_gpu(s: &Settings, job: &Job, on: Device<gpu::Renderer>) -> RenderResult {
        let (renderer, gpu, tables) = (on.renderer, on.gpu, on.tables);
        let (lighting, reused) = crate::relight::lit(job.lighting, job.frame, s, |_| {
            let on = s.per_sun.on_gpu(gpu).then(|| renderer.per_sun(gpu));
            cpu::light_on(job.tables, job.frame, s, job.progress, on)
        })?;
        let (image, t, largest) =
            renderer.gather(gpu, job.tables, tables, job.frame, s, &lighting)?;
        let mut report = lighting.report.clone();
        report.gather_s = t.upload + t.frame + t.readback;
        report.largest_edge_depth = largest;
        if reused {
            (report.propagation_s, report.diffusion_s, report.clear_air_s) = (0.0, 0.0, 0.0);
        }
        let mut out = rendered(image, &report, report.gather_s, &gpu.describe(), job.frame);
        if reused {
            out.reused_lighting();
        }
        Ok(out)
    }
}

/// The frame with its passes (the lighting's steps, then the gather on `on`) and summary.
fn rendered(
    image: crate::image::Image,
    report: &cpu::MaxReport,
    gather_s: f64,
    on: &str,
    frame: &Frame,
) -> Rendered {
    let lighting_on = if report.on.iter().all(|o| o == "the CPU") {
        format!("the CPU, {} threads", rayon::current_num_threads())
    } else {
        format!(
            "the reduced sunlight on {}, the skylight on {}, the diffusion on {}",
            report.on[0], report.on[1], report.on[2]
        )
    };
    let summary = format!(
        "diffusion + Poisson edges (lighting on {lighting_on}; gather on {on}): {}×{}, \
         grid {:?}: reduced sunlight {:.2} s, diffusion {:.2} s ({} unknowns, {} levels, {:?} \
         CG iterations to residuals {:.1e}/{:.1e}/{:.1e}), clear-air propagation and second \
         solve {:.2} s (mean light across clear air {:.2e}), final gather {gather_s:.2} s; \
         largest edge depth {:.2}",
        image.width,
        image.height,
        frame.grid.dims,
        report.propagation_s,
        report.diffusion_s,
        report.unknowns,
        report.levels,
        report.iterations,
        report.residual[0],
        report.residual[1],
        report.residual[2],
        report.clear_air_s,
        report.clear_air_mean,
        report.largest_edge_depth
    );
    let pass = |name, seconds| Pass { name, seconds };
    Rendered {
        summary,
        image,
        extra: Vec::new(),
        figures: vec![
            ("unknowns", report.unknowns as f64),
            ("CG iterations", report.iterations[1] as f64),
            ("largest edge depth", report.largest_edge_depth),
        ],
        passes: vec![
            pass("reduced light", report.propagation_s),
            pass("diffusion", report.diffusion_s),
            pass("clear air", report.clear_air_s),
            pass("gather", gather_s),
        ],
    }
}

/// The model's settings, `[render.max]`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Settings {
    /// T: the voxel optical depth β_ext h (green) at which the dense (diffusion) treatment
    /// takes over from the edge (Poisson) treatment, > 0. Default 1.
    pub threshold: f64,
    /// Relative residual ‖b − A x‖/‖b‖ the diffusion solve must reach, (0, 0.1]. Default 1e-6.
    #[serde(rename = "diffusion_tolerance")]
    pub tolerance: f64,
    /// Conjugate-gradient iterations allowed, [1, 100000]. Default 500.
    #[serde(rename = "max_diffusion_iterations")]
    pub max_iterations: usize,
    /// Iterations of §3's clear-air propagation (the clouds' light carried across empty voxels
    /// into other parts, then the diffusion solved again), [0, 4]. Default 1, as the paper.
    pub clear_air_iterations: usize,
    /// Where a GPU render runs the per-sun passes (the reduced sunlight's sweep, the skylight's
    /// sweeps and the diffusion solves; §3's clear-air propagation stays on the CPU): "auto"
    /// (the default: the GPU on a real adapter, the CPU on one that emulates a GPU on the
    /// CPU), "gpu" or "cpu". A CPU render runs them on the CPU.
    pub per_sun: Place,
}

impl Default for Settings {
    fn default() -> Self {
        Self {
            threshold: 1.0,
            tolerance: 1e-6,
            max_iterations: 500,
            clear_air_iterations: 1,
            per_sun: Place::Auto,
        }
    }
}

impl Settings {
    /// Checks the settings, naming the key, its value and the allowed range.
    pub fn check(&self) -> Result<(), FrameError> {
        if !(self.threshold.is_finite() && self.threshold > 0.0) {
            return Err(FrameError(format!(
                "threshold = {} is outside the allowed range (0, ∞) (a voxel's \
                 optical depth)",
                crate::checks::Shown(self.threshold)
            )));
        }
        crate::lighting::diffusion::check_settings(self.tolerance, self.max_iterations)?;
        if self.clear_air_iterations > 4 {
            return Err(FrameError(format!(
                "clear_air_iterations = {} is outside the allowed range [0, 4]",
                self.clear_air_iterations
            )));
        }
        Ok(())
    }

    /// The share of a voxel of optical depth `tau_voxel` that the edge treatment takes.
    pub fn edge_share(&self, tau_voxel: f64) -> f64 {
        (1.5 - tau_voxel / self.threshold).clamp(0.0, 1.0)
    }
}
