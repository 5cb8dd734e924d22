//! The scene file's objects and their checks: `[[light]]`, `[[medium]]` and `[[occluder]]`.

use super::*;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct MediumKeys {
    pub(super) field: String,
    pub(super) number_density_per_m3: f64,
    pub(super) min_m: Option<[f64; 3]>,
    pub(super) max_m: Option<[f64; 3]>,
    pub(super) ambient: Option<[f64; 3]>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct OccluderKeys {
    pub(super) shape: String,
    pub(super) min_m: Option<[f64; 3]>,
    pub(super) max_m: Option<[f64; 3]>,
    pub(super) center_m: Option<[f64; 3]>,
    pub(super) radius_m: Option<f64>,
    pub(super) file: Option<String>,
    pub(super) offset_m: Option<[f64; 3]>,
    pub(super) scale: Option<f64>,
    pub(super) albedo: Option<f64>,
}

/// The largest sun irradiance and light intensity per channel a scene may give (the image's
/// unit): a pixel is an f32, and the sun's disk alone multiplies the irradiance by 1/Ω_disk
/// ≈ 1.7·10⁴ and a light's intensity is divided by down to 10⁻⁶ m², so 10³⁰ stays finite.
pub const MAX_SOURCE: f64 = 1e30;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct LightKeys {
    pub(super) position_m: [f64; 3],
    pub(super) intensity: [f64; 3],
    pub(super) spot_direction: Option<[f64; 3]>,
    pub(super) spot_half_angle_deg: Option<f64>,
}

pub(super) fn light(l: &LightKeys) -> Result<Light, String> {
    let p = DVec3::from_array(l.position_m);
    if !p.is_finite() || p.y <= 0.0 {
        return Err(format!(
            "position_m = {:?} must be finite and above the ground (y > 0): a light at or \
             below y = 0 is inside the ground, an occluder",
            l.position_m
        ));
    }
    if l.intensity
        .iter()
        .any(|v| !(v.is_finite() && (0.0..=MAX_SOURCE).contains(v)))
    {
        return Err(format!(
            "intensity = {:?} is outside the allowed range [0, {MAX_SOURCE:e}] per channel",
            l.intensity
        ));
    }
    let spot = match (l.spot_direction, l.spot_half_angle_deg) {
        (None, None) => None,
        (Some(d), Some(a)) => {
            let d = DVec3::from_array(d);
            if !d.is_finite() || d.length() == 0.0 {
                return Err(format!(
                    "spot_direction = {:?} must be a non-zero vector",
                    d
                ));
            }
            if !(a > 0.0 && a < 180.0) {
                return Err(format!(
                    "spot_half_angle_deg = {a} is outside the allowed range (0, 180) degrees \
                     (a light shining everywhere is a point light: leave out the spot keys)"
                ));
            }
            Some((d.normalize(), a))
        }
        _ => {
            return Err("a spot needs both spot_direction and spot_half_angle_deg".into());
        }
    };
    Ok(Light {
        position_m: p,
        intensity: l.intensity,
        spot,
    })
}

pub(super) fn medium(m: &MediumKeys) -> Result<Medium, String> {
    let n = m.number_density_per_m3;
    if !(n.is_finite() && n > 0.0) {
        return Err(format!(
            "number_density_per_m3 = {n} must be finite and > 0 (particles per m³)"
        ));
    }
    let region = match (m.min_m, m.max_m) {
        (None, None) => crate::objects::Region::Everywhere,
        (Some(lo), Some(hi)) => {
            if (0..3).any(|a| !(lo[a].is_finite() && hi[a].is_finite() && lo[a] < hi[a])) {
                return Err(format!(
                    "min_m = {lo:?} must lie below max_m = {hi:?} on every axis (a medium is \
                     a convex, axis-aligned box)"
                ));
            }
            crate::objects::Region::Box {
                min_m: DVec3::from_array(lo),
                max_m: DVec3::from_array(hi),
            }
        }
        _ => {
            return Err(
                "a medium box needs both min_m and max_m (neither: the whole scene)".into(),
            );
        }
    };
    let ambient = m.ambient.unwrap_or([0.0; 3]);
    if ambient.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
        return Err(format!(
            "ambient = {ambient:?} must be ≥ 0 (radiance per channel)"
        ));
    }
    Ok(crate::objects::Medium {
        field: m.field.clone(),
        number_density_per_m3: n,
        region,
        ambient,
    })
}

pub(super) fn occluder(o: &OccluderKeys, base: &Path) -> Result<Occluder, String> {
    use crate::geometry::{Mesh, Sphere, read_obj};
    let albedo = o.albedo.unwrap_or(0.5);
    if !(0.0..=1.0).contains(&albedo) {
        return Err(format!(
            "albedo = {} is outside the allowed range [0, 1]",
            crate::checks::Shown(albedo)
        ));
    }
    let finite = |v: Option<[f64; 3]>, what: &str| {
        v.filter(|v| v.iter().all(|x| x.is_finite()))
            .map(DVec3::from_array)
            .ok_or_else(|| format!("shape {:?} needs a finite {what} = [x, y, z]", o.shape))
    };
    let shape = match o.shape.as_str() {
        "box" => {
            let (lo, hi) = (finite(o.min_m, "min_m")?, finite(o.max_m, "max_m")?);
            if !lo.cmplt(hi).all() {
                return Err(format!(
                    "min_m = {:?} must lie below max_m = {:?} on every axis",
                    lo.to_array(),
                    hi.to_array()
                ));
            }
            crate::objects::OccluderShape::Mesh(Mesh::cuboid(lo, hi))
        }
        "sphere" => {
            let center = finite(o.center_m, "center_m")?;
            let radius = o.radius_m.ok_or("shape \"sphere\" needs radius_m")?;
            positive("radius_m", radius)?;
            crate::objects::OccluderShape::Sphere(Sphere { center, radius })
        }
        "mesh" => {
            let file = o
                .file
                .as_ref()
                .ok_or("shape \"mesh\" needs file (a Wavefront OBJ)")?;
            let scale = o.scale.unwrap_or(1.0);
            positive("scale", scale)?;
            let offset = match o.offset_m {
                None => DVec3::ZERO,
                Some(v) => finite(Some(v), "offset_m")?,
            };
            let mut mesh = read_obj(&base.join(file))?;
            let vertices = mesh.vertices.iter().map(|v| *v * scale + offset).collect();
            mesh = Mesh::new(vertices, std::mem::take(&mut mesh.triangles));
            crate::objects::OccluderShape::Mesh(mesh)
        }
        other => {
            return Err(format!("shape = {other:?} is not one of box, sphere, mesh"));
        }
    };
    Ok(crate::objects::Occluder { shape, albedo })
}
