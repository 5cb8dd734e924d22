//! Riley et al. 2004 §4–5 headless: half-angle slicing (Kniss et al.) of a density grid with a
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
//!    τ = β_ext Δ_l, Δ_l = Δ/(h·l): I ← I e^{−τ} + I (1 − e^{−τ}) (α F_{n+1+τ})^τ, n ← n + α τ
//!    (the expected scatter count, Eq. 21/22; green channel, as Riley's single alpha). F is the
//!    fields' mix weighted like Eq. 6 and linear in fractional n (Riley floored it because his
//!    hardware could not interpolate float textures).
//!
//! S_atm (Eq. 12) is the sunlight left at height p_y by the atmosphere. Per pixel, with the
//! ray's distance K_mid to the middle of the box and T_vol the volume's transparency:
//! L = Sky(0, K_mid) + T_air(K_mid) L_vol + T_vol (Sky(0, K_end) − Sky(0, K_mid)) + T_vol sun,
//! where Sky is [`sky::Atmosphere::inscatter`] (Eqs. 11–15), K_end the ground (black) or ∞,
//! and "sun" the disk of 0.5° (Riley §4.2.4) attenuated by the whole atmosphere.
//!
//! Units: radiance per unit solar irradiance outside the atmosphere (1/sr) per channel.

pub mod cpu;
pub mod gpu;
pub mod image;
pub mod scene;
pub mod sky;
pub mod volume;

pub use scene::RenderScene;
pub use sky::Atmosphere;
pub use volume::DensityGrid;

use mie::crystal::geometry::{Vec3, add_scaled, basis, cross, dot, normalize, scale, sub};

/// Up to this many fields take part in one render (one RGBA texel per voxel).
pub const MAX_FIELDS: usize = 4;

/// Angular diameter of the sun disk (Riley et al. 2004 §4.2.4), degrees.
pub const SUN_DIAMETER_DEG: f64 = 0.5;

/// A pinhole camera; y is up, metres, sea level at y = 0.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    pub position_m: Vec3,
    pub look_at_m: Vec3,
    /// Vertical field of view, degrees.
    pub fov_deg: f64,
}

/// The sun: a collimated source (Riley Eq. 18).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sun {
    /// Above the horizon, (0, 90] degrees (the sky model needs l_y > 0).
    pub elevation_deg: f64,
    /// Measured from +z towards +x, degrees.
    pub azimuth_deg: f64,
    /// Irradiance outside the atmosphere per channel (the image's unit).
    pub irradiance: [f64; 3],
}

impl Sun {
    /// Unit vector towards the sun.
    pub fn direction(&self) -> Vec3 {
        let (e, a) = (
            self.elevation_deg.to_radians(),
            self.azimuth_deg.to_radians(),
        );
        [e.cos() * a.sin(), e.sin(), e.cos() * a.cos()]
    }
}

/// Everything one frame needs besides the tables.
#[derive(Debug, Clone)]
pub struct Frame {
    pub camera: Camera,
    pub sun: Sun,
    pub atmosphere: Atmosphere,
    /// Riley's ξ: back-scattered light added to the phase function in the eye pass (1/sr).
    pub xi: f64,
    pub width: usize,
    pub height: usize,
    pub slices: usize,
    /// Light-buffer texels per side.
    pub light_resolution: usize,
    pub grid: DensityGrid,
}

/// The derived geometry both renderers use (module docs).
#[derive(Debug, Clone, Copy)]
pub struct Setup {
    pub eye: Vec3,
    pub forward: Vec3,
    pub right: Vec3,
    pub up: Vec3,
    pub tan_half_fov_y: f64,
    pub aspect: f64,
    /// Direction the sunlight travels (−sun direction).
    pub light: Vec3,
    pub half: Vec3,
    pub front_to_back: bool,
    /// Plane value of the first slice's centre, and the spacing Δ along h.
    pub slice_start: f64,
    pub slice_step: f64,
    /// Light-buffer axes (⟂ l), origin (u, w of texel (0, 0)'s corner) and texel size.
    pub light_u: Vec3,
    pub light_w: Vec3,
    pub light_origin: [f64; 2],
    pub light_texel: [f64; 2],
}

/// Bad frame parameters, named with their allowed range.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct FrameError(pub String);

