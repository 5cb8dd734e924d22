//! The scene file's view tables and their checks: `[render]`, `[camera]`, `[sun]`, `[sky]`,
//! `[haze]` and `[ground]`.

use super::*;

/// The largest `[render] grid_resolution` (voxels along the volumes' longest side).
pub const MAX_GRID_RESOLUTION: usize = 512;

/// The ground's albedo when a scene has no `[ground] albedo`: a grey ground, the same for
/// every model.
pub const DEFAULT_GROUND_ALBEDO: f64 = 0.1;

/// The allowed range of a scale height (the sky's and the haze's), metres.
pub const SCALE_HEIGHT_RANGE_M: (f64, f64) = (1.0, 1e6);

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct HazeKeys {
    pub(super) field: String,
    pub(super) number_density_per_m3: f64,
    pub(super) scale_height_m: f64,
}

/// `[haze]`: an aerosol layer of a `[[field]]` (of kind haze) with an exponential height
/// profile N(y) = N_0 e^{−y/H} over the whole scene.
#[derive(Debug, Clone, PartialEq)]
pub struct HazeKeysChecked {
    /// The field's name.
    pub field: String,
    /// N_0 at y = 0 (1/m³), > 0.
    pub number_density_per_m3: f64,
    /// H (m), > 0.
    pub scale_height_m: f64,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct GroundKeys {
    pub(super) albedo: Option<f64>,
}

/// `[render]`: the keys every model shares, and one table per model (`[render.<model>]`).
#[derive(Debug, Default, Deserialize)]
pub(super) struct RenderKeys {
    pub(super) width: Option<usize>,
    pub(super) height: Option<usize>,
    pub(super) grid_resolution: Option<usize>,
    pub(super) exposure: Option<f64>,
    #[serde(flatten)]
    pub(super) rest: BTreeMap<String, toml::Value>,
}

/// Keys `[render]` held before each model had its own table: (old key, model, key there).
pub(super) const MOVED_KEYS: &[(&str, &str, &str)] = &[
    ("slices", "riley, miyazaki", "slices"),
    ("light_resolution", "riley, miyazaki", "light_resolution"),
    ("xi", "riley", "xi"),
    ("light_update", "riley", "light_update"),
    ("spp", "truth", "spp"),
    ("seed", "truth", "seed"),
    ("svs_a", "miyazaki", "a"),
    ("k_multi", "miyazaki", "k_multi"),
    ("svs_phase", "miyazaki", "phase"),
    ("max_threshold", "max", "threshold"),
    ("diffusion_tolerance", "max", "diffusion_tolerance"),
    (
        "max_diffusion_iterations",
        "max",
        "max_diffusion_iterations",
    ),
    ("clear_air_iterations", "max", "clear_air_iterations"),
    ("biri_kernel", "biri", "kernel"),
];

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct CameraKeys {
    pub(super) position_m: [f64; 3],
    pub(super) look_at_m: [f64; 3],
    pub(super) fov_deg: Option<f64>,
    pub(super) projection: Option<String>,
    pub(super) width_m: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct SunKeys {
    pub(super) elevation_deg: f64,
    pub(super) azimuth_deg: f64,
    pub(super) irradiance: Option<[f64; 3]>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct SkyKeys {
    pub(super) enabled: Option<bool>,
    pub(super) beta_sea_level_per_m: Option<[f64; 3]>,
    pub(super) scale_height_m: Option<f64>,
}

/// A scale height in [`SCALE_HEIGHT_RANGE_M`].
pub(super) fn scale_height(what: &str, h: f64) -> Result<f64, String> {
    let (lo, hi) = SCALE_HEIGHT_RANGE_M;
    if h.is_finite() && (lo..=hi).contains(&h) {
        Ok(h)
    } else {
        Err(format!(
            "{what} = {} is outside the allowed range [{lo}, {hi:e}] (m)",
            crate::checks::Shown(h)
        ))
    }
}

/// `[camera]`: finite positions, and the field of view of a perspective camera or the width
/// (m, (0, 1e7]) of an orthographic one.
pub(super) fn camera_keys(camera: CameraKeys) -> Result<Camera, String> {
    for (key, v) in [
        ("position_m", camera.position_m),
        ("look_at_m", camera.look_at_m),
    ] {
        if v.iter().any(|x| !x.is_finite()) {
            return Err(format!("[camera] {key} = {v:?} must be finite (m)"));
        }
    }
    let projection = match (camera.projection.as_deref(), camera.width_m) {
        (None | Some("perspective"), None) => Projection::Perspective,
        (None | Some("perspective"), Some(w)) => {
            return Err(format!(
                "[camera] width_m = {w} is a key of projection = \"orthographic\" (a \
                 perspective camera has fov_deg)"
            ));
        }
        (Some("orthographic"), None) => {
            return Err(
                "[camera] projection = \"orthographic\" needs width_m, the image's width in \
                 metres, (0, 1e7]"
                    .into(),
            );
        }
        (Some("orthographic"), Some(w)) => {
            if camera.fov_deg.is_some() {
                return Err("[camera] fov_deg is a key of perspective cameras; an \
                     orthographic camera has width_m"
                    .into());
            }
            if !(w.is_finite() && w > 0.0 && w <= 1e7) {
                return Err(format!(
                    "[camera] width_m = {} is outside the allowed range (0, 1e7] (m)",
                    crate::checks::Shown(w)
                ));
            }
            Projection::Orthographic { width_m: w }
        }
        (Some(other), _) => {
            return Err(format!(
                "[camera] projection = {other:?} is neither \"perspective\" nor \"orthographic\""
            ));
        }
    };
    Ok(Camera {
        position_m: DVec3::from_array(camera.position_m),
        look_at_m: DVec3::from_array(camera.look_at_m),
        fov_deg: camera.fov_deg.unwrap_or(60.0),
        projection,
    })
}

/// `[render]`'s shared keys and the model tables, checked.
pub(super) struct RenderChecked {
    pub(super) width: usize,
    pub(super) height: usize,
    pub(super) grid_resolution: usize,
    pub(super) exposure: Option<f64>,
    pub(super) models: BTreeMap<String, toml::Table>,
}

pub(super) fn render_keys(render: RenderKeys) -> Result<RenderChecked, String> {
    let mut models = BTreeMap::new();
    for (key, value) in render.rest {
        if let Some(&(_, model, new_key)) = MOVED_KEYS.iter().find(|m| m.0 == key) {
            return Err(format!(
                "[render] {key}: each model's settings live in its own table: write \
                 {new_key} = {value} under [render.{}] (models: {model})",
                model.split(", ").next().unwrap_or(model)
            ));
        }
        let table = match (MODEL_NAMES.contains(&key.as_str()), value) {
            (true, toml::Value::Table(t)) => t,
            (true, _) => return Err(format!("[render] {key} must be a table, [render.{key}]")),
            (false, _) => {
                return Err(format!(
                    "[render] {key} is not a key of [render] (width, height, grid_resolution, \
                     exposure) nor a model's table ({})",
                    MODEL_NAMES
                        .iter()
                        .map(|m| format!("[render.{m}]"))
                        .collect::<Vec<_>>()
                        .join(", ")
                ));
            }
        };
        ModelSettings::parse(&key, &table).map_err(|e| e.0)?;
        models.insert(key, table);
    }
    let grid_resolution = render.grid_resolution.unwrap_or(128);
    if !(2..=MAX_GRID_RESOLUTION).contains(&grid_resolution) {
        return Err(format!(
            "[render] grid_resolution = {grid_resolution} is outside the allowed range [2, \
             {MAX_GRID_RESOLUTION}]"
        ));
    }
    let exposure = match render.exposure {
        None | Some(0.0) => None,
        Some(e) => Some(positive("[render] exposure", e)?),
    };
    Ok(RenderChecked {
        width: render.width.unwrap_or(512),
        height: render.height.unwrap_or(512),
        grid_resolution,
        exposure,
        models,
    })
}

pub(super) fn sky_keys(sky: SkyKeys) -> Result<Atmosphere, String> {
    let mut atmosphere = Atmosphere::default();
    if let Some(b) = sky.beta_sea_level_per_m {
        if b.iter()
            .any(|v| !(v.is_finite() && (0.0..=1.0).contains(v)))
        {
            return Err(format!(
                "[sky] beta_sea_level_per_m = {b:?} is outside the allowed range [0, 1] per \
                 channel (1/m; clear air is ~10⁻⁵)"
            ));
        }
        atmosphere.beta_sea_level_per_m = b;
    }
    if let Some(h) = sky.scale_height_m {
        atmosphere.scale_height_m = scale_height("[sky] scale_height_m", h)?;
    }
    if sky.enabled == Some(false) {
        atmosphere.beta_sea_level_per_m = [0.0; 3];
    }
    Ok(atmosphere)
}

/// `[sun]`; a scene of homogeneous media lit by lamps (`--model biri`) may have none: then
/// it is dark, straight overhead.
pub(super) fn sun_keys(sun: Option<SunKeys>, lamps_only: bool) -> Result<Sun, String> {
    let sun = match sun {
        Some(s) => s,
        None if lamps_only => SunKeys {
            elevation_deg: 90.0,
            azimuth_deg: 0.0,
            irradiance: Some([0.0; 3]),
        },
        None => return Err("no [sun] table (elevation_deg, azimuth_deg)".into()),
    };
    for (key, v) in [
        ("elevation_deg", sun.elevation_deg),
        ("azimuth_deg", sun.azimuth_deg),
    ] {
        if !v.is_finite() {
            return Err(format!(
                "[sun] {key} = {v} must be a finite angle (degrees)"
            ));
        }
    }
    let irradiance = sun.irradiance.unwrap_or([1.0; 3]);
    if irradiance
        .iter()
        .any(|v| !(v.is_finite() && (0.0..=MAX_SOURCE).contains(v)))
    {
        return Err(format!(
            "[sun] irradiance = {irradiance:?} is outside the allowed range [0, {MAX_SOURCE:e}] \
             per channel"
        ));
    }
    Ok(Sun {
        elevation_deg: sun.elevation_deg,
        azimuth_deg: sun.azimuth_deg,
        irradiance,
    })
}

pub(super) fn haze_keys(h: HazeKeys) -> Result<HazeKeysChecked, String> {
    if !(h.number_density_per_m3.is_finite() && h.number_density_per_m3 > 0.0) {
        return Err(format!(
            "[haze] number_density_per_m3 = {} must be finite and > 0 (particles per m³ at y = 0)",
            h.number_density_per_m3
        ));
    }
    scale_height("[haze] scale_height_m", h.scale_height_m)?;
    Ok(HazeKeysChecked {
        field: h.field,
        number_density_per_m3: h.number_density_per_m3,
        scale_height_m: h.scale_height_m,
    })
}
