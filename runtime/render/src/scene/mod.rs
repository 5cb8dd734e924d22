//! The render part of a scene file: the same TOML as the bake's `[scene]`/`[[field]]`, plus
//!
//! ```toml
//! [render]                  # shared by every model
//! width = 512               # pixels
//! height = 512
//! grid_resolution = 128     # voxels along the volumes' box's longest side
//! exposure = 0.0            # PNG exposure; 0 or absent: automatic
//!
//! [render.riley]            # each model's settings in its own table (crate::registry); a key
//! slices = 256              # another model owns, or none does, is refused naming both
//! light_resolution = 512    # light-buffer texels per side
//! xi = 0.0                  # Riley's ξ (1/sr), back-scattered light in the eye pass
//! light_update = "continuum"   # "continuum" (default) or "riley2004" (Eq. 25 as printed)
//!
//! [render.miyazaki]
//! slices = 256
//! light_resolution = 512    # shadow-surface texels per side
//! a = 1.5                   # slice normal splits view:sun angles 1 : a, (0, 2]
//! k_multi = 0.0             # constant multiple scattering of clouds (1/sr), ≥ 0
//! phase = "tables"          # "tables" (Ams_1) or "cornette_shanks" (Eq. 3)
//!
//! [render.max]
//! threshold = 1.0           # voxel optical depth where diffusion takes over, > 0
//! diffusion_tolerance = 1e-6       # relative residual of the solve, (0, 0.1]
//! max_diffusion_iterations = 500   # CG iteration cap, [1, 100000]
//! clear_air_iterations = 1  # §3's propagation across clear air, [0, 4]
//! per_sun = "auto"          # the per-sun passes of a GPU render: "auto", "gpu" or "cpu"
//!
//! [render.coupled]
//! preset = "balanced"       # "realtime", "balanced" or "reference": the values of the next
//!                           # four keys and diffusion_tolerance (a key given here wins)
//! diffuse = "transport"     # discrete-ordinates transport, or "diffusion" (the P1 solve alone)
//! directions = 96           # the transport's directions, [16, 1024] (balanced's)
//! transport_tolerance = 0.01       # a round's relative change that ends it, [1e-6, 0.5]
//! max_transport_iterations = 40    # source iterations, [1, 1000]
//! transport_coarsening = 0  # grid voxels per transport voxel: 1, 2, 4; 0 automatic
//! source = "buffer"         # "buffer" (the beam's loss) or "first-scatter" (f = 0, as max)
//! split = "delta-eddington" # δ-M's f (f = g² with the diffusion), or "hemisphere" (Riley's F_n)
//! emergent = "p1"           # the diffusion's light with its flux, or "isotropic"
//! diffusion_tolerance = 1e-6       # relative residual of the solve, [1e-12, 0.1]
//! max_diffusion_iterations = 500   # CG iteration cap, [1, 100000]
//! per_sun = "auto"          # the per-sun passes of a GPU render: "auto", "gpu" or "cpu"
//! per_view = "auto"         # the gather of a GPU render: "auto", "gpu" or "cpu"
//!
//! [render.biri]
//! kernel = "exact"          # "exact" (the kernel's primitive) or "polynomial" (Eq. 2)
//!
//! [render.truth]
//! spp = 256                 # samples (paths) per pixel, [1, 2²⁰]
//! seed = 1                  # seed of the random streams
//! noise = 0.0               # stop at this median relative standard error; 0: run every sample
//! max_scatterings = 0       # 1: single scattering only; 0: unbounded
//! wavelengths_per_path = 0  # hero wavelengths per path, 1–4; 0: all of rgb3, 4 of a spectrum
//! max_seconds = 0           # stop after the pass that passes this many seconds; 0: no bound
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
//! [[medium]]                # --model biri, truth: a homogeneous medium of a baked field
//! field = "fog"             # a [[field]] of the scene
//! number_density_per_m3 = 1e8   # > 0; β_ext = N σ_ext
//! min_m = [-10, 0, -10]     # optional box (both corners); absent: the whole scene
//! max_m = [10, 8, 10]
//! ambient = [0, 0, 0]       # optional ambient fog radiance (image's unit), ≥ 0 (Biri §3)
//!
//! [[occluder]]              # --model biri, truth: a Lambertian shadow caster
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
//! # periodic = true on the scene's only [[volume]]: its box repeats in x and z without end
//! #   (the benchmarks' cyclic boundaries); truth and coupled
//! # projection = "orthographic" with width_m = 2000 instead of fov_deg: every pixel looks
//! #   along the view direction from its own point (the image is width_m wide, its height
//! #   follows the aspect); every model
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
//! shape = "rain_shaft"      # cumulus | cirrus | rain_shaft | grid | vdb
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
//! # vdb: file = "cloud.vdb"; grid = "density" (default); the file's own transform, then
//! # scale_m = 1 (multiplies it) and offset_m = [0, 0, 0] (added, m); y is up
//! seed = 1
//! ```