impl Frame {
    /// Checks the parameters and derives the slicing geometry.
    pub fn setup(&self) -> Result<Setup, FrameError> {
        let bad = |s: String| Err(FrameError(s));
        if !(1..=8192).contains(&self.width) || !(1..=8192).contains(&self.height) {
            return bad(format!(
                "image size {}×{} is outside the allowed range 1…8192 pixels per side",
                self.width, self.height
            ));
        }
        if !(1..=4096).contains(&self.slices) {
            return bad(format!(
                "slices = {} is outside the allowed range [1, 4096]",
                self.slices
            ));
        }
        if !(2..=4096).contains(&self.light_resolution) {
            return bad(format!(
                "light_resolution = {} is outside the allowed range [2, 4096]",
                self.light_resolution
            ));
        }
        let fov = self.camera.fov_deg;
        if !(fov > 0.0 && fov < 170.0) {
            return bad(format!(
                "camera fov_deg = {fov} is outside the allowed range (0, 170) degrees"
            ));
        }
        let e = self.sun.elevation_deg;
        if !(e > 0.0 && e <= 90.0) {
            return bad(format!(
                "sun elevation_deg = {e} is outside the allowed range (0, 90]: the sky model \
                 (Riley et al. 2004 Eq. 12) needs the sun above the horizon"
            ));
        }
        if self.camera.position_m[1] < 0.0 {
            return bad(format!(
                "camera height {} m is below sea level (y ≥ 0 required)",
                self.camera.position_m[1]
            ));
        }
        if self.grid.contains(self.camera.position_m) {
            return bad(format!(
                "the camera at {:?} m is inside the volumes' box {:?}…{:?} m; half-angle \
                 slicing needs it outside",
                self.camera.position_m, self.grid.min_m, self.grid.max_m
            ));
        }
        let forward = sub(self.camera.look_at_m, self.camera.position_m);
        if dot(forward, forward) == 0.0 {
            return bad("camera look_at_m equals position_m".into());
        }
        let forward = normalize(forward);
        let mut right = cross(forward, [0.0, 1.0, 0.0]);
        if dot(right, right) < 1e-12 {
            right = [1.0, 0.0, 0.0];
        }
        let right = normalize(right);
        let up = cross(right, forward);

        let light = scale(-1.0, self.sun.direction());
        let front_to_back = dot(forward, light) >= 0.0;
        let half = if front_to_back {
            normalize(add_scaled(forward, 1.0, light))
        } else {
            normalize(sub(light, forward))
        };
        let corners = self.grid.corners();
        let along = |axis: Vec3| {
            corners
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &c| {
                    let v = dot(axis, c);
                    (lo.min(v), hi.max(v))
                })
        };
        let (h_lo, h_hi) = along(half);
        let slice_step = (h_hi - h_lo) / self.slices as f64;
        // Light-buffer axes: any orthonormal pair ⟂ l.
        let (light_u, light_w) = basis(light);
        let (u_lo, u_hi) = along(light_u);
        let (w_lo, w_hi) = along(light_w);
        let res = self.light_resolution as f64;
        Ok(Setup {
            eye: self.camera.position_m,
            forward,
            right,
            up,
            tan_half_fov_y: (fov.to_radians() / 2.0).tan(),
            aspect: self.width as f64 / self.height as f64,
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
}

impl Setup {
    /// Unit ray direction through the centre of pixel (i, j), row j = 0 at the top.
    pub fn ray(&self, i: usize, j: usize, width: usize, height: usize) -> Vec3 {
        let sx = (2.0 * (i as f64 + 0.5) / width as f64 - 1.0) * self.tan_half_fov_y * self.aspect;
        let sy = (1.0 - 2.0 * (j as f64 + 0.5) / height as f64) * self.tan_half_fov_y;
        normalize(add_scaled(
            add_scaled(self.forward, sx, self.right),
            sy,
            self.up,
        ))
    }
}

/// A rendered frame: linear radiance per pixel (rows top to bottom) and the volume's
/// transparency (green channel) per pixel.
#[derive(Debug, Clone)]
pub struct Image {
    pub width: usize,
    pub height: usize,
    pub rgb: Vec<[f32; 3]>,
    pub transparency: Vec<f32>,
}
