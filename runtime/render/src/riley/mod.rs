//! Riley et al. 2004 §4–5: half-angle slicing (Kniss et al.) of a density grid with a
//! light buffer and an eye buffer, the multiple-scattering tables for the angular spread of
//! sunlight, and the analytic sky in front of and behind the volume.
//!
//! # The model, as [`cpu::render`] (the reference) and [`gpu::Renderer`] compute it
//! Slices are planes h·x = c_k, k = 0..S−1, spaced Δ = (extent of the box along h)/S, with h
//! halfway between the view direction v and the light's direction of travel l (h ∝ v + l when
//! v·l ≥ 0: the eye composites front to back; h ∝ l − v otherwise: back to front). Light always
//! crosses the slices in order, so one pass serves both buffers. Per slice k:
//!
//! 1. **Eye** (Eq. 26): each pixel's ray meets slice k at p; with the light buffer's (I, n)
//!    there (bilinear), the slab of thickness Δ_e = Δ/|h·d| adds
//!    I · S_atm(p_y) · (Ams_{n+1}(θ) + ξ) · α (1 − e^{−β_ext Δ_e}) per channel, θ the
//!    angle between the sunlight and the ray towards the eye, Ams the spatial mix of the fields
//!    (Eq. 6) and α = β_sca/β_ext (Eq. 3). α(1 − e^{−β_ext Δ_e}) is Riley's β_sca Δ to first
//!    order and never exceeds the slab's albedo for thick slabs.
//! 2. **Light** (Eqs. 21, 25): each light-buffer texel's ray (along l) meets slice k; with
//!    τ = β_ext Δ_l, Δ_l = Δ/(h·l): I ← I · keep(τ), n ← n + α τ (the expected scatter count,
//!    Eq. 21/22; green channel, as Riley's single alpha), F = F_{n+1+τ} the fields' mix weighted
//!    like Eq. 6 and linear in fractional n (Riley floored it because his hardware could not
//!    interpolate float textures). keep is [`LightUpdate`]:
//!    - `continuum` (default): keep = e^{−τ(1 − αF)}, the forward-scattered share αF of what
//!      the slab removes stays in the beam. It is first order in τ, so the buffer converges as
//!      slices are added, and the eye pass reads the light at the slab's middle (the buffer
//!      carried over half the slab), which removes the remaining O(Δ) error: the side-lit
//!      τ = 32 ball moves +0.59 % from 256 to 1024 slices (`tests/render.rs`).
//!    - `riley2004`: Eq. 25 as printed, keep = e^{−τ} + (1 − e^{−τ})(αF)^τ, whose loss
//!      τ²·ln(1/αF) is second order: thin slabs lose almost nothing, and the same ball brightens
//!      by +24.6 % from 256 to 1024 slices. Kept for comparison; the eye reads the buffer as
//!      it stands.
//!
//! S_atm (Eq. 12) is the sunlight left at height p_y by the atmosphere. Per pixel, with the
//! ray's distance K_mid to the middle of the box and T_vol the volume's transparency:
//! L = Sky(0, K_mid) + T_air(K_mid) L_vol + T_vol (Sky(0, K_end) − Sky(0, K_mid)) + T_vol sun,
//! where Sky is [`crate::sky::Atmosphere::inscatter`] (Eqs. 11–15), K_end the ground (black) or ∞,
//! and "sun" the disk of 0.5° (Riley §4.2.4) attenuated by the whole atmosphere.
//!
//! Units: radiance per unit solar irradiance outside the atmosphere (1/sr) per channel.

pub mod cpu;
pub mod gpu;

use std::time::Instant;

use glam::DVec3;
use serde::{Deserialize, Serialize};

use runtime::gpu::{Gpu, GpuTables, TexelFormat};

use crate::checks::FrameError;
use crate::frame::Frame;
use crate::gpu::RenderError;
use crate::model::{Device, Job, Model, Need, Pass, RenderResult, Rendered, image_need};
use crate::shading::{MAX_PHASE_TERM, check_slicing};

use crate::geometry::basis;

/// `--model riley`.
pub struct Riley;

/// The model's settings, `[render.riley]`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Settings {
    /// Number S of half-angle slices through the grid's box, [1, 4096] (default 256).
    pub slices: usize,
    /// Light-buffer texels per side, [2, 4096] (default 512).
    pub light_resolution: usize,
    /// Riley's ξ: back-scattered light added to the phase function in the eye pass (1/sr),
    /// ≥ 0 (default 0).
    pub xi: f64,
    /// How the light buffer loses light per slab (default continuum).
    pub light_update: LightUpdate,
}

