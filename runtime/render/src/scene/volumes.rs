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
    pub(super) grid: Option<String>,
    pub(super) scale_m: Option<f64>,
    pub(super) offset_m: Option<[f64; 3]>,
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
    let vdb_keys = [
        ("grid", v.grid.is_some()),
        ("scale_m", v.scale_m.is_some()),
        ("offset_m", v.offset_m.is_some()),
    ];
    if v.shape != "vdb"
        && let Some((key, _)) = vdb_keys.iter().find(|(_, set)| *set)
    {
        return Err(format!(
            "{key} is a key of shape \"vdb\" only (this volume's shape is {:?})",
            v.shape
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
        "grid" => grid(v, base)?,
        "vdb" => vdb(v, base)?,
        other => {
            return Err(format!(
                "shape = {other:?} is not one of cumulus, cirrus, rain_shaft, grid, vdb"
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

/// A `shape = "vdb"` volume: its file read now (crate::volume::read_vdb), so a bad file is
/// refused before anything is baked. Its box is the file's, not given by hand.
fn vdb(v: &VolumeKeys, base: &Path) -> Result<Shape, String> {
    let file = v
        .file
        .as_ref()
        .ok_or("shape \"vdb\" needs file (an OpenVDB .vdb file)")?;
    for (key, set) in [
        ("dims", v.dims.is_some()),
        ("min_m", v.min_m.is_some()),
        ("max_m", v.max_m.is_some()),
    ] {
        if set {
            return Err(format!(
                "{key} is not a key of shape \"vdb\": its box is the file's own (the active \
                 voxels' box through the file's transform); place it with scale_m and offset_m"
            ));
        }
    }
    let scale = v.scale_m.unwrap_or(1.0);
    if !(scale.is_finite() && scale > 0.0) {
        return Err(format!(
            "scale_m = {} must be finite and > 0 (metres per unit of the file's world space)",
            crate::checks::Shown(scale)
        ));
    }
    let offset = v.offset_m.unwrap_or([0.0; 3]);
    if offset.iter().any(|x| !x.is_finite()) {
        return Err(format!("offset_m = {offset:?} must be finite (m)"));
    }
    let grid = v.grid.clone().unwrap_or_else(|| "density".into());
    let file = base.join(file);
    let (summary, values) =
        crate::volume::read_vdb(&file, &grid, scale, DVec3::from_array(offset))?;
    Ok(Shape::Vdb {
        file,
        grid,
        summary,
        values,
    })
}

/// A `shape = "grid"` volume: its raw f32 file read now (crate::volume::read_grid).
fn grid(v: &VolumeKeys, base: &Path) -> Result<Shape, String> {
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
    Ok(Shape::Grid {
        file,
        dims,
        min_m,
        max_m,
        values,
    })
}