use std::collections::BTreeMap;
use std::path::Path;

use serde::Deserialize;

use glam::DVec3;

use crate::model::{Model, Need};

use crate::objects::{Light, Medium, Occluder};
use crate::registry::{MODEL_NAMES, ModelError, ModelSettings, model_keys};
use crate::volume::{Shape, Volume, VolumeError, grid_dims, joint_bounds, rasterize};
use crate::{
    camera::Camera, camera::Projection, camera::Sun, checks::FrameError, frame::Frame, frame::Haze,
    sky::Atmosphere,
};
use runtime::Tables;

mod objects;
mod view;
mod volumes;

use objects::*;
use view::*;
use volumes::*;

pub use objects::MAX_SOURCE;
pub use view::{DEFAULT_GROUND_ALBEDO, HazeKeysChecked, MAX_GRID_RESOLUTION, SCALE_HEIGHT_RANGE_M};

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

/// What a render needs from a scene file: the parts every model shares, and each model's own
/// settings table, checked.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderScene {
    /// Image width, 1…8192 pixels (default 512).
    pub width: usize,
    /// Image height, 1…8192 pixels (default 512).
    pub height: usize,
    /// Voxels along the box's longest side, [2, 512] (default 128).
    pub grid_resolution: usize,
    /// None: automatic.
    pub exposure: Option<f64>,
    /// From `[camera]`; fov (0, 170) degrees (default 60).
    pub camera: Camera,
    /// From `[sun]`; elevation (0, 90] degrees, irradiance ≥ 0 (default [1, 1, 1]).
    pub sun: Sun,
    /// From `[sky]`; `enabled = false` sets β_sl to zero (no sky, no aerial perspective).
    pub atmosphere: Atmosphere,
    /// The `[[volume]]` tables.
    pub volumes: Vec<Volume>,
    /// The one volume repeats without end in x and z (`periodic = true`): its box is the
    /// period ([`crate::volume::DensityGrid::periodic`]).
    pub periodic: bool,
    /// `[ground] albedo`: a Lambertian ground at y = 0, [0, 1] (default
    /// [`DEFAULT_GROUND_ALBEDO`]; 0 is black).
    pub ground_albedo: f64,
    /// The `[[light]]` tables.
    pub lights: Vec<Light>,
    /// The `[[medium]]` tables.
    pub media: Vec<Medium>,
    /// The `[[occluder]]` tables.
    pub occluders: Vec<Occluder>,
    /// `[haze]`, if any.
    pub haze: Option<HazeKeysChecked>,
    /// `[render.<model>]` per model that has one, each already checked against its model.
    pub models: BTreeMap<String, toml::Table>,
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

