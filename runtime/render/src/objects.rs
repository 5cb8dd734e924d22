//! The objects of a scene besides the density volumes, shared by every model that draws them:
//! point and spot lights (`[[light]]`), homogeneous media (`[[medium]]`) in a region, and
//! Lambertian occluders (`[[occluder]]`: meshes and spheres, [`crate::geometry`]).

use glam::DVec3;

use crate::geometry::{self, Mesh, Sphere};

/// A point light, optionally a spot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Light {
    /// Position (m); above the ground (y > 0).
    pub position_m: DVec3,
    /// Radiant intensity per channel, in the image's unit × m² (1/sr per unit solar
    /// irradiance × m²): at distance r it gives irradiance I/r².
    pub intensity: [f64; 3],
    /// A spot's unit axis and half-angle (degrees, (0, 180]); `None`: all directions.
    pub spot: Option<(DVec3, f64)>,
}

/// Where a medium is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Region {
    /// Everywhere (§5.1: the scene is covered by the medium).
    Everywhere,
    /// The axis-aligned box [min, max] (§5.2).
    Box {
        /// Lower corner (m).
        min_m: DVec3,
        /// Upper corner (m).
        max_m: DVec3,
    },
}

impl Region {
    /// The part [a, b] of the ray o + x d, x ∈ [0, x_max], inside the region.
    pub fn span(&self, o: DVec3, d: DVec3, x_max: f64) -> Option<(f64, f64)> {
        let (a, b) = match self {
            Self::Everywhere => (0.0, x_max),
            Self::Box { min_m, max_m } => {
                let (a, b) = geometry::ray_box(o, d, *min_m, *max_m)?;
                (a.max(0.0), b.min(x_max))
            }
        };
        (a < b).then_some((a, b))
    }

    /// Whether `p` is inside.
    pub fn contains(&self, p: DVec3) -> bool {
        match self {
            Self::Everywhere => true,
            Self::Box { min_m, max_m } => p.cmpge(*min_m).all() && p.cmple(*max_m).all(),
        }
    }
}

/// A homogeneous medium of one baked field (`[[medium]]`).
#[derive(Debug, Clone, PartialEq)]
pub struct Medium {
    /// The field's name.
    pub field: String,
    /// Particles per m³, > 0: β_ext = N σ_ext.
    pub number_density_per_m3: f64,
    /// Where it is.
    pub region: Region,
    /// The paper's ambient fog (§3, §5.1.2): a radiance per channel (the image's unit) that a
    /// ray gains in proportion 1 − e^{−τ} of the medium it crosses, standing in for multiple
    /// scattering. ≥ 0.
    pub ambient: [f64; 3],
}

/// An occluder's geometry.
#[derive(Debug, Clone, PartialEq)]
pub enum OccluderShape {
    /// A triangle mesh (a box, or an OBJ file).
    Mesh(Mesh),
    /// A sphere.
    Sphere(Sphere),
}

/// A shadow caster with a Lambertian surface (`[[occluder]]`).
#[derive(Debug, Clone, PartialEq)]
pub struct Occluder {
    /// Its geometry.
    pub shape: OccluderShape,
    /// Lambertian albedo, [0, 1].
    pub albedo: f64,
}

impl Occluder {
    /// The nearest hit of o + x d in (ε, x_max): distance and normal facing the ray.
    pub fn hit(&self, o: DVec3, d: DVec3, x_max: f64) -> Option<(f64, DVec3)> {
        match &self.shape {
            OccluderShape::Mesh(m) => m.hit(o, d, x_max),
            OccluderShape::Sphere(s) => s.hit(o, d, x_max),
        }
    }

    /// How many times the open segment p → q is blocked (triangles crossed; 1 for a sphere).
    pub fn blockers(&self, p: DVec3, q: DVec3) -> usize {
        match &self.shape {
            OccluderShape::Mesh(m) => m.crossings(p, q),
            OccluderShape::Sphere(s) => s.blocks(p, q) as usize,
        }
    }

    /// Axis-aligned bounds.
    pub fn bounds(&self) -> (DVec3, DVec3) {
        match &self.shape {
            OccluderShape::Mesh(m) => m.bounds,
            OccluderShape::Sphere(s) => (
                s.center - DVec3::splat(s.radius),
                s.center + DVec3::splat(s.radius),
            ),
        }
    }

    /// Whether `p` is inside (a closed mesh's parity, a sphere's radius).
    pub fn contains(&self, p: DVec3) -> bool {
        match &self.shape {
            OccluderShape::Mesh(m) => m.contains(p),
            OccluderShape::Sphere(s) => (p - s.center).length() < s.radius,
        }
    }
}

/// The index in `tables` of the field a `[[medium]]` uses.
pub fn field_index(
    tables: &runtime::Tables,
    name: &str,
) -> Result<usize, crate::checks::FrameError> {
    tables
        .fields
        .iter()
        .position(|f| f.name == name)
        .ok_or_else(|| {
            crate::checks::FrameError(format!(
                "a [[medium]] uses field {name:?}, which the tables do not hold"
            ))
        })
}

/// Refuses media that overlap, or a medium filling the scene beside others: the models that
/// draw media attenuate each ray by one medium at a time.
pub fn check_media(media: &[Medium]) -> Result<(), crate::checks::FrameError> {
    let bad = |s: String| Err(crate::checks::FrameError(s));
    let everywhere = media.iter().position(|m| m.region == Region::Everywhere);
    if let Some(i) = everywhere
        && media.len() > 1
    {
        return bad(format!(
            "[[medium]] {} fills the whole scene, so it cannot share it with {} other \
             medium/media (give each a box, min_m and max_m, that do not overlap)",
            i + 1,
            media.len() - 1
        ));
    }
    for (i, a) in media.iter().enumerate() {
        for (j, b) in media.iter().enumerate().skip(i + 1) {
            if let (
                Region::Box {
                    min_m: a0,
                    max_m: a1,
                },
                Region::Box {
                    min_m: b0,
                    max_m: b1,
                },
            ) = (a.region, b.region)
                && a0.cmplt(b1).all()
                && b0.cmplt(a1).all()
            {
                return bad(format!(
                    "[[medium]] {} and [[medium]] {} overlap: the media of one scene must not \
                     (each ray's attenuation is one medium's at a time)",
                    i + 1,
                    j + 1
                ));
            }
        }
    }
    Ok(())
}

/// Refuses a light inside an occluder (for every model that draws occluders).
pub fn check_lights(
    lights: &[Light],
    occluders: &[Occluder],
) -> Result<(), crate::checks::FrameError> {
    for (i, l) in lights.iter().enumerate() {
        for (k, o) in occluders.iter().enumerate() {
            if o.contains(l.position_m) {
                return Err(crate::checks::FrameError(format!(
                    "[[light]] {}: position_m = {:?} is inside [[occluder]] {}: its light could \
                     never leave it",
                    i + 1,
                    l.position_m.to_array(),
                    k + 1
                )));
            }
        }
    }
    Ok(())
}
