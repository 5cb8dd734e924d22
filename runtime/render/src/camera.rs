//! The pinhole camera and the sun.

use glam::DVec3;

/// A pinhole camera; y is up, metres, sea level at y = 0.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// Eye position (m); at or above sea level (y ≥ 0) and outside the volumes' box.
    pub position_m: DVec3,
    /// Point the camera looks at (m); must differ from `position_m`.
    pub look_at_m: DVec3,
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
    pub fn direction(&self) -> DVec3 {
        let (e, a) = (
            self.elevation_deg.to_radians(),
            self.azimuth_deg.to_radians(),
        );
        DVec3::new(e.cos() * a.sin(), e.sin(), e.cos() * a.cos())
    }
}
