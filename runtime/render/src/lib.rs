//! The renderers fed by photometeor's tables: one module per render model over shared parts.
//!
//! # The shape of a model
//! A model is a folder `src/<model>/` with a unit type implementing [`Model`]
//! ([`model`]'s docs): its `NAME` (`--model <name>` and the scene table `[render.<name>]`), its
//! `Settings` (a serde struct read from that table; keys it does not have are refused naming
//! the model and the key), `check` (its settings' ranges) and `check_frame` (what it needs of a
//! scene and refuses in it, before anything is baked), its CPU reference (`cpu.rs`) and its GPU
//! renderer (`gpu.rs` with its WGSL beside it). Adding one is its folder plus one line in the
//! `models!` list at the end of `model.rs`; the scene parser, `photometeor render`,
//! `photometeor bench render` dispatch through [`ModelSettings`], so nothing
//! else changes. A model imports the shared modules only, never another model (a test holds
//! this: `tests/layout.rs`).
//!
//! The models:
//! - [`riley`]: Riley et al. 2004's half-angle slicing with a light buffer and an eye buffer,
//!   the multiple-scattering tables Ams_n and F_n for the angular spread of sunlight (the
//!   default).
//! - [`miyazaki`]: Miyazaki, Dobashi & Nishita's shadow-view slices — single scattering with a
//!   constant k_multi, a shadow surface for the clouds' shadows on the ground and in the air.
//! - [`max`]: Max, Schussman, Miyazaki, Iwasaki & Nishita 2004 — a diffusion solve in the dense
//!   core, Poisson-weighted multiple anisotropic scattering from the bake's M(D, θ) at the
//!   edges (lighting on the CPU, the final gather on the GPU).
//! - [`coupled`]: Riley's light buffer for the forward low orders and the light it drops
//!   carried by a δ-scaled diffusion solve, gathered with its P1 flux.
//! - [`biri`]: Biri, Arquès & Michelin 2006 — single scattering of point and spot lights in
//!   homogeneous media in closed form per ray, volumetric shadows from the occluders'
//!   silhouette planes.
//! - [`truth`]: an unbiased spectral Monte Carlo path tracer of the full radiative transfer on
//!   the same scene, the reference every fast model is measured against.
//!
//! # The shared parts
//! - [`scene`]: the scene file's render tables → [`RenderScene`] (shared keys, objects, one
//!   checked settings table per model) → [`Frame`] (the view, the density grid, the objects)
//!   for a set of tables.
//! - [`objects`]: lights, media and their regions, occluders; [`geometry`]: meshes (OBJ),
//!   spheres, ray tests; [`volume`]: density volumes rasterized into one grid.
//! - [`camera`], [`sky`] (Riley's analytic sky, Eqs. 9–15), [`shading`] (per-sample
//!   coefficients, sun-side buffer lookups, the pixel composed around a volume's light),
//!   [`image`] (EXR and PNG out), [`error_map`] (a frame against the truth).
//! - [`lattice`] (light on the voxel grid: optics, upwind sweeps, reduced sun and sky) and
//!   [`diffusion`] (the multigrid-preconditioned diffusion solve), for the models that light
//!   a grid once per sun and gather per view.
//! - [`gpu`]: the plumbing every GPU renderer uses (pipelines, buffers, slice uniforms, a
//!   timed frame and its readback); each WGSL uniform is mirrored by a Pod struct declared
//!   with `runtime::uniform!`, whose layout a test checks against the shader's.
//!
//! Units: radiance per unit solar irradiance outside the atmosphere (1/sr) per channel; lengths
//! in metres, y up, sea level at y = 0.

#![warn(missing_docs)]

pub mod biri;
pub mod camera;
pub mod coupled;
pub mod diffusion;
pub mod diffusion_gpu;
pub mod error_map;
pub mod geometry;
pub mod gpu;
pub mod image;
pub mod lattice;
pub mod max;
pub mod miyazaki;
pub mod model;
pub mod objects;
pub mod relight;
pub mod riley;
pub mod rng;
pub mod scene;
pub mod shading;
pub mod sky;
pub mod skylight;
pub mod truth;
pub mod volume;

pub use camera::{Camera, Sun};
pub use model::{Job, Model, ModelSettings, On, Rendered};
pub use scene::RenderScene;
pub use sky::Atmosphere;
pub use volume::DensityGrid;

use glam::DVec3;

/// A number as an error message shows it: plain decimals where they are
/// short (`0.5`, `-1`, `2000`), scientific notation where they are not
/// (`1e-300`, `1e308`), `NaN` and `inf` as Rust writes them.
pub(crate) struct Shown(pub f64);

impl std::fmt::Display for Shown {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let x = self.0;
        if !x.is_finite() || x == 0.0 || (1e-4..1e7).contains(&x.abs()) {
            write!(f, "{x}")
        } else {
            write!(f, "{x:e}")
        }
    }
}

/// Two unit vectors completing the unit vector `d` to an orthonormal basis (d, e1, e2).
pub fn basis(d: DVec3) -> (DVec3, DVec3) {
    let helper = if d.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
    let e1 = (helper - helper.dot(d) * d).normalize();
    (e1, d.cross(e1))
}

/// Up to this many fields take part in one render (one RGBA texel per voxel).
pub const MAX_FIELDS: usize = 4;

