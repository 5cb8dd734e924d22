//! `--model coupled`: the sunlight's forward peak kept in a beam, the rest of what the beam
//! loses carried by δ-M-scaled discrete-ordinates transport (accelerated by a diffusion solve),
//! both gathered along the eye's rays — the light Riley's buffer drops, no longer lost. A
//! recipe over the grid lighting layer ([`crate::lighting`]): this module says which passes run
//! in which order with which sources; the passes themselves are shared.
//!
//! # Why
//! Riley et al. 2004 §4.3 keep in the light buffer only the forward-scattered share αF of what
//! a slab removes (the continuum update of the light buffer); the rest of the scattered
//! light is gone, which is why `riley` is −17 … −88 % dark at optical depths 8–64
//! (`docs/truth/sweep`). Max et al. 2004 have that light in a diffusion solve but feed it the
//! first-scattered sunlight with its forward peak spread by g alone and show it isotropic.
//!
//! # The model, per sun ([`light::light`]) and per view ([`gather::gather`])
//! The phase function is split into a forward peak and the rest, p = f δ(forward) + (1 − f) p′.
//! With the transport (the default, step 3b) the split is δ-M's (Wiscombe 1977) at the degree L
//! = 4 the transport keeps: f = χ_5, p′'s Legendre moments χ′_l = (χ_l − f)/(1 − f), the χ_l
//! integrated from the tables' Ams_1 per field and channel. With `diffuse = "diffusion"` it is
//! δ-Eddington's (Joseph, Wiscombe & Weinman 1976): f = g² (g from the bake's transport factor
//! 1 − αg), p′ of asymmetry g′ = (g − f)/(1 − f). The transfer equation with p is the one
//! with p′ in a medium of extinction β_ext(1 − αf) and albedo α(1 − f)/(1 − αf).
//! 1. **The beam** at every voxel centre, by an upwind sweep along the light's direction of
//!    travel l ([`crate::lighting::beam`]): intensity I per channel (the fraction of the
//!    sunlight), each step of optical depth τ (trapezoid of β_ext) keeping e^{−τ(1 − αf)}.
//!    This is Riley's continuum update (Eqs. 21–22) with the forward share f in place of F_n,
//!    on the grid instead of half-angle slices, so the lighting does not depend on the view.
//! 2. **Its loss as sources**: per unit volume the beam loses E ΔI/Δs (E the sun's irradiance
//!    times S_atm, Riley Eq. 12); of that loss β_ext(1 − αf) the share α(1 − f)/(1 − αf) is
//!    scattered (the rest absorbed) — the light Riley's buffer drops. It is the first-scattered
//!    source of the δ-scaled medium: Q_0 = (that)/4π and Q_1 = g′ Q_0 l. The skylight adds
//!    β_sca S and g β_sca F_sky as in `max` ([`crate::lighting::sky::reduced_sky`]).
//! 3. **Diffusion** ([`crate::lighting::diffusion`], Max Eqs. 4, 7; Marshak's boundary) per channel with
//!    κ_tr = β_ext(1 − αg), which is also the δ-scaled medium's σ′_t(1 − α′g′): the scaling
//!    changes the sources, not the operator. Then the flux J = Q_1/κ_tr − D∇I_0 per voxel
//!    ([`crate::lighting::diffusion::flux`]) and the P1 radiance I_0 + I_1·ω, I_1 = 3J.
//!
//!    3b. **Transport** ([`crate::lighting::transport`], `diffuse = "transport"`, the default): the δ-M-scaled
//!    transfer equation of the diffuse light solved by discrete ordinates on the same grid —
//!    `directions` directions of equal solid angle (a Fibonacci set), each swept upwind
//!    (short characteristics: bilinear in the layer behind, the emission linear over the
//!    step), the radiance kept per voxel as spherical-harmonic moments to degree 4, which is
//!    all the scattering by the degree-4 p′ needs of it. The sources are step 2's, the sunlit
//!    one now with p′'s whole angular shape, Q(ω) = Q_0 p′(ω·l). Source iteration starts
//!    from step 3's P1 radiance; each round's change of the mean radiance, scattered, is
//!    diffused by the same solver and added (diffusion synthetic acceleration, Alcouffe
//!    1977), until a round changes the mean radiance by less than `transport_tolerance`.
//!    Why: the P1 radiance is right where the cloud is diffusive (a plane slab τ ≥ 8 within
//!    1–7 %) but a cloud's light leaves it from its outer transport mean free path, where it
//!    is not: on the soft ball (τ_tr ≤ 4.5 through the centre even at τ 64) the diffusion
//!    alone is 26–40 % dark from the side and the sun's side, and its forward views 42–76 %
//!    bright (δ-Eddington's f = g² ≈ 0.74 keeps light scattered by up to ~20° in the beam).
//! 4. **The gather** along each pixel's ray in half-voxel steps, front to back, through the
//!    δ-scaled extinction β_ext(1 − αf) (what the forward peak scatters still travels towards
//!    the eye); per unit of true optical depth a point sends towards the eye ω
//!    α [p(θ) I E + (1 − f) I_0 + (g − f) I_1·ω + (1 − f) S]: the beam scattered by the exact
//!    phase function (Ams_1), the P1 radiance scattered by p′ (its first moment g′), the
//!    skylight's mean S likewise; with the transport, the diffuse term is
//!    (1 − f) Σ_l χ′_l Σ_m Y_lm(ω) φ_lm, its moments scattered by p′ towards the eye. The beam term is Nakajima & Tanaka's (1988) TMS correction:
//!    the single scattering of the δ-scaled beam with the untruncated phase function, so
//!    glories, fogbows and rainbows keep their exact shape; the thin limit is exact single
//!    scattering (f cancels to first order in τ). That phase function is blurred by the
//!    scatterings of the forward peak the beam and the eye's ray kept ([`peak`]: Ams_1
//!    convolved with a Poisson number of Gaussian peaks fitted to the table's forward lobe,
//!    its optical depth counted along the beam and the ray; with the transport): the glory's
//!    rings, 0.5° apart, wash out as the truth's do under the droplets' ~1° diffraction peak;
//!    beyond 90°–120° of scattering the rest of δ-M's forward cone (to ~12°) blurs it too, so
//!    the fogbow's 4° bow softens as the truth's does. The ground and the air below the grid are
//!    lit through the δ-scaled extinction (the forward peak's light still arrives; the halo
//!    scene's clear-sky pixels read −4.7 % lit through the true one, +2.3 % through this), and
//!    the ground and the sky behind are seen through the δ-scaled extinction too (what the forward peak scatters out of a smooth
//!    background it scatters in from next to it; the rainbow scene read −26.4 % through the
//!    true extinction, +1.8 % through the δ-scaled), the sun's disk and T_vol through the true
//!    one.
//!
//! `[render.coupled]` keeps the candidates the design was chosen from, each measured against
//! the truth in `docs/coupled/` (all but the first with `diffuse = "diffusion"`):
//! - `diffuse = "diffusion"`: steps 1–4 without 3b, δ-Eddington's split;
//! - `split = "hemisphere"`: f = F_{n+1}, the tables' forward-hemisphere fraction, Riley's n
//!   counted and Ams_{n+1} in the gather, the true extinction in the gather (Riley's buffer
//!   exactly, with its dropped back-scattered light diffused);
//! - `source = "first-scatter"`: f = 0, Max's first-scattered sources (no δ-scaling);
//! - `emergent = "isotropic"`: the diffusion's light without its I_1 term, as Max.
//!
//! # Where each pass runs
//! The CPU reference (`--cpu`) runs everything on the CPU in f64 (rayon). A GPU render runs,
//! with `per_view = "auto"` on a real GPU or `"gpu"` anywhere, the gather on the GPU ([`gpu`],
//! the lighting's buffers kept there between views) and, with `per_sun = "auto"` on a real
//! GPU or `"gpu"` anywhere, the per-sun passes: the transport's sweeps
//! ([`crate::lighting::transport_gpu`]: one dispatch per layer of each sweep order, a workgroup
//! per voxel of the layer, an invocation per direction, in f32), the skylight's sweeps
//! ([`crate::lighting::sky_gpu`]), the beam's ([`crate::lighting::beam_gpu`]; but for the
//! hemisphere split) and every diffusion solve — the three channels' and the
//! transport's acceleration — ([`crate::lighting::diffusion_gpu`]: the same conjugate gradients and
//! V-cycle in f32 inside an f64 refinement). The source iteration's control (acceleration
//! sources, the convergence test), the medium per voxel, the sources, the flux and the budget
//! stay on the CPU. On lavapipe (a CPU
//! emulating a GPU) the GPU passes are slower than the CPU reference, so `auto` keeps them on
//! the CPU there.
//!
//! Units: radiance per unit solar irradiance outside the atmosphere (1/sr) per channel.

