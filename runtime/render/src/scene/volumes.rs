//! The scene file's `[[volume]]` tables and their checks: each shape's keys, the size
//! profiles, and the grid files they read.

use super::*;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct VolumeKeys {
    pub(super) field: String,
    pub(super) shape: String,
    pub(super) number_density_per_m3: f64,
    pub(super) center_m: Option<[f64; 3]>,
    pub(super) radius_m: Option<f64>,
    pub(super) height_m: Option<f64>,
    pub(super) bottom_m: Option<f64>,
    pub(super) top_m: Option<f64>,
    pub(super) size_m: Option<f64>,
    pub(super) thickness_m: Option<f64>,
    pub(super) file: Option<String>,
    pub(super) dims: Option<[usize; 3]>,
    pub(super) min_m: Option<[f64; 3]>,
    pub(super) max_m: Option<[f64; 3]>,
    pub(super) seed: Option<u64>,
    pub(super) r_eff_um: Option<ProfileKeys>,
    pub(super) median_radius_um: Option<ProfileKeys>,
    pub(super) radius_um: Option<ProfileKeys>,
    pub(super) periodic: Option<bool>,
}

/// A size profile `{ base, top }` (crate::volume::SizeProfile).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct ProfileKeys {
    pub(super) base: f64,
    pub(super) top: f64,
}

pub(super) fn volume(v: &VolumeKeys, base: &Path) -> Result<Volume, String> {
    let need = |what: &str, x: Option<f64>| -> Result<f64, String> {
        let x = x.ok_or_else(|| format!("shape {:?} needs {what}", v.shape))?;
        positive(what, x)
    };
    let center = |c: Option<[f64; 3]>| {
        c.filter(|c| c.iter().all(|x| x.is_finite()))
            .map(DVec3::from_array)
            .ok_or_else(|| format!("shape {:?} needs a finite center_m = [x, y, z]", v.shape))
    };
    let density = v.number_density_per_m3;
    if !(density.is_finite() && density > 0.0) {
        return Err(format!(
            "number_density_per_m3 = {density} must be finite and > 0 (particles per m³)"
        ));
    }
    let shape = match v.shape.as_str() {
        "cumulus" => Shape::Cumulus {
            center_m: center(v.center_m)?,
            radius_m: need("radius_m", v.radius_m)?,
            height_m: need("height_m", v.height_m)?,
        },
        "cirrus" => Shape::Cirrus {
            center_m: center(v.center_m)?,
            size_m: need("size_m", v.size_m)?,
            thickness_m: need("thickness_m", v.thickness_m)?,
        },
        "rain_shaft" => {
            let bottom = v.bottom_m.unwrap_or(0.0);
            let top = need("top_m", v.top_m)?;
            if !(bottom.is_finite() && bottom < top) {
                return Err(format!("bottom_m = {bottom} must be below top_m = {top}"));
            }
            Shape::RainShaft {
                center_m: center(v.center_m)?,
                radius_m: need("radius_m", v.radius_m)?,
                bottom_m: bottom,
                top_m: top,
            }
        }
        "grid" => {
            let file = v.file.as_ref().ok_or("shape \"grid\" needs file")?;
            let dims = v.dims.ok_or("shape \"grid\" needs dims = [nx, ny, nz]")?;
            let (lo, hi) = (
                v.min_m.ok_or("shape \"grid\" needs min_m")?,
                v.max_m.ok_or("shape \"grid\" needs max_m")?,
            );
            if (0..3).any(|a| !(lo[a].is_finite() && hi[a].is_finite() && lo[a] < hi[a])) {
                return Err(format!(
                    "min_m = {lo:?} must lie below max_m = {hi:?} on every axis"
                ));
            }
            let (file, min_m, max_m) = (
                base.join(file),
                DVec3::from_array(lo),
                DVec3::from_array(hi),
            );
            let values = crate::volume::read_grid(&file, dims, min_m, max_m)?;
            Shape::Grid {
                file,
                dims,
                min_m,
                max_m,
                values,
            }
        }
        other => {
            return Err(format!(
                "shape = {other:?} is not one of cumulus, cirrus, rain_shaft, grid"
            ));
        }
    };
    let profiles = [
        ("r_eff_um", &v.r_eff_um),
        ("median_radius_um", &v.median_radius_um),
        ("radius_um", &v.radius_um),
    ];
    let mut size = None;
    for (key, p) in profiles {
        let Some(p) = p else { continue };
        if size.is_some() {
            return Err(format!(
                "{key} = {{ base, top }}: a volume has one size profile, of one of {}",
                crate::volume::PROFILE_KEYS.join(", ")
            ));
        }
        for (end, x) in [("base", p.base), ("top", p.top)] {
            if !(x.is_finite() && x > 0.0) {
                return Err(format!(
                    "{key} = {{ base = {}, top = {} }}: {end} must be finite and > 0 (µm)",
                    crate::checks::Shown(p.base),
                    crate::checks::Shown(p.top)
                ));
            }
        }
        size = Some(crate::volume::SizeProfile {
            key: key.to_string(),
            base: p.base,
            top: p.top,
            members: None,
        });
    }
    Ok(Volume {
        field: v.field.clone(),
        number_density_per_m3: density,
        shape,
        seed: v.seed.unwrap_or(1),
        size,
    })
}