impl Default for Settings {
    fn default() -> Self {
        Self {
            slices: 256,
            light_resolution: 512,
            xi: 0.0,
            light_update: LightUpdate::default(),
        }
    }
}

impl Model for Riley {
    const NAME: &'static str = "riley";
    const ABOUT: &'static str = "Riley et al. 2004: half-angle slicing with light and eye \
        buffers, the multiple-scattering tables Ams_n and F_n for the angular spread of sunlight";
    const TEXELS: TexelFormat = TexelFormat::Auto;
    const GPU: bool = true;
    type Settings = Settings;
    type Renderer = gpu::Renderer;

    fn check(s: &Settings) -> Result<(), FrameError> {
        check_slicing(s.slices, s.light_resolution, "light-buffer")?;
        if !(s.xi.is_finite() && (0.0..=MAX_PHASE_TERM).contains(&s.xi)) {
            return Err(FrameError(format!(
                "xi = {} is outside the allowed range [0, {MAX_PHASE_TERM:e}] (1/sr)",
                crate::checks::Shown(s.xi)
            )));
        }
        Ok(())
    }

    fn check_frame(s: &Settings, frame: &Frame) -> Result<(), FrameError> {
        frame.sunlight_only(Self::NAME, false)?;
        Setup::new(frame, s).map(|_| ())
    }

    fn memory(s: &Settings, pixels: u64, _dims: [usize; 3]) -> Vec<Need> {
        // Per pixel: its ray (24 B), (L, T) per channel (48), the composed pixel and the
        // image (32): measured 107 B (RSS at 1024² less 256², CPU reference); per light texel
        // (I, n) (32).
        let res = s.light_resolution as u64;
        vec![
            image_need("the eye buffer and image", pixels, 112),
            Need {
                what: "the light buffer",
                bytes: res * res * 32,
                setting: "[render.riley] light_resolution".into(),
            },
        ]
    }

    fn renderer(gpu: &Gpu, tables: &GpuTables) -> Option<gpu::Renderer> {
        Some(gpu::Renderer::new(gpu, tables))
    }

    fn render_cpu(s: &Settings, job: &Job) -> Result<Rendered, RenderError> {
        let start = Instant::now();
        let image = cpu::render(job.tables, job.frame, s)?;
        let seconds = start.elapsed().as_secs_f64();
        let summary = format!(
            "CPU reference: {}×{}, {} slices, light buffer {}²: {seconds:.2} s",
            image.width, image.height, s.slices, s.light_resolution
        );
        Ok(Rendered::cpu_frame(image, seconds, summary))
    }

    fn render_gpu(s: &Settings, job: &Job, on: Device<gpu::Renderer>) -> RenderResult {
        let (renderer, gpu, tables) = (on.renderer, on.gpu, on.tables);
        let (image, t) = renderer.render(gpu, job.tables, tables, job.frame, s)?;
        let summary = format!(
            "{}: {}×{}, {} slices, light buffer {}²: {}",
            gpu.describe(),
            image.width,
            image.height,
            s.slices,
            s.light_resolution,
            t.describe()
        );
        Ok(Rendered::plain(image, Pass::of_gpu(&t), summary))
    }
}

/// The derived geometry both renderers use (module docs).
#[derive(Debug, Clone, Copy)]
pub struct Setup {
    /// The camera: each pixel's ray ([`Setup::pixel`]).
    pub camera: crate::camera::Camera,
    /// Eye position (m), the centre of an orthographic image.
    pub eye: DVec3,
    /// Unit view direction v.
    pub forward: DVec3,
    /// Unit camera right axis, v × y (x when looking straight up or down).
    pub right: DVec3,
    /// Unit camera up axis, right × v.
    pub up: DVec3,
    /// Direction the sunlight travels (−sun direction).
    pub light: DVec3,
    /// Unit half-angle vector h, the slices' normal: ∝ v + l if front to back, else ∝ l − v.
    pub half: DVec3,
    /// Whether the eye composites front to back (v·l ≥ 0); otherwise back to front.
    pub front_to_back: bool,
    /// Plane value of the first slice's centre, and the spacing Δ along h.
    pub slice_start: f64,
    /// Slice spacing Δ along h (m).
    pub slice_step: f64,
    /// Light-buffer axes (⟂ l), origin (u, w of texel (0, 0)'s corner) and texel size.
    pub light_u: DVec3,
    /// Second light-buffer axis w (⟂ l and u).
    pub light_w: DVec3,
    /// (u, w) of texel (0, 0)'s corner (m).
    pub light_origin: [f64; 2],
    /// Texel size along u and w (m).
    pub light_texel: [f64; 2],
}

