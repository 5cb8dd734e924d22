//! Miyazaki, Dobashi & Nishita's shadow-view slices (`--model miyazaki`): single scattering
//! of sunlight by the clouds and the air with a constant multiple-scattering term k_multi,
//! attenuated towards the sun and towards the eye in one pass of slices, with the clouds'
//! shadows on the ground and on the air (light shafts).
//!
//! # The method as the paper states it (§3–4)
//! - **Eq. 1**: I_v = I_back g_view(T) + I_sun ∫₀ᵀ ((β_cl(α) + k_multi) ρ_cl + β_atm(α) ρ_atm)
//!   g_view(t) g_sun(s) dt, discretized over n slices as **Eq. 4** I_v = I_back g_view(T) +
//!   Σᵢ ΔI_v(tᵢ) with **Eq. 5** ΔI_v = Δt(p) I_sun (…) g_view(tᵢ) g_sun(sᵢ).
//! - **Shadow-view slices (§4.2)**: parallel planes whose normal n splits the angle θ between
//!   the view direction V_e and V′ (the direction towards the sun V_s, or −V_s when
//!   V_e·V_s < 0) as θ_e : θ_s = 1 : a ([`Settings::a`], the paper's 1.0–2.0): n is the
//!   slerp of V_e towards V′ by θ/(1 + a). a = 1 is Riley's half-angle vector; the larger a,
//!   the closer the slices are to facing the eye and the less the sampling interval
//!   Δt(p) = Δ/|n·d(p)| differs between pixels. Slices are processed from the sun's side, so
//!   the eye composites back to front when V_e·V_s ≥ 0 and front to back otherwise.
//! - **Shadow surface (Eq. 10)**: a buffer perpendicular to the sun, initialized to 1, into
//!   which each slice's cloud density is projected: g_sun_cl ← g_sun_cl · exp(−k_cl ρ_cl Δs)
//!   with Δs = Δ/|n·V_s| the same for every texel (**Eq. 7**). Per slice the paper updates the
//!   shadow surface *first*, then the screen (§4.1: "First … Δg_sun−cl is calculated by
//!   Eq. 10"), so a slice is lit through itself.
//! - **The screen (Eqs. 8, 9, §4.3)**: per pixel and slice ΔI_SVS = Δt ((β_cl(α) + k_multi)
//!   ρ_cl + β_atm(α) ρ_atm) g_sun_atm g_sun_cl and Δg_view = exp(−(k_atm ρ_atm + k_cl ρ_cl) Δt),
//!   blended back to front as S ← C + Δg_view S or front to back as S ← S + α* C, α* ← α* Δg_view
//!   (C = I_sun ΔI_SVS). As printed, a slice's own light is not attenuated by the slice, and C
//!   is the Riemann term Δt·β, not Riley's α(1 − e^{−τ}).
//! - **Atmosphere (§4.4)**: the atmospheric particles are the Rayleigh air, β_sl e^{−h/H}
//!   with its phase function (Riley Eq. 1), and the aerosol layer `[haze]` ([`crate::frame::Haze`]):
//!   N_0 e^{−h/H_h} particles of a baked field (kind `haze`) with its own Ams_1 (or
//!   Cornette–Shanks), σ_sca and σ_ext. g_sun_atm(h), the sunlight reaching height h, is the
//!   sky model's Eq. 12 ([`crate::sky::Atmosphere::sunlight`]) times its analogue for the haze,
//!   e^{−N_0 σ_ext H_h e^{−h/H_h}/sin e}; the paper tabulates the same in its atmosphere
//!   texture. k_multi does not apply to the haze (Eq. 1).
//!
//! # With our tables
//! - β_cl(α) ρ_cl = Σ_f ρ_f σ_sca,f P_f(α) per channel, P_f = the field's Ams_1 (its
//!   single-scattering phase function, 1/sr), or Cornette & Shanks's function (the paper's
//!   Eq. 3, which it calls Henyey–Greenstein) over 4π with the field's own asymmetry g from
//!   Ams_1 ([`SvsPhase::CornetteShanks`], so the paper's images can be reproduced and the
//!   difference shown). k_cl ρ_cl = Σ_f ρ_f σ_ext,f.
//! - k_multi (1/sr) is added to the phase function of the cloud fields only, as in Eq. 1:
//!   (P_f + k_multi) σ_sca,f ρ_f.
//!
//! # Where this departs from, or fills in, the paper
//! - The slices span the volumes' box only. Outside it, along each view ray, the air is
//!   integrated with the final shadow surface where it may be shadowed (the far side of the
//!   slices from the sun; unshadowed on the sun's side), so light shafts continue below the
//!   box down to the ground: without haze, Eq. 14 in closed form less the shadow's deficit by a
//!   64-point midpoint rule over the shadow's prism; with haze, both species by the midpoint
//!   rule at 0.02 of an optical depth (at most 2 km) per step, until the transmittance from
//!   the eye is below 10⁻⁷.
//! - The ground is a Lambertian plane at y = 0 of albedo [`crate::frame::Frame::ground_albedo`], lit
//!   by the sun through the air (Eq. 12) and the final shadow surface; the paper draws shadows
//!   on its terrain but gives no reflectance model. No skylight reaches the ground.
//! - The shadow surface covers the box's footprint as seen from the sun; outside it there is
//!   no cloud and g_sun_cl = 1 (not the edge texel).

