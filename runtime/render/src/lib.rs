//! The renderers fed by photometeor's tables, over shared parts: the scene file ([`scene`]),
//! density volumes ([`volume`]), the analytic sky ([`sky`]), camera and sun ([`camera`]), and
//! image output ([`image`]).
//!
//! Each render model is a module of its own with the same shape — scene keys → frame → CPU
//! reference → GPU:
//! - [`riley`]: Riley et al. 2004's half-angle slicing with a light buffer and an eye buffer,
//!   the multiple-scattering tables Ams_n and F_n for the angular spread of sunlight (`--model
//!   riley`, the default).
//!
//! - [`truth`]: an unbiased spectral Monte Carlo path tracer of the full radiative transfer on
//!   the same scene (`--model truth`), the reference every fast model is measured against.
//!
//! A new model (Miyazaki's shadow-view slices, Max et al.'s diffusion,
//! Biri's analytic single scattering) goes beside them as `src/<model>/`, using the same
//! scene, volumes, sky, camera and image.
//!
//! Units: radiance per unit solar irradiance outside the atmosphere (1/sr) per channel; lengths
//! in metres, y up, sea level at y = 0.

#![warn(missing_docs)]

pub mod camera;
pub mod error_map;
pub mod image;
pub mod riley;
pub mod scene;
pub mod sky;
pub mod truth;
pub mod volume;

pub use camera::{Camera, Sun};
pub use scene::RenderScene;
pub use sky::Atmosphere;
pub use volume::DensityGrid;

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
    /// Riley's ξ: back-scattered light added to the phase function in the eye pass (1/sr).
    pub xi: f64,
    /// Image width, 1…8192 pixels.
    pub width: usize,
    /// Image height, 1…8192 pixels.
    pub height: usize,
    /// Number S of half-angle slices through the grid's box, [1, 4096].
    pub slices: usize,
    /// Light-buffer texels per side.
    pub light_resolution: usize,
    /// Number densities, channel i = field i of the tables.
    pub grid: DensityGrid,
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