impl Setup {
    /// Checks the frame and the settings and derives the slicing geometry.
    pub fn new(frame: &Frame, settings: &Settings) -> Result<Self, FrameError> {
        frame.check_view()?;
        Riley::check(settings)?;
        // A pinhole's check: each orthographic pixel starts at its own point of the image
        // plane, and its ray skips the slabs behind that point (t ≤ 0) wherever it lies.
        let perspective = frame.camera.ortho_half_height_m((1, 1)).is_none();
        if perspective && frame.grid.contains(frame.camera.position_m) {
            return Err(FrameError(format!(
                "the camera at {:?} m is inside the volumes' box {:?}…{:?} m; half-angle \
                 slicing needs it outside",
                frame.camera.position_m, frame.grid.min_m, frame.grid.max_m
            )));
        }
        let (forward, right, up) = frame.camera.axes().expect("checked by check_view");

        let light = -frame.sun.direction();
        let front_to_back = forward.dot(light) >= 0.0;
        let half = if front_to_back {
            (forward + light).normalize()
        } else {
            (light - forward).normalize()
        };
        let along = |axis: DVec3| frame.grid.span_along(axis);
        let (h_lo, h_hi) = along(half);
        let slice_step = (h_hi - h_lo) / settings.slices as f64;
        // Light-buffer axes: any orthonormal pair ⟂ l.
        let (light_u, light_w) = basis(light);
        let (u_lo, u_hi) = along(light_u);
        let (w_lo, w_hi) = along(light_w);
        let res = settings.light_resolution as f64;
        Ok(Setup {
            camera: frame.camera,
            eye: frame.camera.position_m,
            forward,
            right,
            up,
            light,
            half,
            front_to_back,
            slice_start: h_lo + 0.5 * slice_step,
            slice_step,
            light_u,
            light_w,
            light_origin: [u_lo, w_lo],
            light_texel: [(u_hi - u_lo) / res, (w_hi - w_lo) / res],
        })
    }

    /// The ray of pixel (i, j), row j = 0 at the top: its origin and unit direction
    /// ([`crate::camera::Camera::pixel`]).
    pub fn pixel(&self, i: usize, j: usize, width: usize, height: usize) -> (DVec3, DVec3) {
        self.camera
            .pixel((self.forward, self.right, self.up), (i, j), (width, height))
    }
}

/// The light buffer's update across a slab of optical depth τ = β_ext Δ_l, with albedo α and
/// forward fraction F (Riley et al. 2004 Eq. 25 and what this project uses instead).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LightUpdate {
    /// I ← I e^{−τ(1 − αF)}: of the light a slab removes from the beam, the forward-scattered
    /// share αF stays in it. First order in τ, and the same for any slicing (a product of
    /// exponentials), so the buffer converges as slices are added.
    #[default]
    Continuum,
    /// Eq. 25 as printed, I ← I e^{−τ} + I (1 − e^{−τ}) (αF)^τ: its loss is second order in τ,
    /// so thin slabs lose almost nothing and the buffer brightens without limit as slices are
    /// added (docs/truth.md).
    Riley2004,
}

impl LightUpdate {
    /// The scene/CLI name: `continuum` or `riley2004`.
    pub fn parse(name: &str) -> Option<Self> {
        match name {
            "continuum" => Some(Self::Continuum),
            "riley2004" => Some(Self::Riley2004),
            _ => None,
        }
    }

    /// The fraction of the intensity kept across a slab of optical depth `tau` with albedo
    /// `albedo` and forward fraction `f`.
    pub fn keep(self, tau: f64, albedo: f64, f: f64) -> f64 {
        match self {
            Self::Continuum => (-tau * (1.0 - albedo * f)).exp(),
            Self::Riley2004 => {
                let through = (-tau).exp();
                through + (1.0 - through) * (albedo * f).powf(tau)
            }
        }
    }
}