/// Angular diameter of the sun disk (Riley et al. 2004 §4.2.4), degrees.
pub const SUN_DIAMETER_DEG: f64 = 0.5;

/// Everything one frame needs besides the tables.
#[derive(Debug, Clone)]
pub struct Frame {
    /// The pinhole camera; fov (0, 170) degrees.
    pub camera: Camera,
    /// The sun; elevation (0, 90] degrees.
    pub sun: Sun,
    /// The analytic sky and aerial perspective (Riley Eqs. 11–15).
    pub atmosphere: Atmosphere,
    /// Image width, 1…8192 pixels.
    pub width: usize,
    /// Image height, 1…8192 pixels.
    pub height: usize,
    /// Number densities, channel i = field i of the tables.
    pub grid: DensityGrid,
    /// An aerosol layer over the whole scene (`[haze]`; `miyazaki` and `truth`).
    pub haze: Option<Haze>,
    /// Lambertian albedo of the ground at y = 0 (`[ground] albedo`, [0, 1]; 0 is black).
    pub ground_albedo: f64,
    /// Point and spot lights (`[[light]]`; `biri` and `truth`).
    pub lights: Vec<objects::Light>,
    /// Homogeneous media (`[[medium]]`; `biri` and `truth`).
    pub media: Vec<objects::Medium>,
    /// Lambertian occluders (`[[occluder]]`; `biri` and `truth`).
    pub occluders: Vec<objects::Occluder>,
}

/// An aerosol layer: field `field` of the tables at N(y) = N_0 e^{−y/H}.
#[derive(Debug, Clone, PartialEq)]
pub struct Haze {
    /// Index of its field in the tables.
    pub field: usize,
    /// The field's name.
    pub name: String,
    /// N_0 at y = 0 (1/m³).
    pub number_density_per_m3: f64,
    /// H (m).
    pub scale_height_m: f64,
}

impl Frame {
    /// The checks every model makes of the view: image size, field of view, sun above the
    /// horizon, camera at or above sea level and looking somewhere, ground albedo in [0, 1].
    pub fn check_view(&self) -> Result<(), FrameError> {
        let bad = |s: String| Err(FrameError(s));
        if !(1..=8192).contains(&self.width) || !(1..=8192).contains(&self.height) {
            return bad(format!(
                "image size {}×{} is outside the allowed range 1…8192 pixels per side",
                self.width, self.height
            ));
        }
        let fov = self.camera.fov_deg;
        if !(fov > 0.0 && fov < 170.0) {
            return bad(format!(
                "camera fov_deg = {} is outside the allowed range (0, 170) degrees",
                Shown(fov)
            ));
        }
        let e = self.sun.elevation_deg;
        if !(e > 0.0 && e <= 90.0) {
            return bad(format!(
                "sun elevation_deg = {e} is outside the allowed range (0, 90]: the sky model \
                 (Riley et al. 2004 Eq. 12) needs the sun above the horizon"
            ));
        }
        if self.camera.position_m.y < 0.0 {
            return bad(format!(
                "camera height {} m is below sea level (y ≥ 0 required)",
                self.camera.position_m.y
            ));
        }
        if self.camera.axes().is_none() {
            return bad("camera look_at_m equals position_m".into());
        }
        if !(0.0..=1.0).contains(&self.ground_albedo) {
            return bad(format!(
                "[ground] albedo = {} is outside the allowed range [0, 1]",
                self.ground_albedo
            ));
        }
        Ok(())
    }

    /// Refuses what a sunlit slicing model cannot draw: media and occluders, lights, and
    /// (unless `haze_ok`) a haze layer, naming the tables and the models that draw them.
    pub fn sunlight_only(&self, model: &str, haze_ok: bool) -> Result<(), FrameError> {
        if !self.media.is_empty() || !self.occluders.is_empty() {
            return Err(FrameError(format!(
                "the scene has {} [[medium]] and {} [[occluder]] table(s), which only --model \
                 biri and --model truth draw",
                self.media.len(),
                self.occluders.len()
            )));
        }
        if !self.lights.is_empty() {
            return Err(FrameError(format!(
                "the scene has {} [[light]] table(s); --model {model} models sunlight only \
                 (render it with --model truth)",
                self.lights.len()
            )));
        }
        if let (Some(h), false) = (&self.haze, haze_ok) {
            return Err(FrameError(format!(
                "the scene has a [haze] layer (field {:?}); --model {model} draws Rayleigh air \
                 only (render it with --model miyazaki or truth)",
                h.name
            )));
        }
        Ok(())
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

/// Bad frame parameters, named with their allowed range.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct FrameError(pub String);

/// A rendered frame: linear radiance per pixel (rows top to bottom) and the volume's
/// transparency (green channel) per pixel.
#[derive(Debug, Clone)]
pub struct Image {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Linear R, G, B radiance per pixel, row-major (1/sr per unit solar irradiance).
    pub rgb: Vec<[f32; 3]>,
    /// The volume's transparency T_vol (green channel) per pixel, 0…1.
    pub transparency: Vec<f32>,
}

impl Image {
    /// An image from (rgb, T_vol) per pixel, row-major.
    pub fn from_pixels(width: usize, height: usize, pixels: &[([f32; 3], f32)]) -> Self {
        Self {
            width,
            height,
            rgb: pixels.iter().map(|p| p.0).collect(),
            transparency: pixels.iter().map(|p| p.1).collect(),
        }
    }
}
