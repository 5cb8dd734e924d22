//! The render part of a scene file: the same TOML as the bake's `[scene]`/`[[field]]`, plus
//!
//! ```toml
//! [render]
//! width = 512               # pixels
//! height = 512
//! slices = 256              # half-angle slices through the volumes' box
//! light_resolution = 512    # light-buffer texels per side
//! grid_resolution = 128     # voxels along the box's longest side
//! xi = 0.0                  # Riley's ξ (1/sr), back-scattered light in the eye pass
//! light_update = "continuum"   # riley: "continuum" (default) or "riley2004" (Eq. 25 as printed)
//! exposure = 0.0            # PNG exposure; 0 or absent: automatic
//! spp = 256                 # --model truth: samples (paths) per pixel, [1, 2²⁰]
//! svs_a = 1.5               # --model miyazaki: slice normal splits view:sun angles 1 : a, (0, 2]
//! k_multi = 0.0             # --model miyazaki: constant multiple scattering of clouds (1/sr), ≥ 0
//! svs_phase = "tables"      # --model miyazaki: "tables" (Ams_1) or "cornette_shanks" (Eq. 3)
//! seed = 1                  # --model truth: seed of the random streams
//! max_threshold = 1.0       # --model max: voxel optical depth where diffusion takes over, > 0
//! diffusion_tolerance = 1e-6       # --model max: relative residual of the solve, (0, 0.1]
//! max_diffusion_iterations = 500   # --model max: CG iteration cap, [1, 100000]
//! clear_air_iterations = 1  # --model max: §3's propagation across clear air, [0, 4]
//! biri_kernel = "exact"     # --model biri: "exact" (the kernel's primitive) or "polynomial" (Eq. 2)
//!
//! [ground]
//! albedo = 0.1              # Lambertian ground at y = 0, [0, 1] (default 0.1); 0: black
//!
//! [[light]]                 # point or spot light (--model truth, biri)
//! position_m = [0, 50, 0]   # y > 0, outside every occluder
//! intensity = [1e4, 1e4, 1e4]   # per channel, ≥ 0: irradiance I/r² in the image's unit at r metres
//! spot_direction = [0, -1, 0]   # optional: a spot's axis
//! spot_half_angle_deg = 30      # with spot_direction, (0, 180)
//!
//! [[medium]]                # --model biri: a homogeneous medium of a baked field
//! field = "fog"             # a [[field]] of the scene
//! number_density_per_m3 = 1e8   # > 0; β_ext = N σ_ext
//! min_m = [-10, 0, -10]     # optional box (both corners); absent: the whole scene
//! max_m = [10, 8, 10]
//! ambient = [0, 0, 0]       # optional ambient fog radiance (image's unit), ≥ 0 (Biri §3)
//!
//! [[occluder]]              # --model biri: a Lambertian shadow caster
//! shape = "box"             # box | sphere | mesh
//! min_m = [0, 0, 0]         # box
//! max_m = [1, 4, 1]
//! center_m = [0, 2, 0]      # sphere
//! radius_m = 1
//! file = "statue.obj"       # mesh: Wavefront OBJ (v, f), relative to the scene
//! offset_m = [0, 0, 0]      # mesh: added to its vertices after scale
//! scale = 1.0               # mesh: multiplies its vertices, > 0
//! albedo = 0.5              # [0, 1]
//!
//! [camera]
//! position_m = [0, 2, 0]    # metres, y up, sea level y = 0
//! look_at_m = [0, 600, 5000]
//! fov_deg = 60              # vertical
//!
//! [sun]
//! elevation_deg = 20        # (0, 90]
//! azimuth_deg = 180         # from +z towards +x
//! irradiance = [1, 1, 1]    # outside the atmosphere, per channel (the image's unit)
//!
//! [sky]
//! enabled = true            # analytic sky and aerial perspective (Riley Eqs. 11–15)
//! beta_sea_level_per_m = [5.8e-6, 1.35e-5, 3.31e-5]
//! scale_height_m = 8000
//!
//! [haze]                    # --model miyazaki, truth: an aerosol layer over the whole scene
//! field = "haze"            # a [[field]] of kind haze
//! number_density_per_m3 = 2e8   # at sea level (y = 0), > 0
//! scale_height_m = 1200     # N(y) = N_0 e^{−y/H}, > 0
//!
//! [[volume]]
//! field = "rain"            # a [[field]] of the scene
//! shape = "rain_shaft"      # cumulus | cirrus | rain_shaft | grid
//! number_density_per_m3 = 1000   # peak; β_ext = density · σ_ext (Riley Eq. 2)
//! center_m = [0, 0, 6000]
//! radius_m = 2500           # cumulus, rain_shaft
//! height_m = 1500           # cumulus
//! bottom_m = 0              # rain_shaft
//! top_m = 2500              # rain_shaft
//! size_m = 8000             # cirrus: side of the square sheet
//! thickness_m = 800         # cirrus
//! file = "density.f32"      # grid: raw little-endian f32, x fastest, relative to the scene
//! dims = [64, 32, 64]       # grid
//! min_m = [0, 0, 0]         # grid box
//! max_m = [1000, 500, 1000]
//! seed = 1
//! ```