pub mod gather;
pub mod gpu;
pub mod light;
pub mod moments;
pub mod peak;

use std::time::Instant;

use serde::{Deserialize, Serialize};

use runtime::gpu::{Gpu, GpuTables, TexelFormat};

use crate::checks::FrameError;
use crate::frame::Frame;
use crate::gpu::RenderError;
use crate::lighting::Place;
use crate::lighting::transport;
use crate::model::{Device, Job, Model, Need, Pass, RenderResult, Rendered, image_need};
use crate::relight::Lit;

/// `--model coupled`.
pub struct Coupled;

/// Bytes the lighting takes per voxel at its peak beyond the grid (optics 96, buffer 32,
/// sources and the solve's problem 80, the solver's vectors and hierarchy ≈ 120, the result
/// and its flux 96, the skylight 96).
pub const MEMORY_PER_VOXEL: u64 = 520;

/// Bytes the discrete-ordinates transport adds per transport voxel (the grid's, or its blocks
/// with `transport_coarsening`) at its peak: two sets of 75 moments (1200), the scaled medium and
/// its sources (288), the acceleration's operators and solver (≈ 240), the sweeps' layers
/// (a few layers of the grid, ≈ 72 at 64 along an axis).
pub const TRANSPORT_MEMORY_PER_VOXEL: u64 = 1800;

