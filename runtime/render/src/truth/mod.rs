//! The path-traced truth (`render --model truth`): an unbiased spectral Monte Carlo solution of
//! the radiative transfer equation on the same scene — volumes, camera, sun, atmosphere,
//! ground and lights — that the fast models approximate, so that each of them can be measured
//! against it (`photometeor compare-render`, `docs/truth.md`).
//!
//! # Transport
//! - **Spectral.** Every camera path carries n = min(N, [`MAX_CARRIED`]) of the bake's N
//!   wavelengths — all three of an `rgb3` bake — by hero-wavelength sampling (Wilkie, Nawaz,
//!   Droske, Weidlich & Hanika 2014): one uniform number u places the m-th at u + m/n (mod 1)
//!   in the CDF of q_j = (w_Rj + w_Gj + w_Bj)/3 (from the manifest's channel weights), so
//!   each is marginally drawn with probability q_j. The first, the hero, makes every sampling
//!   decision with its own phase function, σ_ext and albedo (`<field>.single.exr`); for each
//!   carried wavelength m the path keeps f_m/p_0 (its contribution over the hero's sampling
//!   density) and p_m/p_0 (how likely m's own sampling was to make the same path). Its
//!   radiance L_m then adds w_cm L_m f_m / (q_m Σ_k p_k) to channel c: the one-sample balance
//!   heuristic over the carried wavelengths (Veach 1997 §9.2), which keeps every weight below
//!   n times what m's own sampling would give, whatever the spread of phase functions, σ_ext
//!   and Rayleigh β with λ. A pixel's R, G, B are then the same weighted sums over
//!   wavelengths that the tables are (Σ_j w_cj L_j), and every path feeds every channel.
//!   `wavelengths_per_path = 1` is one wavelength per path (its contribution w_cj L_j / q_j),
//!   which the photon estimator of the slab tests uses.
//! - **Volumes.** Free paths in the density grid by delta tracking (Woodcock et al. 1965) with
//!   one majorant for every wavelength, μ̄ = max_j Σ_f max ρ_f · σ_ext,f,j, decided by the
//!   hero; a null collision changes wavelength m's density by (μ̄ − μ_m)/(μ̄ − μ_0). At a real
//!   collision the scattering field is chosen by the hero's share of β_sca and f_m gains
//!   β_sca,f,m/β_ext,0 (Riley et al. 2004 Eqs. 3 and 6: the mixture of fields is the
//!   β_sca-weighted mix of their phase functions). Transmittance for next-event estimation by
//!   ratio tracking (Cramer 1978; Novák et al. 2014) on tentative points shared by the carried
//!   wavelengths, with Russian roulette once the largest falls below 1/20.
//! - **Air.** An exponential Rayleigh atmosphere β(y) = β_sl(λ) e^{−y/H} with the sky model's
//!   β_sl and scale height H (Riley et al. 2004 §4.1, Eq. 1 for the phase function), sampled
//!   analytically (the optical depth along a ray is closed-form), competing with the volumes:
//!   the collision is the nearer of the two independent free paths. β_sl(λ) interpolates the
//!   three per-channel values log-linearly in ln λ at the channels' mean wavelengths (so an
//!   `rgb3` bake gets exactly β_sl of its channel). `[sky] enabled = false` turns the air off.
//! - **Sun.** Collimated, as in the fast models (Riley Eq. 18), with its irradiance per
//!   channel, attenuated by the air (and by the volumes, by ratio tracking). A camera ray that
//!   leaves the scene without a collision inside the 0.5° disk sees I_s/Ω_disk, as the fast
//!   models draw it.
//! - **Ground.** A Lambertian plane at y = 0 of albedo `[ground] albedo` (default 0.1, 0 is
//!   black), the same ground as the fast models'.
//! - **Lights.** Point lights of intensity I (per channel, the image's unit × m²/sr), spot
//!   lights with a hard cone; I/r² times the transmittance.
//! - **Media and occluders** (`[[medium]]`, `[[occluder]]`, the scenes of `--model biri`):
//!   a homogeneous medium adds its field's density N inside its box (or everywhere) to the
//!   grid's, tracked by the same delta tracking (the majorant gains the densest medium's
//!   extinction; a medium filling the scene is tracked out to 30 free paths beyond
//!   everything in it, where e^{−30} of the light is left); occluders are Lambertian surfaces
//!   like the ground that end free paths and block shadow rays.
//! - **Estimators.** Next-event estimation toward the sun and every light at every scattering
//!   vertex, weighted by the exact tabulated phase function (the bin the angle falls into).
//!   All light sources here are δ distributions in direction (the sun is collimated, lights
//!   are points), which phase sampling can never hit: the balance-heuristic MIS weight of the
//!   next-event sample is 1 and the combined estimator is next-event estimation alone.
//! - **Guided continuations.** A droplet's forward lobe (the 550 nm cloud: 589 /sr in its first
//!   bin, 4π∫p² dΩ = 1426) makes the next-event weight huge for the rare path whose direction
//!   comes within a degree of the sun: the light that reaches a point by small-angle forward
//!   scattering. Plain phase sampling finds those directions rarely and pays for them with
//!   fireflies. So at a volume vertex the continuation is drawn, with probability
//!   ε = [`GUIDE_SHARE`], from the phase function's lobe about the sun direction instead of
//!   about the path, and weighted by the one-sample MIS ratio p(d, ω)/q(ω) with
//!   q = (1 − ε) p(d, ω) + ε p(sun, ω)/(1 − f) (f the forward δ, which only the unguided branch
//!   draws: its weight is 1/(1 − ε)). Unbiased for every ε < 1; on the DISORT slabs it turns the
//!   cloud's camera-side radiances from heavy-tailed (18–35 % low at 5·10⁴ paths) into ones
//!   that agree within 3σ, and it cuts the variance of HG double scattering 27-fold.
//!   Air and ground vertices are guided the same way ([`Tracer::continue_guided`]: the lobe
//!   of a field drawn uniformly, q = (1 − ε) own(ω) + ε (1/F) Σ_f p_f(sun, ω)/(1 − f_f), own
//!   the Rayleigh phase function or the cosine): the air under a cirrus of 100 µm columns
//!   (first bin ≈ 10⁴ /sr) is lit by the sun's forward-scattered aureole, which a Rayleigh
//!   continuation finds rarely and pays for with a weight of up to 10⁴: unguided, the halo
//!   scene's truth at 16 384 spp had 1 % of its pixels as fireflies holding 14 % of the
//!   image's light; at 4 096 spp its median pixel read 9 % below the guided one's and two
//!   seeds' image sums were 2.7 % apart (guided: 0.03 %).
//! - **Paths** end when they leave the scene (black space), on a black ground, by Russian
//!   roulette once the largest weight n·f_m/Σ_k p_k falls below [`ROULETTE_WEIGHT`]
//!   (survivors carry exactly that weight, never more), or after [`MAX_BOUNCES`] scatterings (a safety bound far beyond any
//!   table order). **Splitting**: a camera path whose largest weight n·W_m exceeds
//!   [`SPLIT_WEIGHT`] becomes k = ⌈n·W_m⌉ branches ([`MAX_SPLIT`] at most) of 1/k of its
//!   weight, each followed on from the vertex and direction just drawn (with the roulette, a
//!   weight window; unbiased). The guided continuations' MIS ratio multiplies the weight by
//!   ≈ 1/(1 − ε) at every unguided bounce and by a small number at a guided one: without
//!   splitting, a path of hundreds of scatterings ends tiny almost always and huge (1.11²⁰⁰)
//!   very rarely, and in conservative slabs at τ = 16 the radiances came out 2–5 % low with an
//!   understated σ (docs/truth.md).
//!
//! # Determinism
//! Sample s of pixel p draws from its own random stream, seeded by (seed, p, s): the image is
//! the same for a given seed whatever the thread count or pass schedule.
//!
//! # Camera
//! One ray through each pixel's centre, as the fast models sample pixels, so images compare
//! pixel for pixel. The camera may sit inside a volume.