pub mod cpu;
pub mod gpu;

use std::time::Instant;

use glam::DVec3;
use serde::{Deserialize, Serialize};

use runtime::gpu::{Gpu, GpuTables, TexelFormat};

use crate::gpu::RenderError;
use crate::model::{Device, Job, Model, Need, Pass, RenderResult, Rendered, image_need};
use crate::shading::{MAX_PHASE_TERM, check_slicing};
use crate::{checks::FrameError, frame::Frame, geometry::basis};

/// `--model miyazaki`.
pub struct Miyazaki;

impl Model for Miyazaki {
    const NAME: &'static str = "miyazaki";
    const ABOUT: &'static str = "Miyazaki, Dobashi & Nishita: shadow-view slices, single \
        scattering plus a constant k_multi, shadows on the ground and in the air, a [haze] layer";
    const TEXELS: TexelFormat = TexelFormat::Auto;
    const GPU: bool = true;
    type Settings = Settings;
    type Renderer = gpu::Renderer;

    fn check(s: &Settings) -> Result<(), FrameError> {
        check(s)
    }

    fn check_frame(s: &Settings, frame: &Frame) -> Result<(), FrameError> {
        frame.sunlight_only(Self::NAME, true)?;
        setup(frame, s).map(|_| ())
    }

    fn memory(s: &Settings, pixels: u64, _dims: [usize; 3]) -> Vec<Need> {
        // Per pixel: its ray (24 B), the scattering texture (128), S, α*, T (72), the composed
        // pixel and the image (32): measured 259 B; per shadow texel, g_sun per channel (24).
        let res = s.light_resolution as u64;
        vec![
            image_need("the screen buffers and image", pixels, 264),
            Need {
                what: "the shadow surface",
                bytes: res * res * 24,
                setting: "[render.miyazaki] light_resolution".into(),
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
            "shadow-view slices (CPU reference): {}×{}, {} slices, a = {}, k_multi = {} /sr, \
             shadow surface {}²: {seconds:.2} s",
            image.width, image.height, s.slices, s.a, s.k_multi, s.light_resolution
        );
        Ok(Rendered::cpu_frame(image, seconds, summary))
    }

    fn render_gpu(s: &Settings, job: &Job, on: Device<gpu::Renderer>) -> RenderResult {
        let (renderer, gpu, tables) = (on.renderer, on.gpu, on.tables);
        let (image, t) = renderer.render(gpu, job.tables, tables, job.frame, s)?;
        let summary = format!(
            "shadow-view slices ({}): {}×{}, {} slices, a = {}, k_multi = {} /sr, shadow surface \
             {}²: {}",
            gpu.describe(),
            image.width,
            image.height,
            s.slices,
            s.a,
            s.k_multi,
            s.light_resolution,
            t.describe()
        );
        Ok(Rendered::plain(image, Pass::of_gpu(&t), summary))
    }
}

/// The allowed range of [`Settings::a`]: (0, 2]. The paper uses 1.0–2.0; below 1 the slices
/// turn towards the sun and away from the eye, and at 0 they face the sun, edge-on to an eye
/// at 90° to it.
pub const A_RANGE: (f64, f64) = (0.0, 2.0);

/// The phase function of the clouds in Eqs. 1 and 8.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SvsPhase {
    /// Each field's baked Ams_1 (its exact single-scattering phase function), per channel.
    Tables,
    /// Cornette & Shanks's function (Miyazaki's Eq. 3) with each field's g per channel.
    CornetteShanks,
}