/// The automatic `transport_coarsening` of the `balanced` preset keeps at least this many
/// transport voxels along the grid's longest side (dense_cumulus, 128 → 64: bias against the
/// truth −12.1 % at 2 against −12.9 % at 1, the sweeps an eighth of the cost), and of
/// `realtime`; `reference` keeps every voxel ([`Preset::auto_transport_voxels`]).
pub const AUTO_TRANSPORT_VOXELS: usize = 64;

/// The deepest scene (the optical depth of its deepest point, as [`crate::auto`] measures it)
/// coupled takes with its default settings: on the soft ball at 48³ the transport converged at
/// τ 320 (7 iterations) and diverged from τ 360 (docs/models/coupled.md, "Optical depth").
/// Deeper scenes are refused before the lighting unless `max_transport_iterations` is raised.
pub const MAX_OPTICAL_DEPTH: f64 = 300.0;

/// The largest product of the scene's optical depth and its densest transport voxel's that
/// coupled takes with its default settings: on the soft ball from 16³ to 48³ the transport
/// converged up to products of 3 200 and diverged from 3 675 (docs/models/coupled.md,
/// "Optical depth"); a coarse grid reaches it below [`MAX_OPTICAL_DEPTH`] (16³: τ ≈ 180).
pub const MAX_DEPTH_PRODUCT: f64 = 3000.0;

impl Settings {
    /// The transport's coarsening on `dims`: the setting, or (0, automatic) the largest of 4,
    /// 2 that leaves the preset's [`Preset::auto_transport_voxels`] along the longest side,
    /// else 1.
    pub fn coarsening(&self, dims: [usize; 3]) -> usize {
        let longest = dims.into_iter().max().unwrap_or(0);
        let keep = self.preset.auto_transport_voxels();
        match self.transport_coarsening {
            0 => [4, 2]
                .into_iter()
                .find(|f| longest / f >= keep)
                .unwrap_or(1),
            set => set,
        }
    }
}

/// Named settings that trade accuracy for time, `preset = "…"` in `[render.coupled]` (or
/// `--set preset=…`): each sets the transport's directions, tolerances and coarsening, and a
/// key given beside it overrides the preset's value. Their measured errors against the truth
/// and their costs: docs/models/coupled.md, "Presets".
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Preset {
    /// The fewest directions and the loosest tolerances measured to keep the cases near the
    /// truth: 32 directions, transport_tolerance 0.03, diffusion_tolerance 1e-4, the transport
    /// on at least 64 voxels along the longest side as `balanced` (at 32 the glory scene read
    /// −10.1 % against the truth and the dawn cumulus +5.9 %, at 64 −6.6 % and +3.0 %).
    Realtime,
    /// The defaults: 96 directions, at least 64 transport voxels along the longest side,
    /// transport_tolerance 0.01, diffusion_tolerance 1e-6.
    #[default]
    Balanced,
    /// Converged further, to measure the others by: 192 directions, the transport on every
    /// voxel, transport_tolerance 1e-3 (at most 200 iterations), diffusion_tolerance 1e-8.
    Reference,
}