mod checks;
pub mod gpu;
mod passes;
pub mod phase;
mod tracer;

use std::f64::consts::PI;
use std::time::Instant;

use glam::DVec3;
use grid::ThetaGrid;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use runtime::gpu::{Gpu, GpuTables, TexelFormat};

use crate::geometry::basis;
use crate::geometry::box_span;
use crate::gpu::RenderError;
use crate::model::{Device, Job, Model, Need, Pass, Progress, RenderResult, Rendered, image_need};
use crate::objects::Light;
use crate::{
    camera::SUN_DIAMETER_DEG, checks::FrameError, frame::Frame, image::Image, volume::DensityGrid,
    volume::MAX_FIELDS,
};
use phase::{PhaseSampler, rayleigh, rotate, sample_rayleigh};
use runtime::Tables;

use checks::*;
use passes::*;
use tracer::*;

pub use checks::check;
pub use passes::std_error;
pub use tracer::{MAX_CARRIED, MAX_SPLIT, ROULETTE_WEIGHT, Rng, SPLIT_WEIGHT, Tracer};

/// Scatterings after which a path is cut (none of our scenes comes near it: a path through a
/// cloud of optical depth 100 scatters ~10⁴ times).
pub const MAX_BOUNCES: usize = 1_000_000;

/// The default share of guided continuations (module docs, "Estimators").
pub const GUIDE_SHARE: f64 = 0.1;