impl SvsPhase {
    /// Parses the scene key's value, `tables` or `cornette_shanks`.
    pub fn parse(text: &str) -> Option<Self> {
        match text {
            "tables" => Some(Self::Tables),
            "cornette_shanks" => Some(Self::CornetteShanks),
            _ => None,
        }
    }
}

/// The model's settings, `[render.miyazaki]` (the ground albedo is the frame's).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Settings {
    /// Number of shadow-view slices through the volumes' box, [1, 4096] (default 256).
    pub slices: usize,
    /// Shadow-surface texels per side, [2, 4096] (default 512).
    pub light_resolution: usize,
    /// θ_e : θ_s = 1 : a, in [`A_RANGE`] (0 excluded).
    pub a: f64,
    /// The constant multiple-scattering term of the clouds (1/sr), ≥ 0.
    pub k_multi: f64,
    /// The clouds' phase function.
    pub phase: SvsPhase,
}

impl Default for Settings {
    fn default() -> Self {
        Self {
            slices: 256,
            light_resolution: 512,
            a: 1.5,
            k_multi: 0.0,
            phase: SvsPhase::Tables,
        }
    }
}

/// The derived geometry of the slices and the shadow surface.
#[derive(Debug, Clone, Copy)]
pub struct SvsSetup {
    /// The camera: each pixel's ray ([`SvsSetup::pixel`]).
    pub camera: crate::camera::Camera,
    /// Eye position (m), the centre of an orthographic image.
    pub eye: DVec3,
    /// Camera axes: view direction, right, up.
    pub axes: (DVec3, DVec3, DVec3),
    /// Unit direction towards the sun, V_s.
    pub to_sun: DVec3,
    /// The slices' unit normal n.
    pub normal: DVec3,
    /// Whether the eye composites back to front (V_e·V_s ≥ 0); otherwise front to back.
    pub back_to_front: bool,
    /// Plane values n·x of the slices' range over the box.
    pub range: (f64, f64),
    /// Slice spacing Δ along n (m).
    pub step: f64,
    /// The sun's path through one slice, Δs = Δ/|n·V_s| (m).
    pub sun_step: f64,
    /// Shadow-surface axes (⟂ V_s).
    pub shadow_u: DVec3,
    /// Second shadow-surface axis.
    pub shadow_w: DVec3,
    /// (u, w) of texel (0, 0)'s corner (m).
    pub shadow_origin: [f64; 2],
    /// Texel size along u and w (m).
    pub shadow_texel: [f64; 2],
}

/// The slices' normal for view direction `ve`, direction towards the sun `vs` and ratio `a`
/// (module docs): the slerp of V_e towards V′ = ±V_s by θ/(1 + a).
pub fn slice_normal(ve: DVec3, vs: DVec3, a: f64) -> DVec3 {
    let v = if ve.dot(vs) >= 0.0 { vs } else { -vs };
    let theta = ve.dot(v).clamp(-1.0, 1.0).acos();
    if theta < 1e-9 {
        return ve;
    }
    let theta_e = theta / (1.0 + a);
    ((theta - theta_e).sin() * ve + theta_e.sin() * v).normalize()
}

/// Checks the settings, naming the key, its value and the range.
pub fn check(settings: &Settings) -> Result<(), FrameError> {
    let bad = |s: String| Err(FrameError(s));
    check_slicing(settings.slices, settings.light_resolution, "shadow surface")?;
    if !(settings.a.is_finite() && settings.a > A_RANGE.0 && settings.a <= A_RANGE.1) {
        return bad(format!(
            "a = {} is outside the allowed range ({}, {}] (the paper uses 1.0–2.0)",
            crate::checks::Shown(settings.a),
            A_RANGE.0,
            A_RANGE.1
        ));
    }
    if !(settings.k_multi.is_finite() && (0.0..=MAX_PHASE_TERM).contains(&settings.k_multi)) {
        return bad(format!(
            "k_multi = {} is outside the allowed range [0, {:e}] (1/sr)",
            crate::checks::Shown(settings.k_multi),
            MAX_PHASE_TERM
        ));
    }
    Ok(())
}