impl Preset {
    /// Every preset, cheapest first.
    pub const ALL: [Preset; 3] = [Preset::Realtime, Preset::Balanced, Preset::Reference];

    /// The name scenes use.
    pub fn name(self) -> &'static str {
        match self {
            Preset::Realtime => "realtime",
            Preset::Balanced => "balanced",
            Preset::Reference => "reference",
        }
    }

    /// The transport voxels the automatic coarsening keeps along the grid's longest side.
    pub fn auto_transport_voxels(self) -> usize {
        match self {
            Preset::Realtime | Preset::Balanced => AUTO_TRANSPORT_VOXELS,
            Preset::Reference => usize::MAX,
        }
    }

    /// The preset's settings (where a pass runs is not the preset's: `auto`).
    pub fn settings(self) -> Settings {
        let (directions, transport_tolerance, max_transport_iterations, diffusion_tolerance) =
            match self {
                Preset::Realtime => (32, 0.03, 40, 1e-4),
                Preset::Balanced => (96, 0.01, 40, 1e-6),
                Preset::Reference => (192, 1e-3, 200, 1e-8),
            };
        Settings {
            preset: self,
            source: Source::Buffer,
            split: Split::DeltaEddington,
            emergent: Emergent::P1,
            diffusion_tolerance,
            max_diffusion_iterations: 500,
            diffuse: Diffuse::Transport,
            directions,
            transport_tolerance,
            max_transport_iterations,
            transport_coarsening: 0,
            per_sun: Place::Auto,
            per_view: Place::Auto,
        }
    }
}

/// What feeds the diffusion solve (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Source {
    /// The light the forward buffer drops, α(1 − F) of each slab's extinction (δ-scaled).
    #[default]
    Buffer,
    /// The first-scattered reduced sunlight (F = 0), as Max et al.
    FirstScatter,
}

/// Which share of each slab's scattering the buffer keeps in the beam (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Split {
    /// The δ-split: the forward peak the diffuse light cannot carry stays in the beam; the
    /// rest is the diffuse light's source; the gather sees through β_ext(1 − αf). Its f is
    /// δ-M's, χ_{L+1} of the tables' Ams_1 (Wiscombe 1977; L = 4, the transport's degree),
    /// under `diffuse = "transport"` (the default), and δ-Eddington's, f = g² (Joseph,
    /// Wiscombe & Weinman 1976; the rest of asymmetry g/(1 + g)), under `diffuse =
    /// "diffusion"`. The scene name `delta-eddington` is kept for both.
    #[default]
    DeltaEddington,
    /// f = F_{n+1}, the tables' forward-hemisphere fraction (Riley's continuum update): all
    /// light scattered forward stays in the beam, only back-scattered light is dropped; the
    /// gather sees through β_ext.
    Hemisphere,
}

/// How the diffusion's light is scattered towards the eye (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Emergent {
    /// I_0 + g I_1·ω, the P1 radiance through the phase function's first moment.
    #[default]
    P1,
    /// I_0 alone, as Max et al.
    Isotropic,
}

/// What carries the diffuse light, the beam's scattered loss and the skylight (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Diffuse {
    /// Discrete ordinates ([`transport`]): the δ-M-scaled transfer equation along
    /// `directions` directions, the radiance kept as spherical-harmonic moments to degree 4,
    /// source iteration accelerated by the diffusion solve, from the diffusion's P1 radiance.
    #[default]
    Transport,
    /// The δ-scaled diffusion alone (P1), as Max et al.; ~20× cheaper per sun, 30–40 % dark
    /// in dense clouds seen from the side or the sun's side (docs/models/coupled.md).
    Diffusion,
}