/// Each entry of an array of tables through `f`, its errors prefixed `[[name]] i`.
fn each<K, T>(
    items: &[K],
    name: &str,
    f: impl Fn(&K) -> Result<T, String>,
) -> Result<Vec<T>, String> {
    items
        .iter()
        .enumerate()
        .map(|(i, k)| f(k).map_err(|m| format!("[[{name}]] {}: {m}", i + 1)))
        .collect()
}

/// The line of the key a message names ("… elevation_deg = 120 is outside …": the word before
/// its first " = "), where exactly one line of `text` sets that key; `None` where the key is
/// set on several lines (the message's table would have to choose) or none. Errors found
/// after parsing (the frame's checks) are placed with it too.
pub fn key_line(text: &str, message: &str) -> Option<usize> {
    let before = &message[..message.find(" = ")?];
    let key = before.rsplit([' ', '.']).next().filter(|k| !k.is_empty())?;
    let mut lines = text.lines().enumerate().filter(|(_, l)| {
        l.trim_start()
            .strip_prefix(key)
            .is_some_and(|rest| rest.trim_start().starts_with('='))
    });
    let (i, _) = lines.next()?;
    lines.next().is_none().then_some(i + 1)
}

impl RenderScene {
    /// Parses the render tables of a scene; `origin` names it in errors, `base` resolves grid
    /// and mesh files. A scene without `[camera]`, `[sun]` or `[[volume]]` cannot be rendered.
    pub fn parse(text: &str, origin: &str, base: &Path) -> Result<Self, SceneError> {
        let err = |message: String| SceneError::Invalid {
            origin: origin.to_string(),
            message: match key_line(text, &message) {
                Some(line) => format!("line {line}: {message}"),
                None => message,
            },
        };
        let file: File = toml::from_str(text).map_err(|e| {
            let message = e.message().to_string();
            match e.span() {
                Some(span) => SceneError::Invalid {
                    origin: origin.to_string(),
                    message: format!(
                        "line {}: {message}",
                        text[..span.start.min(text.len())].matches('\n').count() + 1
                    ),
                },
                None => err(message),
            }
        })?;
        let render = render_keys(file.render.unwrap_or_default()).map_err(err)?;
        let camera = file
            .camera
            .ok_or_else(|| err("no [camera] table (position_m, look_at_m, fov_deg)".into()))
            .and_then(|c| camera_keys(c).map_err(err))?;
        let sun = sun_keys(file.sun, !file.media.is_empty()).map_err(err)?;
        let atmosphere = sky_keys(file.sky.unwrap_or_default()).map_err(err)?;
        let ground_albedo = file
            .ground
            .and_then(|g| g.albedo)
            .unwrap_or(DEFAULT_GROUND_ALBEDO);
        if !(0.0..=1.0).contains(&ground_albedo) {
            return Err(err(format!(
                "[ground] albedo = {} is outside the allowed range [0, 1]",
                crate::checks::Shown(ground_albedo)
            )));
        }
        let haze = file.haze.map(haze_keys).transpose().map_err(err)?;
        if file.volumes.is_empty() && file.media.is_empty() {
            return Err(err(
                "no [[volume]] (or [[medium]]) table: nothing to render".into(),
            ));
        }
        let lights = each(&file.lights, "light", light).map_err(err)?;
        let media = each(&file.media, "medium", medium).map_err(err)?;
        let occluders = each(&file.occluders, "occluder", |o| occluder(o, base)).map_err(err)?;
        let volumes = each(&file.volumes, "volume", |v| volume(v, base)).map_err(err)?;
        let periodic = file.volumes.iter().any(|v| v.periodic == Some(true));
        if periodic && file.volumes.len() > 1 {
            return Err(err(format!(
                "[[volume]] periodic = true: a periodic volume repeats its box in x and z and \
                 must be the scene's only [[volume]] (the scene has {})",
                file.volumes.len()
            )));
        }
        if !volumes.is_empty() {
            let (lo, hi) = joint_bounds(&volumes);
            if !(hi - lo).is_finite() {
                return Err(err(format!(
                    "the [[volume]]s span {:?} to {:?} m: their box must have a finite size",
                    lo.to_array(),
                    hi.to_array()
                )));
            }
        }
        Ok(Self {
            width: render.width,
            height: render.height,
            grid_resolution: render.grid_resolution,
            exposure: render.exposure,
            camera,
            sun,
            atmosphere,
            volumes,
            periodic,
            ground_albedo,
            lights,
            media,
            occluders,
            haze,
            models: render.models,
        })
    }