/// Checks the frame and the settings and derives the geometry.
pub fn setup(frame: &Frame, settings: &Settings) -> Result<SvsSetup, FrameError> {
    frame.check_view()?;
    check(settings)?;
    let bad = |s: String| Err(FrameError(s));
    // A pinhole's check: each orthographic pixel starts at its own point of the image plane,
    // and its ray skips the slabs behind that point (t ≤ 0) wherever it lies.
    let perspective = frame.camera.ortho_half_height_m((1, 1)).is_none();
    if perspective && frame.grid.contains(frame.camera.position_m) {
        return bad(format!(
            "the camera at {:?} m is inside the volumes' box {:?}…{:?} m; shadow-view slicing \
             needs it outside",
            frame.camera.position_m, frame.grid.min_m, frame.grid.max_m
        ));
    }
    let axes = frame.camera.axes().expect("checked by check_view");
    let to_sun = frame.sun.direction();
    let normal = slice_normal(axes.0, to_sun, settings.a);
    let along = |axis: DVec3| frame.grid.span_along(axis);
    let range = along(normal);
    let step = (range.1 - range.0) / settings.slices as f64;
    let (shadow_u, shadow_w) = basis(to_sun);
    let (u_lo, u_hi) = along(shadow_u);
    let (w_lo, w_hi) = along(shadow_w);
    let res = settings.light_resolution as f64;
    Ok(SvsSetup {
        camera: frame.camera,
        eye: frame.camera.position_m,
        axes,
        to_sun,
        normal,
        back_to_front: axes.0.dot(to_sun) >= 0.0,
        range,
        step,
        sun_step: step / normal.dot(to_sun).abs(),
        shadow_u,
        shadow_w,
        shadow_origin: [u_lo, w_lo],
        shadow_texel: [(u_hi - u_lo) / res, (w_hi - w_lo) / res],
    })
}

impl SvsSetup {
    /// The ray of pixel (i, j), row j = 0 at the top: its origin and unit direction
    /// ([`crate::camera::Camera::pixel`]).
    pub fn pixel(&self, i: usize, j: usize, width: usize, height: usize) -> (DVec3, DVec3) {
        self.camera.pixel(self.axes, (i, j), (width, height))
    }

    /// Plane value of the centre of slice `k` in processing order (from the sun's side).
    pub fn plane(&self, k: usize) -> f64 {
        let offset = (k as f64 + 0.5) * self.step;
        if self.normal.dot(self.to_sun) > 0.0 {
            self.range.1 - offset
        } else {
            self.range.0 + offset
        }
    }

    /// The point where shadow texel (a, b)'s sun ray meets the plane n·x = `c`.
    pub fn shadow_point(&self, a: usize, b: usize, c: f64) -> DVec3 {
        let q = (self.shadow_origin[0] + (a as f64 + 0.5) * self.shadow_texel[0]) * self.shadow_u
            + (self.shadow_origin[1] + (b as f64 + 0.5) * self.shadow_texel[1]) * self.shadow_w;
        q + (c - self.normal.dot(q)) / self.normal.dot(self.to_sun) * self.to_sun
    }

    /// Continuous shadow-surface coordinates of `p` (texel centres at integers).
    pub fn shadow_coords(&self, p: DVec3) -> [f64; 2] {
        [
            (self.shadow_u.dot(p) - self.shadow_origin[0]) / self.shadow_texel[0] - 0.5,
            (self.shadow_w.dot(p) - self.shadow_origin[1]) / self.shadow_texel[1] - 0.5,
        ]
    }

    /// Whether `p` lies on the sun's side of every slice (its sunlight crosses none of them).
    pub fn sunward_of_slices(&self, p: DVec3) -> bool {
        let c = self.normal.dot(p);
        if self.normal.dot(self.to_sun) > 0.0 {
            c >= self.range.1
        } else {
            c <= self.range.0
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_normal_splits_the_angle_as_one_to_a() {
        let ve = DVec3::new(0.0, 0.0, 1.0);
        for &(vs, a) in &[
            (DVec3::new(1.0, 0.0, 1.0), 1.0),
            (DVec3::new(1.0, 0.5, 0.2), 2.0),
            (DVec3::new(0.3, 0.4, -1.0), 1.5),
        ] {
            let vs = vs.normalize();
            let n = slice_normal(ve, vs, a);
            let v = if ve.dot(vs) >= 0.0 { vs } else { -vs };
            let (te, ts) = (n.angle_between(ve), n.angle_between(v));
            assert!((ts - a * te).abs() < 1e-12, "{te} {ts} a {a}");
            assert!((te + ts - ve.angle_between(v)).abs() < 1e-12);
        }
        // a = 1 is Riley's half-angle vector.
        let vs = DVec3::new(0.6, 0.8, 0.0);
        let n = slice_normal(ve, vs, 1.0);
        assert!((n - (ve + vs).normalize()).length() < 1e-12);
    }
}