/// The model's settings, `[render.coupled]`: a [`Preset`]'s, with the keys given beside it
/// in its place.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "Given")]
pub struct Settings {
    /// The preset the other keys start from (default "balanced").
    pub preset: Preset,
    /// What feeds the diffusion (default "buffer").
    pub source: Source,
    /// The share the beam keeps (default "delta-eddington": δ-M's f under the transport,
    /// f = g² under the diffusion alone).
    pub split: Split,
    /// The diffusion's light towards the eye (default "p1").
    pub emergent: Emergent,
    /// Relative residual ‖b − A x‖/‖b‖ the diffusion solve must reach, [1e-12, 0.1].
    /// The preset's (balanced: 1e-6).
    pub diffusion_tolerance: f64,
    /// Conjugate-gradient iterations allowed, [1, 100000]. Default 500.
    pub max_diffusion_iterations: usize,
    /// What carries the diffuse light (default "transport").
    pub diffuse: Diffuse,
    /// Directions of the discrete-ordinates transport, [16, 1024]. The preset's (balanced:
    /// 96).
    pub directions: usize,
    /// The transport's source iteration stops when an iteration changes the mean radiance
    /// by less than this (relative, rms over the grid, green), [1e-6, 0.5]. The preset's
    /// (balanced: 0.01).
    pub transport_tolerance: f64,
    /// Source iterations allowed, [1, 1000]. The preset's (balanced: 40).
    pub max_transport_iterations: usize,
    /// The transport's voxels span this many of the grid's along each axis: 1, 2 or 4 (the
    /// medium and the sources averaged over each block, the radiance's moments kept on the
    /// blocks and looked up there by the gathers; at 2
    /// the sweeps cost an eighth, docs/models/coupled.md gives the error), or 0 (the default):
    /// the largest that leaves the transport at least the preset's
    /// [`Preset::auto_transport_voxels`] along the grid's longest side.
    pub transport_coarsening: usize,
    /// Where a GPU render's per-sun passes (the beam's, the skylight's and the transport's
    /// sweeps, the diffusion solves) run: "auto" (the default: on the GPU unless the adapter is a CPU emulation such as
    /// lavapipe), "gpu" or "cpu".
    pub per_sun: Place,
    /// Where a GPU render's gather (per view) runs, as `per_sun`: "auto" (the default),
    /// "gpu" (fails, naming the limit, where the lighting exceeds the adapter's buffers) or
    /// "cpu".
    pub per_view: Place,
}

impl Default for Settings {
    fn default() -> Self {
        Preset::default().settings()
    }
}

/// `[render.coupled]` as written: the preset and the keys given beside it.
#[derive(Deserialize, Default)]
#[serde(default, deny_unknown_fields)]
struct Given {
    preset: Option<String>,
    source: Option<Source>,
    split: Option<Split>,
    emergent: Option<Emergent>,
    diffusion_tolerance: Option<f64>,
    max_diffusion_iterations: Option<usize>,
    diffuse: Option<Diffuse>,
    directions: Option<usize>,
    transport_tolerance: Option<f64>,
    max_transport_iterations: Option<usize>,
    transport_coarsening: Option<usize>,
    per_sun: Option<Place>,
    per_view: Option<Place>,
}

impl TryFrom<Given> for Settings {
    type Error = String;

    fn try_from(g: Given) -> Result<Self, String> {
        let preset = match g.preset.as_deref() {
            None => Preset::default(),
            Some(name) => Preset::ALL
                .into_iter()
                .find(|p| p.name() == name)
                .ok_or_else(|| {
                    format!(
                        "preset = {name:?} is not one of \"realtime\", \"balanced\", \
                         \"reference\" (the presets, cheapest first)"
                    )
                })?,
        };
        let p = preset.settings();
        Ok(Settings {
            preset,
            source: g.source.unwrap_or(p.source),
            split: g.split.unwrap_or(p.split),
            emergent: g.emergent.unwrap_or(p.emergent),
            diffusion_tolerance: g.diffusion_tolerance.unwrap_or(p.diffusion_tolerance),
            max_diffusion_iterations: g
                .max_diffusion_iterations
                .unwrap_or(p.max_diffusion_iterations),
            diffuse: g.diffuse.unwrap_or(p.diffuse),
            directions: g.directions.unwrap_or(p.directions),
            transport_tolerance: g.transport_tolerance.unwrap_or(p.transport_tolerance),
            max_transport_iterations: g
                .max_transport_iterations
                .unwrap_or(p.max_transport_iterations),
            transport_coarsening: g.transport_coarsening.unwrap_or(p.transport_coarsening),
            per_sun: g.per_sun.unwrap_or(p.per_sun),
            per_view: g.per_view.unwrap_or(p.per_view),
        })
    }
}