    /// Model `name` with the scene's `[render.<name>]` settings (defaults where it has none)
    /// and `overrides` on top (e.g. from the command line: key and value), checked.
    pub fn model(
        &self,
        name: &str,
        overrides: &[(String, toml::Value)],
    ) -> Result<ModelSettings, ModelError> {
        let mut table = self.models.get(name).cloned().unwrap_or_default();
        for (key, value) in overrides {
            table.insert(key.clone(), value.clone());
        }
        ModelSettings::parse(name, &table)
    }

    /// Model `M`'s settings from the scene's `[render.<name>]` (defaults where it has none).
    pub fn settings<M: Model>(&self) -> Result<M::Settings, ModelError> {
        let table = self.models.get(M::NAME).cloned().unwrap_or_default();
        crate::registry::parse_settings::<M>(&table)
    }

    /// Model `name` with the scene's settings, checked against the scene ([`Self::check`]).
    pub fn check_for(&self, name: &str) -> Result<ModelSettings, FrameError> {
        let model = self.model(name, &[]).map_err(|e| FrameError(e.0))?;
        self.check(&model)?;
        Ok(model)
    }

    /// The memory a frame of `model` takes, by part: the density grid, the grid files the
    /// scene read, and the model's own buffers ([`crate::model::Model::memory`]).
    pub fn memory(&self, model: &ModelSettings) -> Vec<Need> {
        let dims = if self.volumes.is_empty() {
            [1, 1, 1]
        } else {
            grid_dims(&self.volumes, self.grid_resolution)
        };
        let voxels = crate::model::voxels(dims);
        let files: u64 = self
            .volumes
            .iter()
            .map(|v| match &v.shape {
                Shape::Grid { values, .. } | Shape::Vdb { values, .. } => values.bytes(),
                _ => 0,
            })
            .sum();
        let mut needs = vec![Need {
            what: "the density grid",
            bytes: 16 * voxels,
            setting: "[render] grid_resolution".into(),
        }];
        if files > 0 {
            needs.push(Need {
                what: "the grid files",
                bytes: files,
                setting: "the [[volume]] grid files' dims (a vdb's active box)".into(),
            });
        }
        needs.extend(model.memory(self.width as u64 * self.height as u64, dims));
        needs
    }

    /// Refuses a frame of `model` whose memory ([`Self::memory`]) exceeds `limit` bytes,
    /// naming the total, its largest part and the setting that sets that part.
    pub fn check_memory(&self, model: &ModelSettings, limit: u64) -> Result<(), FrameError> {
        let needs = self.memory(model);
        let total = Need::total(&needs);
        if total <= limit {
            return Ok(());
        }
        let largest = needs
            .iter()
            .max_by_key(|n| n.bytes)
            .expect("the grid is always a part");
        let gib = |b: u64| b as f64 / f64::from(1u32 << 30);
        Err(FrameError(format!(
            "--model {} needs about {:.2} GiB for this frame ({}: {:.2} GiB), more than the {:.2} \
             GiB allowed (--max-memory, default: the memory available); lower {}",
            model.name(),
            gib(total),
            largest.what,
            gib(largest.bytes),
            gib(limit),
            largest.setting
        )))
    }

    /// Whether model `name` has setting `key`.
    pub fn model_has(name: &str, key: &str) -> bool {
        model_keys()
            .iter()
            .any(|(m, keys)| *m == name && keys.iter().any(|k| k == key))
    }