/// Samples per pixel allowed.
pub const SPP_RANGE: (usize, usize) = (1, 1 << 20);

/// The path tracer's settings, `[render.truth]` (its lights, media and occluders are the
/// frame's).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Settings {
    /// Samples (paths) per pixel, [`SPP_RANGE`].
    pub spp: usize,
    /// Seed of the random streams.
    pub seed: u64,
    /// Stop early once the noise (see [`TruthImage::noise`]) is at or below this, [0, 1); 0:
    /// run every sample.
    #[serde(rename = "noise")]
    pub target_noise: f64,
    /// Scatterings after which a path ends, [1, [`MAX_BOUNCES`]]; 0: [`MAX_BOUNCES`]. 1 is
    /// exact single scattering.
    pub max_scatterings: usize,
    /// Wavelengths each camera path carries, 1…[`MAX_CARRIED`]; 0: the default (all of an
    /// `rgb3` bake's three, else [`MAX_CARRIED`]). 1 is one wavelength per path.
    pub wavelengths_per_path: usize,
    /// Stop after the pass that passes this many seconds of tracing, whatever the samples
    /// taken, [0, 10⁷]; 0: no time bound.
    pub max_seconds: f64,
}

impl Default for Settings {
    fn default() -> Self {
        Self {
            spp: 256,
            seed: 1,
            target_noise: 0.0,
            max_scatterings: 0,
            wavelengths_per_path: 0,
            max_seconds: 0.0,
        }
    }
}

/// The largest optical depth the tracer takes on along a straight line through the scene's
/// volumes, media or haze: a conservative path through τ scatters ~τ² times, and beyond this
/// its paths would meet [`MAX_BOUNCES`] (biased) after hours each.
pub const MAX_OPTICAL_DEPTH: f64 = 1000.0;

/// `--model truth`.
pub struct Truth;

impl Model for Truth {
    const NAME: &'static str = "truth";
    const ABOUT: &'static str = "an unbiased spectral Monte Carlo path tracer of the same scene \
        on the GPU (the CPU reference, all cores, with --cpu), the reference every fast model is \
        measured against; its EXR adds stderr.R/G/B and stderr.Y, each pixel's standard error \
        per channel and of its luminance";
    const TEXELS: TexelFormat = TexelFormat::F32;
    const GPU: bool = true;
    const REFERENCE: bool = true;
    const PERIODIC: bool = true;
    type Settings = Settings;
    type Renderer = gpu::Renderer;

    fn check(s: &Settings) -> Result<(), FrameError> {
        check_settings(s)
    }

    fn check_frame(s: &Settings, frame: &Frame) -> Result<(), FrameError> {
        check(frame, s)?;
        crate::objects::check_lights(&frame.lights, &frame.occluders)
    }

    fn memory(_: &Settings, pixels: u64, _dims: [usize; 3]) -> Vec<Need> {
        // Per pixel: its ray (24 B), Σx and Σx² per channel (48), T_vol (8), the mean and
        // standard error (24) and the image (16): measured 110 B.
        vec![image_need("the sums and image", pixels, 120)]
    }

    fn renderer(gpu: &Gpu, _: &GpuTables) -> Option<gpu::Renderer> {
        Some(gpu::Renderer::new(gpu))
    }

    fn render_cpu(s: &Settings, job: &Job) -> Result<Rendered, RenderError> {
        let truth = render(job.tables, job.frame, s, job.progress)?;
        Ok(rendered(
            truth,
            &format!("the CPU ({} threads)", rayon::current_num_threads()),
        ))
    }

    fn render_gpu(s: &Settings, job: &Job, on: Device<gpu::Renderer>) -> RenderResult {
        let (renderer, g) = (on.renderer, on.gpu);
        let on_cpu = |why: String| -> Result<Rendered, RenderError> {
            let truth = render(job.tables, job.frame, s, job.progress)?;
            Ok(rendered(
                truth,
                &format!("the CPU ({} threads): {why}", rayon::current_num_threads()),
            ))
        };
        if let Some(what) = gpu::unsupported(job.frame) {
            return on_cpu(format!("the GPU truth does not trace {what} yet"));
        }
        if g.adapter.get_info().device_type == wgpu::DeviceType::Cpu {
            // A software adapter runs on the same cores as the CPU truth, at half its speed or
            // less (docs/truth.md, "On the GPU").
            return on_cpu(format!(
                "the adapter, {}, is software on the same cores",
                g.describe()
            ));
        }
        let truth = gpu::render(renderer, g, job.tables, job.frame, s, job.progress)?;
        Ok(rendered(truth, &g.describe()))
    }
}