impl Settings {
    /// Checks the settings, naming the key, its value and the allowed range.
    pub fn check(&self) -> Result<(), FrameError> {
        crate::lighting::diffusion::check_settings(
            self.diffusion_tolerance,
            self.max_diffusion_iterations,
        )?;
        if !(16..=1024).contains(&self.directions) {
            return Err(FrameError(format!(
                "directions = {} is outside the allowed range [16, 1024]",
                self.directions
            )));
        }
        if !(1e-6..=0.5).contains(&self.transport_tolerance) {
            return Err(FrameError(format!(
                "transport_tolerance = {} is outside the allowed range \
                 [1e-6, 0.5] (relative change of the mean radiance per iteration)",
                crate::checks::Shown(self.transport_tolerance)
            )));
        }
        if !(1..=1000).contains(&self.max_transport_iterations) {
            return Err(FrameError(format!(
                "max_transport_iterations = {} is outside the allowed range \
                 [1, 1000]",
                self.max_transport_iterations
            )));
        }
        let c = self.transport_coarsening;
        if ![0, 1, 2, 4].contains(&c) {
            return Err(FrameError(format!(
                "transport_coarsening = {c} is not one of 1, 2, 4 (the \
                 grid's voxels per transport voxel along each axis) or 0 (automatic)"
            )));
        }
        if self.diffuse == Diffuse::Transport && !light::delta_scaled(self) {
            return Err(FrameError(
                "diffuse = \"transport\" needs the default source (\"buffer\") \
                 and split (\"delta-eddington\"); set diffuse = \"diffusion\" for the others"
                    .into(),
            ));
        }
        Ok(())
    }
}

impl Model for Coupled {
    const NAME: &'static str = "coupled";
    const ABOUT: &'static str = "the sunlight's forward peak kept in a beam (δ-M), the light it \
        loses carried by discrete-ordinates transport accelerated by diffusion, both gathered \
        with the exact phase function; lighting per sun, the gather per view";
    const TEXELS: TexelFormat = TexelFormat::F32;
    const GPU: bool = true;
    const PERIODIC: bool = true;
    type Settings = Settings;
    type Renderer = gpu::Renderer;

    fn check(s: &Settings) -> Result<(), FrameError> {
        s.check()
    }

    fn check_frame(s: &Settings, frame: &Frame) -> Result<(), FrameError> {
        frame.sunlight_only(Self::NAME, false)?;
        frame.check_view().and_then(|()| s.check())?;
        // A periodic volume's sweeps wrap and repeat, and its gather follows the layer
        // across periods: on the CPU only.
        for (key, place) in [("per_sun", s.per_sun), ("per_view", s.per_view)] {
            if frame.grid.periodic && place == Place::Gpu {
                return Err(FrameError(format!(
                    "[render.coupled] {key} = \"gpu\": a periodic volume is lit and gathered \
                     on the CPU only (its sweeps wrap across the box and repeat until they \
                     settle); set {key} = \"auto\" or \"cpu\""
                )));
            }
        }
        Ok(())
    }

    fn memory(s: &Settings, pixels: u64, dims: [usize; 3]) -> Vec<Need> {
        let voxels = crate::model::voxels(dims);
        // The transport runs on the grid coarsened by `transport_coarsening` (its blocks).
        let c = s.coarsening(dims);
        let transport = crate::model::voxels(dims.map(|d| d.div_ceil(c)));
        let mut needs = vec![
            Need {
                what: "the lighting (optics, buffer, sky, diffusion solve and flux)",
                bytes: voxels * MEMORY_PER_VOXEL,
                setting: "[render] grid_resolution".into(),
            },
            image_need("the gathered image", pixels, 48),
        ];
        if s.diffuse == Diffuse::Transport {
            needs.push(Need {
                what: "the discrete-ordinates transport (two sets of radiance moments, the \
                       scaled medium, one direction's sweep)",
                bytes: transport * TRANSPORT_MEMORY_PER_VOXEL,
                setting: "[render] grid_resolution, or raise [render.coupled] \
                          transport_coarsening (1, 2, 4), or diffuse = \"diffusion\""
                    .into(),
            });
        }
        needs
    }

    fn renderer(gpu: &Gpu, tables: &GpuTables) -> Option<gpu::Renderer> {
        Some(gpu::Renderer::new(gpu, tables))
    }

    fn render_cpu(s: &Settings, job: &Job) -> Result<Rendered, RenderError> {
        let lighting = light::light_with(job.tables, job.frame, s, job.progress)?;
        let start = Instant::now();
        let image = gather::gather(job.tables, job.frame, s, &lighting)?;
        let gather = start.elapsed().as_secs_f64();
        Ok(rendered(
            image,
            &lighting.report,
            gather,
            "CPU",
            (job.frame, s),
        ))
    }