    /// What `model` needs of the scene and refuses in it, checked before anything is baked:
    /// on a frame over the volumes' bounds without particles.
    pub fn check(&self, model: &ModelSettings) -> Result<(), FrameError> {
        let grid = if self.volumes.is_empty() {
            crate::volume::DensityGrid::empty()
        } else {
            let (lo, hi) = joint_bounds(&self.volumes);
            crate::volume::DensityGrid {
                min_m: lo,
                max_m: hi,
                dims: [1, 1, 1],
                data: vec![[0.0; crate::volume::MAX_FIELDS]],
                periodic: self.periodic,
            }
        };
        let mut frame = self.frame_with(grid);
        let fields = self.fields();
        frame.haze = self.haze(|name| fields.iter().position(|f| f == name).unwrap_or(0));
        model.check_frame(&frame)
    }

    fn frame_with(&self, grid: crate::volume::DensityGrid) -> Frame {
        Frame {
            camera: self.camera,
            sun: self.sun,
            atmosphere: self.atmosphere,
            width: self.width,
            height: self.height,
            grid,
            haze: None,
            ground_albedo: self.ground_albedo,
            lights: self.lights.clone(),
            media: self.media.clone(),
            occluders: self.occluders.clone(),
        }
    }

    fn haze(&self, index: impl Fn(&str) -> usize) -> Option<Haze> {
        self.haze.as_ref().map(|h| Haze {
            field: index(&h.field),
            name: h.field.clone(),
            number_density_per_m3: h.number_density_per_m3,
            scale_height_m: h.scale_height_m,
        })
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

    /// The fields the volumes use, in order of first use, then the haze layer's, then the
    /// media's; a volume with a size profile uses its chosen members (once chosen,
    /// [`RenderScene::choose_members`]; before, the swept field's name).
    pub fn fields(&self) -> Vec<String> {
        let mut names: Vec<String> = Vec::new();
        let haze = self.haze.as_ref().map(|h| &h.field);
        let media = self.media.iter().map(|m| &m.field);
        let volumes = self.volumes.iter().flat_map(|v| {
            match v.size.as_ref().and_then(|p| p.members.as_ref()) {
                Some(members) => members.fields.iter().collect(),
                None => vec![&v.field],
            }
        });
        for name in volumes.chain(haze).chain(media) {
            if !names.contains(name) {
                names.push(name.clone());
            }
        }
        names
    }

    /// Chooses, for every volume with a size profile, the members of its swept field that the
    /// renderer mixes ([`crate::volume::choose_members`]): `sweeps` are the scene's swept
    /// fields. The fields other volumes, the haze and the media use take their channels first;
    /// the rest of the [`MAX_FIELDS`](crate::volume::MAX_FIELDS) go to the one swept field sampled
    /// per voxel. Refuses, naming the volume and key: a profile on a field that is not swept or
    /// sweeps another key, a profile outside the sweep's values, a swept field used without
    /// a profile, two swept fields sampled per voxel, too few channels left.
    pub fn choose_members(&mut self, sweeps: &[format::SweepEntry]) -> Result<(), String> {
        let swept = |name: &str| sweeps.iter().find(|s| s.name == name);
        let mut sized: Option<(&format::SweepEntry, f64, f64)> = None;
        for (i, v) in self.volumes.iter().enumerate() {
            let at = format!("[[volume]] {} (field {:?})", i + 1, v.field);
            match (&v.size, swept(&v.field)) {
                (None, Some(s)) => {
                    return Err(format!(
                        "{at}: {:?} sweeps {} from {} to {}; give the volume a size per voxel, \
                         `{} = {{ base = …, top = … }}` (the adiabatic law between its base and \
                         top), or one of its members, {:?} … {:?}",
                        s.name,
                        s.key,
                        crate::checks::Shown(s.values[0]),
                        crate::checks::Shown(s.values[s.values.len() - 1]),
                        s.key,
                        s.fields[0],
                        s.fields[s.fields.len() - 1]
                    ));
                }
                (Some(p), None) => {
                    return Err(format!(
                        "{at}: {} = {{ base, top }} needs a swept field (a [[field]] with \
                         `sweep = {{ key = {:?}, … }}`); {:?} is not swept",
                        p.key, p.key, v.field
                    ));
                }
                (Some(p), Some(s)) => {
                    if p.key != s.key {
                        return Err(format!(
                            "{at}: the profile follows {} and {:?} sweeps {}",
                            p.key, s.name, s.key
                        ));
                    }
                    let (lo, hi) = p.range();
                    let (first, last) = (s.values[0], s.values[s.values.len() - 1]);
                    if lo < first * (1.0 - 1e-9) || hi > last * (1.0 + 1e-9) {
                        return Err(format!(
                            "{at}: {} = {{ base = {}, top = {} }} lies outside the sweep's \
                             values [{}, {}]",
                            p.key,
                            crate::checks::Shown(p.base),
                            crate::checks::Shown(p.top),
                            crate::checks::Shown(first),
                            crate::checks::Shown(last)
                        ));
                    }
                    sized = match sized {
                        Some((other, _, _)) if other.name != s.name => {
                            return Err(format!(
                                "{at}: a render samples one swept field per voxel; {:?} and \
                                 {:?} both have volumes with a size profile",
                                other.name, s.name
                            ));
                        }
                        Some((_, a, b)) => Some((s, a.min(lo), b.max(hi))),
                        None => Some((s, lo, hi)),
                    };
                }
                (None, None) => {}
            }
        }
        let Some((sweep, lo, hi)) = sized else {
            return Ok(());
        };
        let others = self.fields().iter().filter(|f| **f != sweep.name).count();
        let budget = crate::volume::MAX_FIELDS.saturating_sub(others);
        let members = crate::volume::choose_members(sweep, lo, hi, budget).ok_or_else(|| {
            format!(
                "a render holds {} fields and the other volumes, the haze and the media use \
                 {others}: the swept field {:?} needs 2 for a size per voxel",
                crate::volume::MAX_FIELDS,
                sweep.name
            )
        })?;
        for v in &mut self.volumes {
            if let Some(p) = &mut v.size {
                p.members = Some(members.clone());
            }
        }
        Ok(())
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
        let field = |name: &str| {
            let i = index(name);
            (i, tables.fields[i].sigma_ext_m2[1])
        };
        let grid = if self.volumes.is_empty() {
            crate::volume::DensityGrid::empty() // a scene of [[medium]] tables only
        } else {
            let mut grid = rasterize(&self.volumes, self.grid_resolution, field)?;
            grid.periodic = self.periodic;
            grid
        };
        let mut frame = self.frame_with(grid);
        frame.haze = self.haze(index);
        Ok(frame)
    }
}

#[cfg(test)]
mod tests {
    use super::key_line;

    #[test]
    fn a_range_error_is_placed_on_the_one_line_that_sets_its_key() {
        let text = "[sun]\nelevation_deg = 120\nazimuth_deg = 0\n[ground]\nalbedo = 2\n";
        let sun = "sun elevation_deg = 120 is outside the allowed range (0, 90]";
        assert_eq!(key_line(text, sun), Some(2));
        assert_eq!(
            key_line(text, "[ground] albedo = 2 is outside [0, 1]"),
            Some(5)
        );
        // Set on two lines: the message alone cannot say which.
        let twice = "[a]\nalbedo = 2\n[b]\nalbedo = 3\n";
        assert_eq!(key_line(twice, "[b] albedo = 3 is outside [0, 1]"), None);
        // No key named, or a key the text does not set.
        assert_eq!(key_line(text, "no [camera] table"), None);
        assert_eq!(key_line(text, "fov_deg = 0 must be in (0, 170)"), None);
    }
}
