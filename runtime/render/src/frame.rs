//! What one frame is rendered from besides the tables: the view, the sun, the sky, the grid
//! and the scene's objects ([`Frame`]), and the checks every model makes of them.

use crate::camera::{Camera, Sun};
use crate::checks::{FrameError, Shown};
use crate::objects;
use crate::sky::Atmosphere;
use crate::volume::DensityGrid;

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
        if self.camera.projection == crate::camera::Projection::Perspective
            && !(fov > 0.0 && fov < 170.0)
        {
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

    /// Refuses a periodic volume, which only the truth draws, naming `model`.
    pub fn bounded_only(&self, model: &str) -> Result<(), FrameError> {
        if self.grid.periodic {
            return Err(FrameError(format!(
                "[[volume]] periodic = true: --model {model} draws bounded volumes only (its \
                 grid ends at the box); render it with --model truth"
            )));
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