    fn render_gpu(s: &Settings, job: &Job, on: Device<gpu::Renderer>) -> RenderResult {
        let (renderer, gpu, tables) = (on.renderer, on.gpu, on.tables);
        // The lighting takes 5 rows of 16 bytes a voxel, the transport's moments 19 a voxel of
        // its grid: past the adapter's storage-binding limit the view is gathered on the CPU
        // (same image, said so), or refused before any work with `per_view = "gpu"`; on a CPU
        // adapter `auto` gathers on the CPU.
        let dims = job.frame.grid.dims;
        let moments = if s.diffuse == Diffuse::Transport {
            transport::Coarse::dims(dims, s.coarsening(dims))
                .iter()
                .product()
        } else {
            0
        };
        let limit = gpu.device.limits().max_storage_buffer_binding_size;
        let over = gpu::binding_sizes(dims.iter().product(), moments)
            .into_iter()
            .find(|&(_, bytes)| bytes > limit)
            .map(|(what, bytes)| {
                let mib = |b: u64| b as f64 / f64::from(1u32 << 20);
                format!(
                    "{what}'s {:.1} MiB exceed {}'s storage-binding limit of {:.1} MiB",
                    mib(bytes),
                    gpu.describe(),
                    mib(limit)
                )
            });
        let on_cpu = match (s.per_view, over) {
            (Place::Gpu, Some(over)) => {
                return Err(FrameError(format!(
                    "[render.coupled] per_view = \"gpu\": {over}; lower [render] \
                     grid_resolution or set per_view = \"auto\""
                ))
                .into());
            }
            (_, Some(over)) => Some(over),
            _ if job.frame.grid.periodic => Some("a periodic volume".to_string()),
            (place, None) if !place.on_gpu(gpu) => Some(format!(
                "per_view = \"{}\" on {}",
                if place == Place::Cpu { "cpu" } else { "auto" },
                gpu.describe()
            )),
            _ => None,
        };
        // A new sun on the same grid starts the transport from the last sun's moments.
        // (A periodic grid's passes stay on the CPU: the relight drops `on` for it.)
        let on = || s.per_sun.on_gpu(gpu).then(|| renderer.per_sun(gpu));
        let (lighting, lit) = match job.lighting {
            // A viewer's cache with a step budget: this frame's steps of the relight.
            Some(cache) if cache.step_budget().is_some() => {
                let budget = cache.step_budget().expect("matched");
                cache.get_or_step(
                    job.frame,
                    s,
                    |previous| light::Relight::new(job.tables, job.frame, s, previous),
                    |relight: &mut light::Relight| {
                        relight.step_for(job.tables, (on(), job.progress), budget)
                    },
                )?
            }
            cache => {
                let (lighting, reused) = crate::relight::lit(cache, job.frame, s, |previous| {
                    light::light_from(job.tables, job.frame, s, job.progress, (on(), previous))
                })?;
                let lit = if reused { Lit::Kept } else { Lit::Converged };
                (lighting, lit)
            }
        };
        let reused = lit == Lit::Kept;
        let (image, gather, on) = if let Some(why) = on_cpu {
            let start = Instant::now();
            let image = gather::gather(job.tables, job.frame, s, &lighting)?;
            (
                image,
                start.elapsed().as_secs_f64(),
                format!("the CPU: {why}"),
            )
        } else {
            let (image, t) = renderer.gather(gpu, job.tables, tables, job.frame, s, &lighting)?;
            (image, t.upload + t.frame + t.readback, gpu.describe())
        };
        let mut report = lighting.report.clone();
        if reused {
            (report.buffer_s, report.diffusion_s, report.transport_s) = (0.0, 0.0, 0.0);
        }
        let mut out = rendered(image, &report, gather, &on, (job.frame, s));
        if reused {
            out.reused_lighting();
        }
        if let Lit::Partial(steps) = lit {
            out.converging(steps);
        }
        Ok(out)
    }
}

