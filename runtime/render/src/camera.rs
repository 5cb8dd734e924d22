//! The camera (a pinhole, or orthographic: one direction, a point per pixel) and the sun.

use glam::DVec3;

/// Angular diameter of the sun disk (Riley et al. 2004 §4.2.4), degrees.
pub const SUN_DIAMETER_DEG: f64 = 0.5;

/// A camera; y is up, metres, sea level at y = 0.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// Eye position (m), or the centre of an orthographic image; at or above sea level
    /// (y ≥ 0) and outside the volumes' box.
    pub position_m: DVec3,
    /// Point the camera looks at (m); must differ from `position_m`.
    pub look_at_m: DVec3,
    /// Vertical field of view, degrees (a perspective camera's).
    pub fov_deg: f64,
    /// How pixels map to rays.
    pub projection: Projection,
}

/// How a camera's pixels map to rays.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Projection {
    /// A pinhole at `position_m`: pixel (i, j) is the ray from the eye through it
    /// ([`pixel_ray`]), `fov_deg` wide vertically.
    #[default]
    Perspective,
    /// Every pixel looks along the view direction from its own point of the image plane
    /// through `position_m` (normal to the view): the radiance along one direction at one
    /// place, as radiative-transfer benchmarks report per column. The image is `width_m`
    /// wide; its height follows the aspect.
    Orthographic {
        /// Width of the image on its plane (m).
        width_m: f64,
    },
}

impl Camera {
    /// The unit view direction v, right axis v × y (x when looking straight up or down) and
    /// up axis right × v; `None` when `look_at_m` equals `position_m`.
    pub fn axes(&self) -> Option<(DVec3, DVec3, DVec3)> {
        let forward = self.look_at_m - self.position_m;
        if forward.dot(forward) == 0.0 {
            return None;
        }
        let forward = forward.normalize();
        let mut right = forward.cross(DVec3::Y);
        if right.dot(right) < 1e-12 {
            right = DVec3::X;
        }
        let right = right.normalize();
        Some((forward, right, right.cross(forward)))
    }

    /// tan of half the vertical field of view.
    pub fn tan_half_fov(&self) -> f64 {
        (self.fov_deg.to_radians() / 2.0).tan()
    }

    /// Half the image's height on its plane (m) for an orthographic camera of a `width` ×
    /// `height` image; `None` for a perspective one.
    pub fn ortho_half_height_m(&self, (width, height): (usize, usize)) -> Option<f64> {
        match self.projection {
            Projection::Perspective => None,
            Projection::Orthographic { width_m } => {
                Some(0.5 * width_m * height as f64 / width as f64)
            }
        }
    }

    /// The ray of pixel (i, j) (row 0 at the top) of a `width` × `height` image: its origin
    /// and unit direction, for camera axes `axes` ([`Camera::axes`]).
    pub fn pixel(
        &self,
        axes: (DVec3, DVec3, DVec3),
        (i, j): (usize, usize),
        (width, height): (usize, usize),
    ) -> (DVec3, DVec3) {
        match self.ortho_half_height_m((width, height)) {
            None => (
                self.position_m,
                pixel_ray(axes, self.tan_half_fov(), (i, j), (width, height)),
            ),
            Some(half) => {
                let aspect = width as f64 / height as f64;
                let sx = (2.0 * (i as f64 + 0.5) / width as f64 - 1.0) * half * aspect;
                let sy = (1.0 - 2.0 * (j as f64 + 0.5) / height as f64) * half;
                (self.position_m + sx * axes.1 + sy * axes.2, axes.0)
            }
        }
    }
}

/// The unit ray through the centre of pixel (i, j) (row j = 0 at the top) of a `width` ×
/// `height` image, for camera axes `(forward, right, up)` and tan of half the vertical fov.
pub fn pixel_ray(
    axes: (DVec3, DVec3, DVec3),
    tan_half_fov_y: f64,
    (i, j): (usize, usize),
    (width, height): (usize, usize),
) -> DVec3 {
    let aspect = width as f64 / height as f64;
    let sx = (2.0 * (i as f64 + 0.5) / width as f64 - 1.0) * tan_half_fov_y * aspect;
    let sy = (1.0 - 2.0 * (j as f64 + 0.5) / height as f64) * tan_half_fov_y;
    ((axes.0 + sx * axes.1) + sy * axes.2).normalize()
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