use std::path::Path;

use serde::Deserialize;

use glam::DVec3;

use crate::volume::{Shape, Volume, joint_bounds, rasterize};

use crate::volume::VolumeError;
use crate::{Atmosphere, Camera, Frame, FrameError, Sun};
use runtime::Tables;

#[derive(Debug, Default, Deserialize)]
struct File {
    #[serde(default)]
    render: Option<RenderKeys>,
    #[serde(default)]
    camera: Option<CameraKeys>,
    #[serde(default)]
    sun: Option<SunKeys>,
    #[serde(default)]
    sky: Option<SkyKeys>,
    #[serde(default, rename = "volume")]
    volumes: Vec<VolumeKeys>,
    #[serde(default)]
    ground: Option<GroundKeys>,
    #[serde(default, rename = "light")]
    lights: Vec<LightKeys>,
    #[serde(default)]
    haze: Option<HazeKeys>,
    #[serde(default, rename = "medium")]
    media: Vec<MediumKeys>,
    #[serde(default, rename = "occluder")]
    occluders: Vec<OccluderKeys>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct MediumKeys {
    field: String,
    number_density_per_m3: f64,
    min_m: Option<[f64; 3]>,
    max_m: Option<[f64; 3]>,
    ambient: Option<[f64; 3]>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct OccluderKeys {
    shape: String,
    min_m: Option<[f64; 3]>,
    max_m: Option<[f64; 3]>,
    center_m: Option<[f64; 3]>,
    radius_m: Option<f64>,
    file: Option<String>,
    offset_m: Option<[f64; 3]>,
    scale: Option<f64>,
    albedo: Option<f64>,
}

/// The ground's albedo when a scene has no `[ground] albedo` (issue 15: a grey ground, not a
/// black one, for every model).
pub const DEFAULT_GROUND_ALBEDO: f64 = 0.1;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct HazeKeys {
    field: String,
    number_density_per_m3: f64,
    scale_height_m: f64,
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
struct GroundKeys {
    albedo: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct LightKeys {
    position_m: [f64; 3],
    intensity: [f64; 3],
    spot_direction: Option<[f64; 3]>,
    spot_half_angle_deg: Option<f64>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RenderKeys {
    width: Option<usize>,
    height: Option<usize>,
    slices: Option<usize>,
    light_resolution: Option<usize>,
    grid_resolution: Option<usize>,
    xi: Option<f64>,
    light_update: Option<String>,
    exposure: Option<f64>,
    spp: Option<usize>,
    seed: Option<u64>,
    svs_a: Option<f64>,
    k_multi: Option<f64>,
    svs_phase: Option<String>,
    max_threshold: Option<f64>,
    diffusion_tolerance: Option<f64>,
    max_diffusion_iterations: Option<usize>,
    clear_air_iterations: Option<usize>,
    biri_kernel: Option<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraKeys {
    position_m: [f64; 3],
    look_at_m: [f64; 3],
    fov_deg: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SunKeys {
    elevation_deg: f64,
    azimuth_deg: f64,
    irradiance: Option<[f64; 3]>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct SkyKeys {
    enabled: Option<bool>,
    beta_sea_level_per_m: Option<[f64; 3]>,
    scale_height_m: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct VolumeKeys {
    field: String,
    shape: String,
    number_density_per_m3: f64,
    center_m: Option<[f64; 3]>,
    radius_m: Option<f64>,
    height_m: Option<f64>,
    bottom_m: Option<f64>,
    top_m: Option<f64>,
    size_m: Option<f64>,
    thickness_m: Option<f64>,
    file: Option<String>,
    dims: Option<[usize; 3]>,
    min_m: Option<[f64; 3]>,
    max_m: Option<[f64; 3]>,
    seed: Option<u64>,
}

/// What a render needs from a scene file.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderScene {
    /// Image width, 1…8192 pixels (default 512).
    pub width: usize,
    /// Image height, 1…8192 pixels (default 512).
    pub height: usize,
    /// Half-angle slices through the volumes' box, [1, 4096] (default 256).
    pub slices: usize,
    /// Light-buffer texels per side, [2, 4096] (default 512).
    pub light_resolution: usize,
    /// Voxels along the box's longest side, [2, 512] (default 128).
    pub grid_resolution: usize,
    /// Riley's ξ (1/sr), back-scattered light in the eye pass; ≥ 0 (default 0).
    pub xi: f64,
    /// `[render] light_update` (default continuum).
    pub light_update: crate::LightUpdate,
    /// None: automatic.
    pub exposure: Option<f64>,
    /// From `[camera]`; fov (0, 170) degrees (default 60).
    pub camera: Camera,
    /// From `[sun]`; elevation (0, 90] degrees, irradiance ≥ 0 (default [1, 1, 1]).
    pub sun: Sun,
    /// From `[sky]`; `enabled = false` sets β_sl to zero (no sky, no aerial perspective).
    pub atmosphere: Atmosphere,
    /// The `[[volume]]` tables, at least one.
    pub volumes: Vec<Volume>,
    /// `[ground] albedo`: a Lambertian ground at y = 0, [0, 1] (default
    /// [`DEFAULT_GROUND_ALBEDO`]; 0 is black).
    pub ground_albedo: f64,
    /// The `[[light]]` tables.
    pub lights: Vec<crate::objects::Light>,
    /// `[render] spp` for the path tracer (default 256).
    pub spp: usize,
    /// `[render] seed` for the path tracer (default 1).
    pub seed: u64,
    /// `[render] svs_a`, `k_multi` and `svs_phase` for `--model miyazaki`.
    pub svs: crate::miyazaki::SvsSettings,
    /// `[render] max_threshold`, `diffusion_tolerance`, `max_diffusion_iterations` for
    /// `--model max`.
    pub max: crate::max::MaxSettings,
    /// `[haze]`, if any.
    pub haze: Option<HazeKeysChecked>,
    /// `[[medium]]`, `[[occluder]]` and `[render] biri_kernel` for `--model biri`.
    pub biri: crate::biri::BiriSettings,
}

/// A render scene that cannot be used, naming the file, the key or volume, and the allowed range.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The scene file could not be read.
    #[error("reading {}: {source}", path.display())]
    Read {
        /// The scene file.
        path: std::path::PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// A table or key is missing, malformed or out of range.
    #[error("{origin}: {message}")]
    Invalid {
        /// The scene file (or "default render scene").
        origin: String,
        /// What is wrong, naming the key, its value and the allowed range.
        message: String,
    },
    /// The frame's parameters (size, slices, camera, sun) are out of range.
    #[error(transparent)]
    Frame(#[from] FrameError),
    /// A volume cannot be rasterized (grid file size, values).
    #[error(transparent)]
    Volume(#[from] VolumeError),
    /// A volume uses a field the loaded tables do not hold.
    #[error("a volume uses field {name:?}, which the tables do not hold")]
    MissingField {
        /// The field's name.
        name: String,
    },
}

fn positive(what: &str, v: f64) -> Result<f64, String> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(format!("{what} = {v} must be finite and > 0"))
    }
}

impl RenderScene {
    /// Parses the render tables of a scene; `origin` names it in errors, `base` resolves grid
    /// files. A scene without `[camera]`, `[sun]` or `[[volume]]` cannot be rendered.
    pub fn parse(text: &str, origin: &str, base: &Path) -> Result<Self, SceneError> {
        let err = |message: String| SceneError::Invalid {
            origin: origin.to_string(),
            message,
        };
        let file: File = toml::from_str(text).map_err(|e| err(e.message().to_string()))?;
        let render = file.render.unwrap_or_default();
        let camera = file
            .camera
            .ok_or_else(|| err("no [camera] table (position_m, look_at_m, fov_deg)".into()))?;
        // A scene of homogeneous media lit by lamps (--model biri) may have no sun: then it
        // is dark, straight overhead.
        let sun = match file.sun {
            Some(s) => s,
            None if !file.media.is_empty() => SunKeys {
                elevation_deg: 90.0,
                azimuth_deg: 0.0,
                irradiance: Some([0.0; 3]),
            },
            None => return Err(err("no [sun] table (elevation_deg, azimuth_deg)".into())),
        };
        let sky = file.sky.unwrap_or_default();
        let mut atmosphere = Atmosphere::default();
        if let Some(b) = sky.beta_sea_level_per_m {
            if b.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
                return Err(err(format!(
                    "[sky] beta_sea_level_per_m = {b:?} must be ≥ 0 (1/m)"
                )));
            }
            atmosphere.beta_sea_level_per_m = b;
        }
        if let Some(h) = sky.scale_height_m {
            atmosphere.scale_height_m = positive("[sky] scale_height_m", h).map_err(err)?;
        }
        if sky.enabled == Some(false) {
            atmosphere.beta_sea_level_per_m = [0.0; 3];
        }
        let irradiance = sun.irradiance.unwrap_or([1.0; 3]);
        if irradiance.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
            return Err(err(format!(
                "[sun] irradiance = {irradiance:?} must be ≥ 0"
            )));
        }
        let xi = render.xi.unwrap_or(0.0);
        if !(xi.is_finite() && xi >= 0.0) {
            return Err(err(format!("[render] xi = {xi} must be ≥ 0 (1/sr)")));
        }
        let light_update = match render.light_update.as_deref() {
            None => crate::LightUpdate::default(),
            Some(name) => crate::LightUpdate::parse(name).ok_or_else(|| {
                err(format!(
                    "[render] light_update = {name:?} is not one of \"continuum\", \"riley2004\""
                ))
            })?,
        };
        let exposure = match render.exposure {
            None => None,
            Some(0.0) => None,
            Some(e) => Some(positive("[render] exposure", e).map_err(err)?),
        };
        let grid_resolution = render.grid_resolution.unwrap_or(128);
        if !(2..=512).contains(&grid_resolution) {
            return Err(err(format!(
                "[render] grid_resolution = {grid_resolution} is outside the allowed range [2, 512]"
            )));
        }
        let ground_albedo = file
            .ground
            .and_then(|g| g.albedo)
            .unwrap_or(DEFAULT_GROUND_ALBEDO);
        if !(0.0..=1.0).contains(&ground_albedo) {
            return Err(err(format!(
                "[ground] albedo = {ground_albedo} is outside the allowed range [0, 1]"
            )));
        }
        let lights = file
            .lights
            .iter()
            .enumerate()
            .map(|(i, l)| light(l).map_err(|m| err(format!("[[light]] {}: {m}", i + 1))))
            .collect::<Result<Vec<_>, _>>()?;
        let spp = render.spp.unwrap_or(256);
        let (lo, hi) = crate::truth::SPP_RANGE;
        if !(lo..=hi).contains(&spp) {
            return Err(err(format!(
                "[render] spp = {spp} is outside the allowed range [{lo}, {hi}] samples per pixel"
            )));
        }
        let defaults = crate::miyazaki::SvsSettings::default();
        let svs = crate::miyazaki::SvsSettings {
            a: render.svs_a.unwrap_or(defaults.a),
            k_multi: render.k_multi.unwrap_or(defaults.k_multi),
            phase: match render.svs_phase.as_deref() {
                None => defaults.phase,
                Some(name) => crate::miyazaki::SvsPhase::parse(name).ok_or_else(|| {
                    err(format!(
                        "[render] svs_phase = {name:?} is not one of \"tables\", \
                         \"cornette_shanks\""
                    ))
                })?,
            },
        };
        crate::miyazaki::check(&svs).map_err(|e| err(e.0))?;
        let max_defaults = crate::max::MaxSettings::default();
        let max = crate::max::MaxSettings {
            threshold: render.max_threshold.unwrap_or(max_defaults.threshold),
            tolerance: render.diffusion_tolerance.unwrap_or(max_defaults.tolerance),
            max_iterations: render
                .max_diffusion_iterations
                .unwrap_or(max_defaults.max_iterations),
            clear_air_iterations: render
                .clear_air_iterations
                .unwrap_or(max_defaults.clear_air_iterations),
        };
        max.check().map_err(|e| err(e.0))?;
        let haze = match file.haze {
            None => None,
            Some(h) => {
                if !(h.number_density_per_m3.is_finite() && h.number_density_per_m3 > 0.0) {
                    return Err(err(format!(
                        "[haze] number_density_per_m3 = {} must be finite and > 0 (particles \
                         per m³ at y = 0)",
                        h.number_density_per_m3
                    )));
                }
                if !(h.scale_height_m.is_finite() && h.scale_height_m > 0.0) {
                    return Err(err(format!(
                        "[haze] scale_height_m = {} must be finite and > 0 (m)",
                        h.scale_height_m
                    )));
                }
                Some(HazeKeysChecked {
                    field: h.field,
                    number_density_per_m3: h.number_density_per_m3,
                    scale_height_m: h.scale_height_m,
                })
            }
        };
        if file.volumes.is_empty() && file.media.is_empty() {
            return Err(err(
                "no [[volume]] (or [[medium]]) table: nothing to render".into(),
            ));
        }
        let biri = crate::biri::BiriSettings {
            kernel: match render.biri_kernel.as_deref() {
                None => crate::biri::Kernel::default(),
                Some(name) => crate::biri::Kernel::parse(name).ok_or_else(|| {
                    err(format!(
                        "[render] biri_kernel = {name:?} is not one of \"exact\", \"polynomial\""
                    ))
                })?,
            },
            media: file
                .media
                .iter()
                .enumerate()
                .map(|(i, m)| medium(m).map_err(|e| err(format!("[[medium]] {}: {e}", i + 1))))
                .collect::<Result<_, _>>()?,
            occluders: file
                .occluders
                .iter()
                .enumerate()
                .map(|(i, o)| {
                    occluder(o, base).map_err(|e| err(format!("[[occluder]] {}: {e}", i + 1)))
                })
                .collect::<Result<_, _>>()?,
        };
        let volumes = file
            .volumes
            .into_iter()
            .enumerate()
            .map(|(i, v)| volume(v, base).map_err(|m| err(format!("[[volume]] {}: {m}", i + 1))))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self {
            width: render.width.unwrap_or(512),
            height: render.height.unwrap_or(512),
            slices: render.slices.unwrap_or(256),
            light_resolution: render.light_resolution.unwrap_or(512),
            grid_resolution,
            xi,
            light_update,
            exposure,
            camera: Camera {
                position_m: DVec3::from_array(camera.position_m),
                look_at_m: DVec3::from_array(camera.look_at_m),
                fov_deg: camera.fov_deg.unwrap_or(60.0),
            },
            sun: Sun {
                elevation_deg: sun.elevation_deg,
                azimuth_deg: sun.azimuth_deg,
                irradiance,
            },
            atmosphere,
            volumes,
            ground_albedo,
            lights,
            spp,
            seed: render.seed.unwrap_or(1),
            svs,
            max,
            haze,
            biri,
        })
    }

    /// Refuses what a model cannot draw: Riley's model has sunlight and Rayleigh air only.
    pub fn check_model(&self, model: &str) -> Result<(), FrameError> {
        if model == "biri" {
            return self.check_biri();
        }
        if model == "truth" {
            return self
                .biri
                .check_lights(&self.lights)
                .map_err(|e| FrameError(e.0));
        }
        if !self.biri.media.is_empty() || !self.biri.occluders.is_empty() {
            return Err(FrameError(format!(
                "the scene has {} [[medium]] and {} [[occluder]] table(s), which only --model \
                 biri and --model truth draw",
                self.biri.media.len(),
                self.biri.occluders.len()
            )));
        }
        if model == "miyazaki" && self.lights.is_empty() {
            return Ok(()); // sunlight over a Lambertian ground, through haze
        }
        if let Some(h) = &self.haze {
            return Err(FrameError(format!(
                "the scene has a [haze] layer (field {:?}); --model {model} draws Rayleigh air \
                 only (render it with --model miyazaki or truth)",
                h.field
            )));
        }
        if !self.lights.is_empty() {
            return Err(FrameError(format!(
                "the scene has {} [[light]] table(s); --model {model} models sunlight only \
                 (render it with --model truth)",
                self.lights.len()
            )));
        }
        Ok(())
    }

    /// What `--model biri` refuses: density volumes, haze and sunlight (it draws point and
    /// spot lights in homogeneous media), and the checks of its own settings.
    fn check_biri(&self) -> Result<(), FrameError> {
        if !self.volumes.is_empty() {
            return Err(FrameError(format!(
                "the scene has {} [[volume]] table(s); --model biri draws homogeneous \
                 [[medium]] tables only (render volumes with riley, miyazaki, max or truth)",
                self.volumes.len()
            )));
        }
        if let Some(h) = &self.haze {
            return Err(FrameError(format!(
                "the scene has a [haze] layer (field {:?}); --model biri draws homogeneous \
                 [[medium]] tables only",
                h.field
            )));
        }
        if self.sun.irradiance.iter().any(|&v| v > 0.0) {
            return Err(FrameError(format!(
                "[sun] irradiance = {:?}: --model biri draws point and spot lights only; set \
                 it to [0, 0, 0] or leave out [sun]",
                self.sun.irradiance
            )));
        }
        self.biri.check(&self.lights).map_err(|e| FrameError(e.0))
    }

    /// The path tracer's settings from the scene (spp, seed, ground, lights).
    pub fn truth_settings(&self) -> crate::truth::TruthSettings {
        crate::truth::TruthSettings {
            spp: self.spp,
            target_noise: 0.0,
            seed: self.seed,
            lights: self.lights.clone(),
            wavelengths_per_path: 0,
            media: self.biri.media.clone(),
            occluders: self.biri.occluders.clone(),
            max_scatterings: 0,
        }
    }

    /// The frame's parameters checked (sizes, camera, sun) before anything is baked: a frame
    /// over the volumes' bounds without rasterizing them.
    pub fn check(&self) -> Result<(), FrameError> {
        self.check_for("riley")
    }

    /// [`RenderScene::check`] for `model`: `riley` checks its slicing setup and refuses
    /// lights and a bright ground ([`RenderScene::check_model`]); `truth` checks the path
    /// tracer's ranges (`truth::check`), and allows a camera inside the volumes.
    pub fn check_for(&self, model: &str) -> Result<(), FrameError> {
        self.check_model(model)?;
        if model == "biri" {
            let mut frame = self.frame_with(empty_grid());
            frame.sun.elevation_deg = 90.0; // biri has no sun
            return frame.check_view();
        }
        let grid = if self.volumes.is_empty() {
            empty_grid()
        } else {
            let (lo, hi) = joint_bounds(&self.volumes);
            super::DensityGrid {
                min_m: lo,
                max_m: hi,
                dims: [1, 1, 1],
                data: vec![[0.0; super::MAX_FIELDS]],
            }
        };
        let frame = self.frame_with(grid);
        match model {
            "truth" => crate::truth::check(&frame, &self.truth_settings()),
            "miyazaki" => crate::miyazaki::setup(&frame, &self.svs).map(|_| ()),
            "max" => frame.check_view().and_then(|()| self.max.check()),
            _ => frame.setup().map(|_| ()),
        }
    }

    fn frame_with(&self, grid: super::DensityGrid) -> Frame {
        Frame {
            camera: self.camera,
            sun: self.sun,
            atmosphere: self.atmosphere,
            xi: self.xi,
            light_update: self.light_update,
            width: self.width,
            height: self.height,
            slices: self.slices,
            light_resolution: self.light_resolution,
            grid,
            haze: None,
            ground_albedo: self.ground_albedo,
        }
    }

    /// Reads a scene file.
    pub fn from_file(path: &Path) -> Result<Self, SceneError> {
        let text = std::fs::read_to_string(path).map_err(|source| SceneError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        let base = path.parent().unwrap_or(Path::new("."));
        Self::parse(&text, &path.display().to_string(), base)
    }

    /// The fields the volumes use, in order of first use, then the haze layer's.
    pub fn fields(&self) -> Vec<String> {
        let mut names: Vec<String> = Vec::new();
        for v in &self.volumes {
            if !names.contains(&v.field) {
                names.push(v.field.clone());
            }
        }
        if let Some(h) = &self.haze
            && !names.contains(&h.field)
        {
            names.push(h.field.clone());
        }
        for m in &self.biri.media {
            if !names.contains(&m.field) {
                names.push(m.field.clone());
            }
        }
        names
    }

    /// The frame: volumes rasterized with channel i = `tables.fields[i]`.
    pub fn frame(&self, tables: &Tables) -> Result<Frame, SceneError> {
        for name in self.fields() {
            if tables.field(&name).is_none() {
                return Err(SceneError::MissingField { name });
            }
        }
        let index = |name: &str| {
            tables
                .fields
                .iter()
                .position(|f| f.name == name)
                .expect("checked above")
        };
        let grid = if self.volumes.is_empty() {
            empty_grid() // a scene of [[medium]] tables only
        } else {
            rasterize(&self.volumes, self.grid_resolution, index)?
        };
        let mut frame = self.frame_with(grid);
        frame.haze = self.haze.as_ref().map(|h| crate::Haze {
            field: index(&h.field),
            number_density_per_m3: h.number_density_per_m3,
            scale_height_m: h.scale_height_m,
        });
        Ok(frame)
    }
}

/// A grid of no particles, one voxel of a millimetre at the origin: what a scene without
/// [[volume]] tables (media only) has.
fn empty_grid() -> super::DensityGrid {
    super::DensityGrid {
        min_m: DVec3::ZERO,
        max_m: DVec3::splat(1e-3),
        dims: [1, 1, 1],
        data: vec![[0.0; super::MAX_FIELDS]],
    }
}

fn light(l: &LightKeys) -> Result<crate::objects::Light, String> {
    let p = DVec3::from_array(l.position_m);
    if !p.is_finite() || p.y <= 0.0 {
        return Err(format!(
            "position_m = {:?} must be finite and above the ground (y > 0): a light at or \
             below y = 0 is inside the ground, an occluder",
            l.position_m
        ));
    }
    if l.intensity.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
        return Err(format!("intensity = {:?} must be ≥ 0", l.intensity));
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
    Ok(crate::objects::Light {
        position_m: p,
        intensity: l.intensity,
        spot,
    })
}

fn medium(m: &MediumKeys) -> Result<crate::objects::Medium, String> {
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

fn occluder(o: &OccluderKeys, base: &Path) -> Result<crate::objects::Occluder, String> {
    use crate::geometry::{Mesh, Sphere, read_obj};
    let albedo = o.albedo.unwrap_or(0.5);
    if !(0.0..=1.0).contains(&albedo) {
        return Err(format!(
            "albedo = {albedo} is outside the allowed range [0, 1]"
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

fn volume(v: VolumeKeys, base: &Path) -> Result<Volume, String> {
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
            let file = v.file.ok_or("shape \"grid\" needs file")?;
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
    Ok(Volume {
        field: v.field,
        number_density_per_m3: density,
        shape,
        seed: v.seed.unwrap_or(1),
    })
}