/// The frame with its passes (the lighting's steps, then the gather) and summary.
fn rendered(
    image: crate::image::Image,
    report: &light::CoupledReport,
    gather_s: f64,
    on: &str,
    (frame, settings): (&Frame, &Settings),
) -> Rendered {
    let summary = format!(
        "beam + δ-scaled diffusion (lighting on the CPU, {} threads, but where the beam, the \
         skylight, the diffusion and the transport say; gather on {on}): {}×{}, \
         grid {:?}: beam {:.2} s (swept on {}, skylight on {}), {}, {}gather {gather_s:.2} s \
         ({}); of the sunlight entering (green): {:.1} % leaves in the buffer, {:.1} % is \
         absorbed from it, {:.1} % feeds the diffusion{}",
        rayon::current_num_threads(),
        image.width,
        image.height,
        frame.grid.dims,
        report.buffer_s,
        report.beam_on,
        report.sky_on,
        if report.diffusion_skipped {
            "diffusion not solved (the transport starts from the last sun's moments)".to_string()
        } else {
            format!(
                "diffusion {:.2} s on {} ({} unknowns, {} levels, {:?} CG iterations to \
                 residuals {:.1e}/{:.1e}/{:.1e})",
                report.diffusion_s,
                report.diffusion_on,
                report.unknowns,
                report.levels,
                report.iterations,
                report.residual[0],
                report.residual[1],
                report.residual[2],
            )
        },
        if report.transport_iterations > 0 {
            format!(
                "transport {:.2} s ({} directions on a grid {:?}, swept on {}, {} iterations \
                 to a change of {:.1e}{}), ",
                report.transport_s,
                settings.directions,
                report.transport_dims,
                report.transport_on,
                report.transport_iterations,
                report.transport_change,
                if report.transport_warm {
                    " from the last sun's moments"
                } else {
                    ""
                }
            )
        } else {
            String::new()
        },
        if report.peaks.is_empty() {
            "no forward peak blurs the sun's single scattering".to_string()
        } else {
            let fits: Vec<String> = report
                .peaks
                .iter()
                .map(|(name, h, s, c)| {
                    format!("{name} half width {h:.2}°, share {s:.2}, cone beyond it {c:.2}")
                })
                .collect();
            format!(
                "the sun's single scattering blurred by the forward peak: {}",
                fits.join("; ")
            )
        },
        100.0 * report.budget.buffer_out[1],
        100.0 * report.budget.buffer_absorbed[1],
        100.0 * report.budget.dropped[1],
        if report.diffusion_skipped {
            String::new()
        } else {
            format!(
                ", which sends {:.1} % out and absorbs {:.1} %",
                100.0 * report.budget.diffusion_out[1],
                100.0 * report.budget.diffusion_absorbed[1],
            )
        },
    );
    let pass = |name, seconds| Pass { name, seconds };
    Rendered {
        summary,
        image,
        extra: Vec::new(),
        figures: vec![
            ("unknowns", report.unknowns as f64),
            ("CG iterations", report.iterations[1] as f64),
            ("transport iterations", report.transport_iterations as f64),
        ],
        passes: vec![
            pass("buffer", report.buffer_s),
            pass("diffusion", report.diffusion_s),
            pass("transport", report.transport_s),
            pass("gather", gather_s),
        ],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read(text: &str) -> Result<Settings, String> {
        toml::from_str::<Settings>(text).map_err(|e| e.message().to_string())
    }

    #[test]
    fn a_preset_sets_its_keys_and_a_key_beside_it_wins() {
        // No preset is the balanced one, whose values are the model's defaults.
        assert_eq!(read("").unwrap(), Settings::default());
        assert_eq!(read("preset = \"balanced\"").unwrap(), Settings::default());
        let realtime = read("preset = \"realtime\"").unwrap();
        assert_eq!(realtime, Preset::Realtime.settings());
        assert_eq!(realtime.directions, 32);
        let reference = read("preset = \"reference\"").unwrap();
        assert_eq!(
            (reference.directions, reference.coarsening([128; 3])),
            (192, 1)
        );
        // The automatic coarsening keeps the preset's voxels along the longest side.
        let dims = [128, 70, 128];
        assert_eq!(realtime.coarsening(dims), 2);
        assert_eq!(Settings::default().coarsening(dims), 2);
        assert_eq!(reference.coarsening(dims), 1);
        // A key given beside the preset overrides it; the others stay the preset's.
        let mixed = read("preset = \"realtime\"\ndirections = 64").unwrap();
        assert_eq!(
            mixed,
            Settings {
                directions: 64,
                ..Preset::Realtime.settings()
            }
        );
        // Every preset's settings pass the model's own checks.
        for p in Preset::ALL {
            p.settings().check().unwrap();
        }
    }

    #[test]
    fn an_unknown_preset_is_refused_by_name_with_the_allowed_ones() {
        let e = read("preset = \"fast\"").unwrap_err();
        assert!(
            e.contains("preset = \"fast\"") && e.contains("\"realtime\", \"balanced\""),
            "{e}"
        );
        let e = read("preset = \"realtime\"\nspeed = 2").unwrap_err();
        assert!(e.contains("speed"), "{e}");
    }
}