/// A traced frame as the models' [`Rendered`], traced on `on` (for the summary).
fn rendered(truth: TruthImage, on: &str) -> Rendered {
    let mut summary = format!(
        "path-traced truth: {}×{}, {} spp, noise {:.2} % (median relative standard error, \
         green, volume pixels), {:.1} s, {:.3} M paths/s on {on}",
        truth.image.width,
        truth.image.height,
        truth.spp,
        truth.noise * 100.0,
        truth.seconds,
        truth.paths_per_second / 1e6,
    );
    if truth.dropped > 0 {
        let all = (truth.image.width * truth.image.height * truth.spp) as f64;
        summary += &format!(
            "; {} of its {all:.3e} samples were not finite (f32) and counted as 0",
            truth.dropped
        );
    }
    let mut extra: Vec<(String, Vec<f32>)> = (0..3)
        .map(|c| {
            (
                format!("stderr.{}", ["R", "G", "B"][c]),
                truth.std_error.iter().map(|e| e[c]).collect(),
            )
        })
        .collect();
    extra.push(("stderr.Y".into(), truth.luma_error.clone()));
    Rendered {
        summary,
        figures: vec![
            ("spp", truth.spp as f64),
            ("noise", truth.noise),
            ("paths per second", truth.paths_per_second),
            // The noise falls as 1/√(time): the time this estimator needs for 1 %.
            (
                "seconds to 1 % noise",
                truth.seconds * (truth.noise / 0.01).powi(2),
            ),
        ],
        image: truth.image,
        extra,
        passes: vec![Pass {
            name: "trace",
            seconds: truth.seconds,
        }],
    }
}

/// A path-traced frame with its per-pixel Monte Carlo standard error.
#[derive(Debug, Clone)]
pub struct TruthImage {
    /// Mean radiance per pixel (and the volume's transparency T_vol, from a fine ray march of
    /// the green channel's β_ext, as the fast models define it).
    pub image: Image,
    /// Standard error of each pixel's mean, per channel (same unit).
    pub std_error: Vec<[f32; 3]>,
    /// Standard error of each pixel's mean luminance (Rec. 709), from the samples' own
    /// luminance: a path carries every channel, so they are correlated, and the channels'
    /// errors combined as if independent understate it (`stderr.Y` in the EXR).
    pub luma_error: Vec<f32>,
    /// Samples per pixel taken.
    pub spp: usize,
    /// Median over the pixels where the volume matters (1 − T_vol > 1 %) of the green
    /// channel's relative standard error; over all lit pixels if there are none.
    pub noise: f64,
    /// Seconds spent tracing.
    pub seconds: f64,
    /// Paths traced per second.
    pub paths_per_second: f64,
    /// Samples that were not finite and counted as 0 (the GPU truth's f32 arithmetic; the
    /// CPU truth has none).
    pub dropped: u64,
}

/// Renders `frame` by path tracing (module docs); `progress` is told after every pass.
pub fn render(
    tables: &Tables,
    frame: &Frame,
    settings: &Settings,
    progress: &dyn Progress,
) -> Result<TruthImage, FrameError> {
    check(frame, settings)?;
    let tracer = Tracer::new(tables, frame, settings)?;
    let (w, h) = (frame.width, frame.height);
    let axes = frame.camera.axes().expect("checked");
    // Each pixel's origin and direction: the eye's, or an orthographic camera's point.
    let rays: Vec<(DVec3, DVec3)> = (0..w * h)
        .map(|p| frame.camera.pixel(axes, (p % w, p / w), (w, h)))
        .collect();
    let transparency: Vec<f64> = rays
        .par_iter()
        .map(|&(o, d)| tracer.transparency(o, d))
        .collect();
    let mut passes = Passes::new(settings, w, transparency, progress);
    while let Some(batch) = passes.next_batch(None) {
        let done = passes.done;
        passes.acc.par_iter_mut().enumerate().for_each(|(p, a)| {
            for s in done..done + batch {
                let mut rng = Rng::stream(settings.seed, p as u64, s as u64);
                let l = tracer.radiance(rays[p].0, rays[p].1, &mut rng);
                for c in 0..3 {
                    a.0[c] += l[c];
                    a.1[c] += l[c] * l[c];
                }
                a.2 += passes::luminance(l).powi(2);
            }
        });
        if passes.end_pass(batch) {
            break;
        }
    }
    Ok(passes.image())
}
