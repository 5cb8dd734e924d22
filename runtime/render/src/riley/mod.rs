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
//!    interpolate float textures). keep is [`crate::LightUpdate`]:
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

use glam::DVec3;

use crate::{Frame, FrameError};

pub use crate::basis;

/// The derived geometry both renderers use (module docs).
#[derive(Debug, Clone, Copy)]
pub struct Setup {
    /// Eye position (m).
    pub eye: DVec3,
    /// Unit view direction v.
    pub forward: DVec3,
    /// Unit camera right axis, v × y (x when looking straight up or down).
    pub right: DVec3,
    /// Unit camera up axis, right × v.
    pub up: DVec3,
    /// tan of half the vertical field of view.
    pub tan_half_fov_y: f64,
    /// Image width / height.
    pub aspect: f64,
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

impl Frame {
    /// Checks the parameters and derives the slicing geometry.
    pub fn setup(&self) -> Result<Setup, FrameError> {
        self.check_view()?;
        let bad = |s: String| Err(FrameError(s));
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
        if self.grid.contains(self.camera.position_m) {
            return bad(format!(
                "the camera at {:?} m is inside the volumes' box {:?}…{:?} m; half-angle \
                 slicing needs it outside",
                self.camera.position_m, self.grid.min_m, self.grid.max_m
            ));
        }
        let (forward, right, up) = self.camera.axes().expect("checked by check_view");
        let fov = self.camera.fov_deg;

        let light = -self.sun.direction();
        let front_to_back = forward.dot(light) >= 0.0;
        let half = if front_to_back {
            (forward + light).normalize()
        } else {
            (light - forward).normalize()
        };
        let along = |axis: DVec3| self.grid.span_along(axis);
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
    pub fn ray(&self, i: usize, j: usize, width: usize, height: usize) -> DVec3 {
        crate::camera::pixel_ray(
            (self.forward, self.right, self.up),
            self.tan_half_fov_y,
            (i, j),
            (width, height),
        )
    }
}
