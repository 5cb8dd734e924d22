//! Scene files: what a scene contains, so that only that is modelled.
//!
//! A scene is TOML with one `[scene]` table and any number of `[[field]]` tables:
//!
//! ```toml
//! [scene]
//! name = "default"
//! spectral = "spectral"     # or "rgb3" (Riley's 650/515/440 nm)
//! wavelengths = 31          # spectral samples over [wavelength_min_nm, wavelength_max_nm]
//! theta_step_deg = 0.18     # must divide 180
//! n_max = 26                # scattering orders Ams_1..Ams_N, or:
//! # max_optical_depth = 10  # N = ⌈τ + 4√τ + 4⌉ (the Poisson tail of the scatter count)
//! poisson_max_depth = 30    # largest optical depth D of the Poisson mixtures M(D, θ), (0, 1000]
//! quality = "standard"      # draft | standard | reference
//!
//! [[field]]
//! name = "cloud"            # user name: the EXR is <name>.exr
//! kind = "cloud"            # cloud | rain | haze (spheres), ice | snow (crystals)
//! # haze: aerosol spheres, lognormal with median_radius_um in [0.05, 1] (default 0.1, σ_g 2);
//! # refractive_index = [n, κ] (cloud, rain, haze) replaces the material's at every wavelength
//! # albedo = 0.99 (any field): the single-scattering albedo, (0, 1], replacing the particles'
//! #   own at every wavelength (the phase function and σ_ext stay)
//! # kind = "hg": a given Henyey–Greenstein lobe instead of particles: g in (−1, 1), and for a
//! #   two-term lobe g2 in (−1, 1) with weight (the first lobe's share, (0, 1)); extinction_m2,
//! #   the cross-section per particle, [1e-30, 1] m²; each one value or [R, G, B] (rgb3 only);
//! #   albedo default 1; albedo may be [R, G, B] (rgb3 only) on any field
//! # kind = "tabulated": a given phase-function table instead of particles: file (CSV or .npy,
//! #   relative to the scene's folder: θ in degrees from 0 to 180 increasing, then p in any
//! #   unit, one column for every wavelength or one per wavelength of the scene, R, G, B in
//! #   rgb3), linear in θ between rows and normalized by us; extinction_m2 as for hg
//! # crystals instead of a distribution: habit = "plate" | "column" | "aggregate",
//! # aspect_ratio (L/2a), max_dimension_um (median), dimension_sigma_g, roughness (Macke δ)
//! temperature_c = 10
//! distribution = { kind = "gamma", r_eff_um = 10, v_eff = 0.1 }
//! ```
//!
//! Errors name the key and its line; nothing is written before the whole scene is valid.
//! The tables `[render]`, `[camera]`, `[sun]`, `[sky]`, `[ground]`, `[haze]`, `[[volume]]` and `[[light]]`
//! belong to the renderer
//! (`photometeor render`, `photometeor-render`'s `scene` module) and are passed over here.

use std::path::{Path, PathBuf};

/// The smallest radius (µm) a sphere field's distribution may name (its median, effective or
/// only radius): 1 nm. At 1 nm water's extinction cross-section is ~10⁻²⁷ m²; at 10⁻⁶ µm it is
/// 1.1·10⁻³⁶ m², under the manifest's floor of 10⁻³⁰ m², which refused it only after the bake.
pub const MIN_RADIUS_UM: f64 = 1e-3;

use format::ChannelValues;
use mie::{Material, SizeDistribution};
use serde::{Deserialize, Serialize};
use thiserror::Error;
use toml::Spanned;

pub use tables::spectral::SpectralMode;

/// Number of optical depths of the Poisson-mixture table.
pub const POISSON_DEPTHS: usize = 64;

/// Smallest optical depth of the Poisson-mixture table (below it the rows are Ams_1 to 10⁻³).
pub const POISSON_MIN_DEPTH: f64 = 1e-3;

/// Most N × K values a channel's tables may hold (500 orders at 0.09°, 26 orders at 0.01° fit).
pub const MAX_TEXELS_PER_CHANNEL: usize = 2_000_000;

/// The scene `photometeor bake` uses when none is given: all four kinds.
pub const DEFAULT_SCENE: &str = include_str!("../data/scenes/default.toml");

/// A scene that cannot be used: the file, and where possible the line and key.
#[derive(Debug, Error)]
pub enum SceneError {
    /// The file could not be read.
    #[error("reading scene {}: {source}", path.display())]
    Read {
        /// The scene file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// A key's value is malformed or out of range.
    #[error("{origin} line {line}: {message}")]
    At {
        /// The scene file (or "default scene").
        origin: String,
        /// 1-based line of the key.
        line: usize,
        /// What is wrong, naming the key, its value and the allowed range.
        message: String,
    },
    /// The scene as a whole cannot be baked.
    #[error("{origin}: {message}")]
    Scene {
        /// The scene file.
        origin: String,
        /// What is wrong.
        message: String,
    },
}

/// Where a key sits: file and line.
#[derive(Debug, Clone)]
struct At {
    origin: String,
    line: usize,
}

impl At {
    fn error(self, message: String) -> SceneError {
        SceneError::At {
            origin: self.origin,
            line: self.line,
            message,
        }
    }
}

/// `return Err(at.error(format!(…)))`.
macro_rules! fail {
    ($at:expr, $($fmt:tt)*) => {
        return Err($at.error(format!($($fmt)*)))
    };
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SceneFile {
    scene: Spanned<Header>,
    #[serde(rename = "field", default)]
    fields: Vec<Spanned<FieldFile>>,
    // The renderer's tables (`render::scene`), checked there, not by the bake.
    #[serde(default, rename = "render")]
    _render: Option<toml::Value>,
    #[serde(default, rename = "camera")]
    _camera: Option<toml::Value>,
    #[serde(default, rename = "sun")]
    _sun: Option<toml::Value>,
    #[serde(default, rename = "sky")]
    _sky: Option<toml::Value>,
    #[serde(default, rename = "volume")]
    _volume: Option<toml::Value>,
    #[serde(default, rename = "ground")]
    _ground: Option<toml::Value>,
    #[serde(default, rename = "light")]
    _light: Option<toml::Value>,
    #[serde(default, rename = "haze")]
    _haze: Option<toml::Value>,
    #[serde(default, rename = "medium")]
    _medium: Option<toml::Value>,
    #[serde(default, rename = "occluder")]
    _occluder: Option<toml::Value>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Header {
    name: String,
    #[serde(default)]
    spectral: Option<String>,
    #[serde(default)]
    wavelengths: Option<usize>,
    #[serde(default)]
    wavelength_min_nm: Option<f64>,
    #[serde(default)]
    wavelength_max_nm: Option<f64>,
    #[serde(default)]
    theta_step_deg: Option<f64>,
    #[serde(default)]
    n_max: Option<usize>,
    #[serde(default)]
    max_optical_depth: Option<f64>,
    #[serde(default)]
    poisson_max_depth: Option<f64>,
    #[serde(default)]
    quality: Option<String>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct FieldFile {
    name: String,
    kind: FieldKind,
    #[serde(default)]
    temperature_c: Option<f64>,
    #[serde(default)]
    distribution: Option<SizeDistribution>,
    /// Sphere material (cloud, rain, haze): water (default) or ice (frozen drops).
    #[serde(default)]
    material: Option<mie::refractive::Material>,
    /// A sphere field's own refractive index m = n + iκ, the same at every wavelength.
    #[serde(default)]
    refractive_index: Option<[f64; 2]>,
    /// A given single-scattering albedo, one for all wavelengths or one per channel.
    #[serde(default)]
    albedo: Option<ChannelValues>,
    /// `hg` fields: the (first) lobe's asymmetry parameter.
    #[serde(default)]
    g: Option<ChannelValues>,
    /// `hg` fields: the second lobe's asymmetry parameter.
    #[serde(default)]
    g2: Option<ChannelValues>,
    /// `hg` fields: the first lobe's share of a two-term lobe.
    #[serde(default)]
    weight: Option<ChannelValues>,
    /// `hg` and `tabulated` fields: the extinction cross-section per particle (m²).
    #[serde(default)]
    extinction_m2: Option<ChannelValues>,
    /// `tabulated` fields: the table's file (CSV or .npy), relative to the scene's folder.
    #[serde(default)]
    file: Option<String>,
    /// Crystal habit (ice, snow): plate | column | aggregate; sets the default aspect ratio.
    #[serde(default)]
    habit: Option<String>,
    #[serde(default)]
    aspect_ratio: Option<f64>,
    #[serde(default)]
    max_dimension_um: Option<f64>,
    #[serde(default)]
    dimension_sigma_g: Option<f64>,
    #[serde(default)]
    roughness: Option<f64>,
    /// One microphysical key swept over a range: the field becomes one member per value.
    #[serde(default)]
    sweep: Option<SweepFile>,
}

/// `sweep = { key = "r_eff_um", from = 4, to = 32, count = 16, spacing = "log" }`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct SweepFile {
    key: String,
    from: f64,
    to: f64,
    #[serde(default)]
    count: Option<usize>,
    #[serde(default)]
    spacing: Option<Spacing>,
}

/// The keys a sweep can take, and where each lives: the sphere distribution of that kind, or
/// a crystal field.
pub const SWEEP_KEYS: [&str; 6] = [
    "r_eff_um",
    "median_radius_um",
    "radius_um",
    "rain_rate_mm_h",
    "max_dimension_um",
    "roughness",
];

/// The most values a sweep may have.
pub const MAX_SWEEP_COUNT: usize = 64;

/// How a sweep's values are spaced between `from` and `to`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Spacing {
    /// Equal ratios (the default: ring angles and the forward lobe scale with 1/size).
    Log,
    /// Equal steps.
    Linear,
}

/// A field swept over one microphysical key: its values and the member fields, one per value,
/// that the bake writes as ordinary fields named `<name>@<k>`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Sweep {
    /// The swept field's name in the scene.
    pub name: String,
    /// The swept key ([`SWEEP_KEYS`]).
    pub key: String,
    /// How the values are spaced.
    pub spacing: Spacing,
    /// The values, increasing, in the key's unit.
    pub values: Vec<f64>,
}

impl Sweep {
    /// The name of member `k` (the field at `values[k]`): `<name>@<k>`, two digits.
    pub fn member(&self, k: usize) -> String {
        format!("{}@{k:02}", self.name)
    }

    /// The member names, in the order of the values.
    pub fn members(&self) -> Vec<String> {
        (0..self.values.len()).map(|k| self.member(k)).collect()
    }

    /// The sweep as the manifest records it.
    pub fn entry(&self) -> format::SweepEntry {
        format::SweepEntry {
            name: self.name.clone(),
            key: self.key.clone(),
            spacing: match self.spacing {
                Spacing::Log => "log".into(),
                Spacing::Linear => "linear".into(),
            },
            values: self.values.clone(),
            fields: self.members(),
        }
    }
}

/// What a particle field is made of: the format's own vocabulary, which manifests and the
/// runtime share.
pub use format::FieldKind;

/// Accuracy presets; their node counts are set from the measured speed/accuracy trade.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Quality {
    /// Fewest nodes and rays (counts in [`Quality::knobs`]): fast, coarse.
    Draft,
    /// The default: the middle preset.
    Standard,
    /// Most nodes and rays: the slowest and most accurate.
    Reference,
}

impl Quality {
    /// Parses "draft", "standard" or "reference"; None for anything else.
    pub fn parse(text: &str) -> Option<Self> {
        match text {
            "draft" => Some(Self::Draft),
            "standard" => Some(Self::Standard),
            "reference" => Some(Self::Reference),
            _ => None,
        }
    }
}

/// One validated particle field.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Field {
    /// User name (ASCII letters, digits, '_', '-'); the EXR is `<name>.exr`.
    pub name: String,
    /// What the field is made of.
    pub kind: FieldKind,
    /// Temperature, °C (default 10 for cloud and rain, −20 for ice and snow); water: [−12, 99].
    pub temperature_c: f64,
    /// What the particles are made of: spheres of water (default) or ice; crystals are ice.
    pub material: mie::refractive::Material,
    /// A sphere field's given refractive index [n, κ], replacing `material`'s at every
    /// wavelength; n in (1, 3], κ in [0, 10].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub refractive_index: Option<[f64; 2]>,
    /// A given single-scattering albedo σ_sca/σ_ext in (0, 1], replacing the particles' own at
    /// every wavelength (σ_ext and the phase function stay as computed); `None`: their own.
    /// One per channel (R, G, B; the three equal where the scene gave one value).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub albedo: Option<[f64; 3]>,
    /// A given lobe instead of particles (`kind = "hg"`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub hg: Option<mie::hg::HgField>,
    /// A given table instead of particles (`kind = "tabulated"`), as read from its file (so
    /// the cache key holds its values).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tabulated: Option<mie::tabulated::TabulatedField>,
    /// Size distribution of spheres (cloud, rain).
    pub distribution: Option<SizeDistribution>,
    /// Crystal population (ice, snow).
    pub crystal: Option<mie::crystal::CrystalField>,
}

impl Field {
    /// m = n + iκ at `wavelength_nm`: the given [`Field::refractive_index`], else the
    /// material's at the field's temperature.
    pub fn refractive_index(
        &self,
        wavelength_nm: f64,
    ) -> Result<num_complex::Complex64, mie::MieError> {
        match self.refractive_index {
            Some([n, kappa]) => Ok(num_complex::Complex64::new(n, kappa)),
            None => self
                .material
                .refractive_index(wavelength_nm, self.temperature_c),
        }
    }
}

/// A validated scene: plain data.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Scene {
    /// Scene name, from `[scene] name`.
    pub name: String,
    /// Spectral sampling: RGB3 or wavelengths over a range.
    pub spectral: SpectralMode,
    /// Angular bin width Δθ, degrees: divides 180, in [0.01, 30] (default 0.18).
    pub theta_step_deg: f64,
    /// Highest scattering order N of Ams_1..Ams_N, in [1, 10000] (default 26).
    pub n_max: usize,
    /// Largest optical depth of the Poisson-mixture table M(D, θ) (`format::poisson`), in
    /// (0, 1000] (default 30); its [`POISSON_DEPTHS`] depths are log-spaced from
    /// [`POISSON_MIN_DEPTH`] to it.
    pub poisson_max_depth: f64,
    /// Accuracy preset (default standard).
    pub quality: Quality,
    /// The particle fields, at least one, with distinct names; a swept field is here as its
    /// members, one per value ([`Sweep::member`]).
    pub fields: Vec<Field>,
    /// The swept fields, in the scene's order.
    pub sweeps: Vec<Sweep>,
}

/// 1-based line of byte offset `at` in `text`.
fn line_of(text: &str, at: usize) -> usize {
    text[..at.min(text.len())].matches('\n').count() + 1
}

/// Line of `key =` in the table that starts at the span (up to the next table header), or
/// the span's first line.
fn key_line(text: &str, span: std::ops::Range<usize>, key: &str) -> usize {
    let body = &text[span.start.min(text.len())..];
    let found = body.lines().scan(span.start, |offset, line| {
        let here = *offset;
        *offset += line.len() + 1;
        Some((here, line))
    });
    for (i, (offset, line)) in found.enumerate() {
        if i > 0 && line.trim_start().starts_with('[') {
            break;
        }
        let t = line.trim_start();
        if t.starts_with(key) && t[key.len()..].trim_start().starts_with('=') {
            return line_of(text, offset);
        }
    }
    line_of(text, span.start)
}

impl Scene {
    /// The optical depths of the Poisson-mixture table: [`POISSON_DEPTHS`] values log-spaced
    /// from [`POISSON_MIN_DEPTH`] to `poisson_max_depth`.
    pub fn poisson_depths(&self) -> Vec<f64> {
        let (a, b) = (POISSON_MIN_DEPTH.ln(), self.poisson_max_depth.ln());
        (0..POISSON_DEPTHS)
            .map(|j| {
                if j + 1 == POISSON_DEPTHS {
                    self.poisson_max_depth
                } else if j == 0 {
                    POISSON_MIN_DEPTH
                } else {
                    (a + (b - a) * j as f64 / (POISSON_DEPTHS - 1) as f64).exp()
                }
            })
            .collect()
    }

    /// The scene file at `path`, or the embedded default scene.
    pub fn from_file_or_default(path: Option<&Path>) -> Result<Self, SceneError> {
        match path {
            Some(p) => Self::from_file(p),
            None => Self::parse(DEFAULT_SCENE, "default scene"),
        }
    }

    /// Reads and validates a scene file.
    pub fn from_file(path: &Path) -> Result<Self, SceneError> {
        let text = std::fs::read_to_string(path).map_err(|source| SceneError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        Self::parse_in(&text, &path.display().to_string(), path.parent())
    }

    /// Parses and validates scene text; `origin` names it in errors; a field's `file` is
    /// relative to the working folder.
    pub fn parse(text: &str, origin: &str) -> Result<Self, SceneError> {
        Self::parse_in(text, origin, None)
    }

    /// Parses and validates scene text; `origin` names it in errors; a field's `file` is
    /// relative to `dir` (the working folder where None).
    pub fn parse_in(text: &str, origin: &str, dir: Option<&Path>) -> Result<Self, SceneError> {
        let file: SceneFile = toml::from_str(text).map_err(|e| SceneError::At {
            origin: origin.to_string(),
            line: e.span().map(|s| line_of(text, s.start)).unwrap_or(0),
            message: e.message().to_string(),
        })?;
        let keys = Keys {
            text,
            origin,
            span: file.scene.span(),
            dir,
        };
        let header = file.scene.into_inner();
        header.check_name(&keys)?;
        let theta_step_deg = header.theta_step_deg(&keys)?;
        let n_max = header.n_max(&keys)?;
        let poisson_max_depth = header.poisson_max_depth(&keys)?;
        let spectral = header.spectral(&keys)?;
        header.check_table_size(&keys, n_max, theta_step_deg)?;
        let quality = header.quality(&keys)?;

        let mut fields: Vec<Field> = Vec::new();
        let mut sweeps: Vec<Sweep> = Vec::new();
        for spanned in file.fields {
            let keys = Keys {
                text,
                origin,
                span: spanned.span(),
                dir,
            };
            let mut field = spanned.into_inner();
            if sweeps.iter().any(|s| s.name == field.name) {
                fail!(keys.at("name"), "field name {:?} is used twice", field.name);
            }
            let Some(sweep) = field.sweep.take() else {
                fields.push(field.validated(&keys, &fields, &spectral)?);
                continue;
            };
            let sweep = field.checked_sweep(&keys, sweep)?;
            let before = fields.len();
            for (k, &value) in sweep.values.iter().enumerate() {
                let mut member = field.clone();
                member.set(&sweep.key, value);
                let mut validated = member
                    .validated(&keys, &fields[..before], &spectral)
                    .map_err(|e| {
                        let message = match e {
                            SceneError::At { message, .. } | SceneError::Scene { message, .. } => {
                                message
                            }
                            other => other.to_string(),
                        };
                        keys.at("sweep").error(format!(
                            "field {:?}: sweep of {} at {} = {}: {message}",
                            field.name,
                            sweep.key,
                            sweep.key,
                            mie::error::Shown(value)
                        ))
                    })?;
                validated.name = sweep.member(k);
                fields.push(validated);
            }
            sweeps.push(sweep);
        }
        if fields.is_empty() {
            return Err(SceneError::Scene {
                origin: origin.to_string(),
                message: "the scene has no [[field]]; nothing to bake".into(),
            });
        }
        Ok(Scene {
            name: header.name,
            spectral,
            theta_step_deg,
            n_max,
            poisson_max_depth,
            quality,
            fields,
            sweeps,
        })
    }
}

/// One TOML table of a scene text: finds the file and line of its keys for errors.
struct Keys<'a> {
    text: &'a str,
    origin: &'a str,
    span: std::ops::Range<usize>,
    /// The folder a field's `file` is relative to (the scene file's; None: the working one).
    dir: Option<&'a Path>,
}

impl Keys<'_> {
    /// Where `key =` sits in this table (or the table's first line when it is absent).
    fn at(&self, key: &str) -> At {
        At {
            origin: self.origin.to_string(),
            line: key_line(self.text, self.span.clone(), key),
        }
    }
}

/// The `[scene]` table's keys, each checked in turn (in this order, so the first bad key of a
/// scene is the one reported).
impl Header {
    /// Refuses an empty, over-long (> 200 characters) or control-character scene name.
    fn check_name(&self, keys: &Keys) -> Result<(), SceneError> {
        if self.name.is_empty()
            || self.name.chars().count() > 200
            || self.name.chars().any(char::is_control)
        {
            fail!(
                keys.at("name"),
                "scene name {:?} must have 1 to 200 characters and no control characters",
                self.name
            );
        }
        Ok(())
    }

    /// Δθ in degrees (default 0.18): must divide 180 and lie in [0.01, 30].
    fn theta_step_deg(&self, keys: &Keys) -> Result<f64, SceneError> {
        let theta_step_deg = self.theta_step_deg.unwrap_or(0.18);
        if grid::ThetaGrid::new(theta_step_deg).is_err() {
            fail!(
                keys.at("theta_step_deg"),
                "theta_step_deg = {theta_step_deg} must divide 180° and lie in [0.01, 30]"
            );
        }
        Ok(theta_step_deg)
    }

    /// N from `n_max` ([1, 10000]) or from `max_optical_depth` τ ((0, 5000]) as
    /// ⌈τ + 4√τ + 4⌉, never both; default 26.
    fn n_max(&self, keys: &Keys) -> Result<usize, SceneError> {
        Ok(match (self.n_max, self.max_optical_depth) {
            (Some(_), Some(_)) => fail!(
                keys.at("max_optical_depth"),
                "give n_max or max_optical_depth, not both"
            ),
            (Some(n), None) => {
                if !(1..=10_000).contains(&n) {
                    fail!(
                        keys.at("n_max"),
                        "n_max = {n} is outside the allowed range [1, 10000]"
                    );
                }
                n
            }
            (None, Some(tau)) => {
                if !(tau.is_finite() && tau > 0.0 && tau <= 5000.0) {
                    fail!(
                        keys.at("max_optical_depth"),
                        "max_optical_depth = {tau} is outside the allowed range (0, 5000]"
                    );
                }
                (tau + 4.0 * tau.sqrt() + 4.0).ceil() as usize
            }
            (None, None) => 26,
        })
    }

    /// Largest optical depth of the Poisson mixtures (default 30), in
    /// ([`POISSON_MIN_DEPTH`], 1000].
    fn poisson_max_depth(&self, keys: &Keys) -> Result<f64, SceneError> {
        let poisson_max_depth = self.poisson_max_depth.unwrap_or(30.0);
        if !(poisson_max_depth.is_finite()
            && poisson_max_depth > POISSON_MIN_DEPTH
            && poisson_max_depth <= 1000.0)
        {
            fail!(
                keys.at("poisson_max_depth"),
                "poisson_max_depth = {poisson_max_depth} is outside the allowed range \
                 ({POISSON_MIN_DEPTH}, 1000] (optical depth)"
            );
        }
        Ok(poisson_max_depth)
    }

    /// `rgb3`, or `spectral` (default) with [3, 1000] wavelengths over a range in nm within
    /// [360, 830] (default [400, 700]).
    fn spectral(&self, keys: &Keys) -> Result<SpectralMode, SceneError> {
        Ok(match self.spectral.as_deref().unwrap_or("spectral") {
            "rgb3" => SpectralMode::Rgb3,
            "spectral" => {
                let count = self.wavelengths.unwrap_or(31);
                let (min_nm, max_nm) = (
                    self.wavelength_min_nm.unwrap_or(400.0),
                    self.wavelength_max_nm.unwrap_or(700.0),
                );
                if !(3..=1000).contains(&count) {
                    fail!(
                        keys.at("wavelengths"),
                        "wavelengths = {count} is outside the allowed range [3, 1000]"
                    );
                }
                if !(min_nm >= 360.0 && max_nm <= 830.0 && min_nm < max_nm) {
                    fail!(
                        keys.at("wavelength_min_nm"),
                        "wavelength range [{min_nm}, {max_nm}] nm must lie within the CIE table [360, 830] nm"
                    );
                }
                SpectralMode::Spectral {
                    count,
                    min_nm,
                    max_nm,
                }
            }
            other => fail!(
                keys.at("spectral"),
                "spectral = {other:?} is not one of \"spectral\", \"rgb3\""
            ),
        })
    }

    /// Refuses tables over [`MAX_TEXELS_PER_CHANNEL`] values (N orders × K angles) per
    /// channel.
    fn check_table_size(
        &self,
        keys: &Keys,
        n_max: usize,
        theta_step_deg: f64,
    ) -> Result<(), SceneError> {
        // The tables hold N × K values per channel and wavelength mixture; bound their size
        // (and so the bake's memory and time) before anything is computed.
        let angles = (180.0 / theta_step_deg).round() as usize + 1;
        if n_max * angles > MAX_TEXELS_PER_CHANNEL {
            let key = if self.max_optical_depth.is_some() {
                "max_optical_depth"
            } else {
                "n_max"
            };
            fail!(
                keys.at(key),
                "n_max = {n_max} orders × {angles} angles (theta_step_deg = {theta_step_deg}) = {} texels per channel exceeds the allowed {MAX_TEXELS_PER_CHANNEL} (≈ {:.0} MB of tables in memory); lower n_max or raise theta_step_deg",
                n_max * angles,
                (n_max * angles * 3 * 8 * 4) as f64 / 1e6
            );
        }
        Ok(())
    }

    /// The accuracy preset (default standard).
    fn quality(&self, keys: &Keys) -> Result<Quality, SceneError> {
        Ok(match self.quality.as_deref() {
            None => Quality::Standard,
            Some(q) => Quality::parse(q).ok_or_else(|| {
                keys.at("quality").error(format!(
                    "quality = {q:?} is not one of draft, standard, reference"
                ))
            })?,
        })
    }
}

/// A key's three channel values (R, G, B), each within `ok` (`range` in words): one value for
/// all, or three where the scene samples one wavelength per channel (`rgb3`).
fn per_channel(
    keys: &Keys,
    spectral: &SpectralMode,
    key: &str,
    value: ChannelValues,
    ok: &dyn Fn(f64) -> bool,
    range: &str,
) -> Result<[f64; 3], SceneError> {
    let values = match value {
        ChannelValues::One(v) => {
            if !ok(v) {
                fail!(
                    keys.at(key),
                    "{key} = {v} is outside the allowed range {range}"
                );
            }
            return Ok([v; 3]);
        }
        ChannelValues::Three(v) => v,
    };
    if *spectral != SpectralMode::Rgb3 {
        fail!(
            keys.at(key),
            "{key} = {values:?}: one value per channel needs spectral = \"rgb3\" (one \
             wavelength per channel); give one value for all wavelengths"
        );
    }
    for (c, v) in ["R", "G", "B"].iter().zip(values) {
        if !ok(v) {
            fail!(
                keys.at(key),
                "{key} = {values:?}: the {c} value {v} is outside the allowed range {range}"
            );
        }
    }
    Ok(values)
}

/// A `[[field]]` table's keys, each checked in turn (in this order, so the first bad key of a
/// field is the one reported).
impl FieldFile {
    /// The validated field; `earlier` are the scene's fields before it (names must differ).
    fn validated(
        self,
        keys: &Keys,
        earlier: &[Field],
        spectral: &SpectralMode,
    ) -> Result<Field, SceneError> {
        self.check_name(keys, earlier)?;
        let (material, temperature_c) = self.material_and_temperature(keys)?;
        self.check_refractive_index(keys)?;
        let albedo = self.albedo(keys, spectral)?;
        self.given_keys_fit_the_kind(keys)?;
        let hg = self.hg(keys, spectral)?;
        let tabulated = self.tabulated(keys, spectral)?;
        let distribution = self.haze_distribution(keys)?;
        let (distribution, crystal) = match self.kind {
            FieldKind::Cloud | FieldKind::Rain | FieldKind::Haze => {
                let d = self.sphere_distribution(keys, distribution, material, temperature_c)?;
                (Some(d), None)
            }
            FieldKind::Ice | FieldKind::Snow => (None, Some(self.crystal(keys, distribution)?)),
            FieldKind::Hg | FieldKind::Tabulated => (None, None),
        };
        Ok(Field {
            name: self.name,
            kind: self.kind,
            temperature_c,
            material,
            refractive_index: self.refractive_index,
            albedo,
            hg,
            tabulated,
            distribution,
            crystal,
        })
    }

    /// The checked sweep: a key this field has ([`SWEEP_KEYS`]), `from` < `to` (both > 0 for
    /// log spacing), `count` in [2, [`MAX_SWEEP_COUNT`]] (default: [`default_sweep_count`]).
    fn checked_sweep(&self, keys: &Keys, s: SweepFile) -> Result<Sweep, SceneError> {
        let at = || keys.at("sweep");
        let has = match (s.key.as_str(), self.distribution) {
            ("r_eff_um", Some(SizeDistribution::Gamma { .. }))
            | ("median_radius_um", Some(SizeDistribution::Lognormal { .. }))
            | ("radius_um", Some(SizeDistribution::Monodisperse { .. }))
            | ("rain_rate_mm_h", Some(SizeDistribution::MarshallPalmer { .. })) => true,
            ("max_dimension_um" | "roughness", _) => {
                matches!(self.kind, FieldKind::Ice | FieldKind::Snow)
            }
            _ => false,
        };
        if !has {
            let what = match (self.kind, self.distribution) {
                (FieldKind::Ice | FieldKind::Snow, _) => "a crystal field".to_string(),
                (_, Some(d)) => format!("a {} distribution", distribution_kind(&d)),
                (_, None) => "a field without a distribution".to_string(),
            };
            fail!(
                at(),
                "field {:?}: sweep key = {:?} cannot sweep {what}; the keys that can:                  r_eff_um (gamma), median_radius_um (lognormal), radius_um (monodisperse),                  rain_rate_mm_h (marshall_palmer), max_dimension_um and roughness (ice, snow)",
                self.name,
                s.key
            );
        }
        let spacing = s.spacing.unwrap_or(Spacing::Log);
        let (from, to) = (s.from, s.to);
        if !(from.is_finite() && to.is_finite() && from < to) {
            fail!(
                at(),
                "field {:?}: sweep from = {}, to = {}: from must be less than to (both finite)",
                self.name,
                mie::error::Shown(from),
                mie::error::Shown(to)
            );
        }
        if spacing == Spacing::Log && from <= 0.0 {
            fail!(
                at(),
                "field {:?}: sweep from = {}: a log sweep needs from > 0 (or spacing = \"linear\")",
                self.name,
                mie::error::Shown(from)
            );
        }
        let count = s
            .count
            .unwrap_or_else(|| default_sweep_count(spacing, from, to));
        if !(2..=MAX_SWEEP_COUNT).contains(&count) {
            fail!(
                at(),
                "field {:?}: sweep count = {count} is outside the allowed range [2, {MAX_SWEEP_COUNT}]",
                self.name
            );
        }
        let values: Vec<f64> = (0..count)
            .map(|k| {
                let t = k as f64 / (count - 1) as f64;
                match (k, spacing) {
                    (0, _) => from,
                    (k, _) if k + 1 == count => to,
                    (_, Spacing::Log) => (from.ln() + t * (to / from).ln()).exp(),
                    (_, Spacing::Linear) => from + t * (to - from),
                }
            })
            .collect();
        // Values that round to one another (from and to too close for the count) would bake
        // the same member twice; the manifest holds strictly increasing values only. A log
        // sweep is interpolated in ln value, so those must differ too.
        let coordinate = |v: f64| match spacing {
            Spacing::Log => v.ln(),
            Spacing::Linear => v,
        };
        if let Some(k) = values
            .windows(2)
            .position(|w| !(w[0] < w[1] && coordinate(w[0]) < coordinate(w[1])))
        {
            let (a, b) = (
                mie::error::Shown(values[k]),
                mie::error::Shown(values[k + 1]),
            );
            let what = if values[k] == values[k + 1] {
                format!("are both {a}")
            } else {
                format!("({a} and {b}) have the same logarithm")
            };
            fail!(
                at(),
                "field {:?}: sweep from = {}, to = {}, count = {count}: values {k} and {} {what} \
                 (a {} sweep this narrow cannot hold {count} distinct values); widen it or \
                 lower count",
                self.name,
                mie::error::Shown(from),
                mie::error::Shown(to),
                k + 1,
                match spacing {
                    Spacing::Log => "log",
                    Spacing::Linear => "linear",
                }
            );
        }
        Ok(Sweep {
            name: self.name.clone(),
            key: s.key,
            spacing,
            values,
        })
    }

    /// Sets the swept key to `value` (a key [`FieldFile::sweep`] accepted).
    fn set(&mut self, key: &str, value: f64) {
        use SizeDistribution as D;
        match (key, &mut self.distribution) {
            ("r_eff_um", Some(D::Gamma { r_eff_um, .. })) => *r_eff_um = value,
            (
                "median_radius_um",
                Some(D::Lognormal {
                    median_radius_um, ..
                }),
            ) => *median_radius_um = value,
            ("radius_um", Some(D::Monodisperse { radius_um })) => *radius_um = value,
            ("rain_rate_mm_h", Some(D::MarshallPalmer { rain_rate_mm_h })) => {
                *rain_rate_mm_h = value
            }
            ("max_dimension_um", _) => self.max_dimension_um = Some(value),
            ("roughness", _) => self.roughness = Some(value),
            _ => unreachable!("sweep key {key} checked"),
        }
    }

    /// Refuses a name that is not 1 to 200 ASCII letters, digits, '_' or '-', or that an
    /// earlier field has.
    fn check_name(&self, keys: &Keys, earlier: &[Field]) -> Result<(), SceneError> {
        if self.name.is_empty()
            || self.name.len() > 200
            || !self
                .name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
        {
            fail!(
                keys.at("name"),
                "field name {:?} must be 1 to 200 ASCII letters, digits, '_' or '-' (it names the EXR file)",
                self.name
            );
        }
        if earlier
            .iter()
            .any(|g| g.name == self.name || g.name.split('@').next() == Some(&self.name))
        {
            fail!(keys.at("name"), "field name {:?} is used twice", self.name);
        }
        Ok(())
    }

    /// The material (default water for spheres, ice for crystals) and its temperature in °C
    /// (default 10 for water, −20 for ice; ice in [−100, 0]); crystals must be ice.
    fn material_and_temperature(&self, keys: &Keys) -> Result<(Material, f64), SceneError> {
        let material = self.material.unwrap_or(match self.kind {
            // A lobe has no material; water's stands in (nothing reads it).
            FieldKind::Cloud | FieldKind::Rain | FieldKind::Haze => Material::Water,
            FieldKind::Hg | FieldKind::Tabulated => Material::Water,
            FieldKind::Ice | FieldKind::Snow => Material::Ice,
        });
        // Liquid drops at 10 °C, ice (crystals or frozen drops) at −20 °C unless given.
        let temperature_c = self.temperature_c.unwrap_or(match material {
            Material::Water => 10.0,
            Material::Ice => -20.0,
        });
        if material == Material::Ice
            && !(temperature_c.is_finite() && (-100.0..=0.0).contains(&temperature_c))
        {
            fail!(
                keys.at("temperature_c"),
                "temperature_c = {temperature_c} is outside the allowed range [-100, 0] °C for ice"
            );
        }
        if material == Material::Water && matches!(self.kind, FieldKind::Ice | FieldKind::Snow) {
            fail!(
                keys.at("material"),
                "field {:?} ({:?}): crystals are ice; material = \"water\" is only for cloud and rain",
                self.name,
                self.kind
            );
        }
        Ok((material, temperature_c))
    }

    /// A given refractive index [n, κ] is for spheres only, with n in (1, 3] and κ in [0, 10].
    fn check_refractive_index(&self, keys: &Keys) -> Result<(), SceneError> {
        if let Some([n, kappa]) = self.refractive_index {
            if matches!(self.kind, FieldKind::Ice | FieldKind::Snow) {
                fail!(
                    keys.at("refractive_index"),
                    "field {:?} ({:?}): crystals are ice; refractive_index is for spheres \
                     (cloud, rain, haze)",
                    self.name,
                    self.kind
                );
            }
            if !(n.is_finite() && n > 1.0 && n <= 3.0) {
                fail!(
                    keys.at("refractive_index"),
                    "refractive_index = [{n}, {kappa}]: n = {n} is outside the allowed range \
                     (1, 3]"
                );
            }
            if !(kappa.is_finite() && (0.0..=10.0).contains(&kappa)) {
                fail!(
                    keys.at("refractive_index"),
                    "refractive_index = [{n}, {kappa}]: κ = {kappa} is outside the allowed \
                     range [0, 10]"
                );
            }
        }
        Ok(())
    }

    /// A given albedo, per channel, each in (0, 1].
    fn albedo(&self, keys: &Keys, spectral: &SpectralMode) -> Result<Option<[f64; 3]>, SceneError> {
        self.albedo
            .map(|a| {
                per_channel(
                    keys,
                    spectral,
                    "albedo",
                    a,
                    &|a| a > 0.0 && a <= 1.0,
                    "(0, 1] (the share of the extinguished light that is scattered)",
                )
            })
            .transpose()
    }

    /// A given phase function's keys on its kind only (`g`, `g2`, `weight` on hg, `file` on
    /// tabulated, `extinction_m2` on both), and no key of particles on either.
    fn given_keys_fit_the_kind(&self, keys: &Keys) -> Result<(), SceneError> {
        let given_keys = [
            ("g", self.g.is_some(), FieldKind::Hg == self.kind),
            ("g2", self.g2.is_some(), FieldKind::Hg == self.kind),
            ("weight", self.weight.is_some(), FieldKind::Hg == self.kind),
            (
                "file",
                self.file.is_some(),
                FieldKind::Tabulated == self.kind,
            ),
            (
                "extinction_m2",
                self.extinction_m2.is_some(),
                self.kind.is_given(),
            ),
        ];
        if let Some((key, _, _)) = given_keys.iter().find(|(_, given, fits)| *given && !fits) {
            let owner = match *key {
                "file" => "kind = \"tabulated\" fields (a given table)",
                "extinction_m2" => "given phase functions (kind = \"hg\" or \"tabulated\")",
                _ => "kind = \"hg\" fields (a given lobe)",
            };
            fail!(
                keys.at(key),
                "field {:?} ({}): {key} is a key of {owner}",
                self.name,
                self.kind
            );
        }
        if !self.kind.is_given() {
            return Ok(());
        }
        let particle_keys = [
            ("distribution", self.distribution.is_some()),
            ("material", self.material.is_some()),
            ("temperature_c", self.temperature_c.is_some()),
            ("refractive_index", self.refractive_index.is_some()),
            ("habit", self.habit.is_some()),
            ("aspect_ratio", self.aspect_ratio.is_some()),
            ("max_dimension_um", self.max_dimension_um.is_some()),
            ("dimension_sigma_g", self.dimension_sigma_g.is_some()),
            ("roughness", self.roughness.is_some()),
        ];
        if let Some((key, _)) = particle_keys.iter().find(|(_, given)| *given) {
            let what = if self.kind == FieldKind::Hg {
                "an hg field is a given lobe (g, g2, weight, extinction_m2, albedo)"
            } else {
                "a tabulated field is a given table (file, extinction_m2, albedo)"
            };
            fail!(
                keys.at(key),
                "field {:?} ({}): {key} is a key of particles; {what}",
                self.name,
                self.kind
            );
        }
        Ok(())
    }

    /// The cross-section of a given phase function: extinction_m2 in [1e-30, 1] m², one value
    /// or [R, G, B] (rgb3).
    fn extinction(&self, keys: &Keys, spectral: &SpectralMode) -> Result<[f64; 3], SceneError> {
        let Some(extinction_m2) = self.extinction_m2 else {
            fail!(
                keys.at("kind"),
                "field {:?} ({}): extinction_m2, the extinction cross-section per particle in \
                 [1e-30, 1] m², is missing",
                self.name,
                self.kind
            );
        };
        per_channel(
            keys,
            spectral,
            "extinction_m2",
            extinction_m2,
            &|e| e.is_finite() && (1e-30..=1.0).contains(&e),
            "[1e-30, 1] m²",
        )
    }

    /// A `tabulated` field's table, read from `file` (relative to the scene's folder) and
    /// checked, with its cross-section; its columns one for all wavelengths or one per
    /// wavelength of the scene (R, G, B in rgb3).
    fn tabulated(
        &self,
        keys: &Keys,
        spectral: &SpectralMode,
    ) -> Result<Option<mie::tabulated::TabulatedField>, SceneError> {
        if self.kind != FieldKind::Tabulated {
            return Ok(None);
        }
        let Some(file) = &self.file else {
            fail!(
                keys.at("kind"),
                "field {:?} (tabulated): file, the table of p(θ) (CSV or .npy: θ in degrees, then \
                 one column or one per wavelength), is missing",
                self.name
            );
        };
        let extinction_m2 = self.extinction(keys, spectral)?;
        let path = match keys.dir {
            Some(dir) => dir.join(file),
            None => PathBuf::from(file),
        };
        let at = || keys.at("file");
        let table = crate::phase_table::Table::read(&path, file)
            .map_err(|e| at().error(format!("field {:?} (tabulated): {e}", self.name)))?;
        let wavelengths = match spectral {
            SpectralMode::Rgb3 => 3,
            SpectralMode::Spectral { count, .. } => *count,
        };
        let columns = table.columns.len();
        if columns != 1 && columns != wavelengths {
            fail!(
                at(),
                "field {:?} (tabulated): file {file} has {columns} columns of p after θ; give one \
                 (every wavelength) or one per wavelength of the scene ({wavelengths}{})",
                self.name,
                if wavelengths == 3 { ": R, G, B" } else { "" }
            );
        }
        let field = table
            .field(file, extinction_m2)
            .map_err(|e| at().error(format!("field {:?} (tabulated): {e}", self.name)))?;
        Ok(Some(field))
    }

    /// An `hg` field's lobe and cross-section, checked (g, g2 in (−1, 1), weight in (0, 1) with
    /// g2, extinction_m2 in [1e-30, 1] m²; each one value or [R, G, B], the latter with `rgb3`
    /// only).
    fn hg(
        &self,
        keys: &Keys,
        spectral: &SpectralMode,
    ) -> Result<Option<mie::hg::HgField>, SceneError> {
        if self.kind != FieldKind::Hg {
            return Ok(None);
        }
        let channels = |key: &str, value: ChannelValues, ok: &dyn Fn(f64) -> bool, range| {
            per_channel(keys, spectral, key, value, ok, range)
        };
        let asymmetry = |g: f64| g.is_finite() && g > -1.0 && g < 1.0;
        let Some(g) = self.g else {
            fail!(
                keys.at("kind"),
                "field {:?} (hg): g, the lobe's asymmetry parameter in (−1, 1), is missing",
                self.name
            );
        };
        let g = channels("g", g, &asymmetry, "(−1, 1)")?;
        let (g2, weight) = match (self.g2, self.weight) {
            (None, None) => ([0.0; 3], [1.0; 3]),
            (Some(g2), Some(w)) => (
                channels("g2", g2, &asymmetry, "(−1, 1)")?,
                channels(
                    "weight",
                    w,
                    &|w| w > 0.0 && w < 1.0,
                    "(0, 1) (the first lobe's share)",
                )?,
            ),
            (Some(_), None) => fail!(
                keys.at("g2"),
                "field {:?} (hg): g2 needs weight, the first lobe's share in (0, 1)",
                self.name
            ),
            (None, Some(_)) => fail!(
                keys.at("weight"),
                "field {:?} (hg): weight needs g2, the second lobe's asymmetry parameter",
                self.name
            ),
        };
        let extinction_m2 = self.extinction(keys, spectral)?;
        Ok(Some(mie::hg::HgField {
            lobes: std::array::from_fn(|c| mie::hg::HgLobe {
                g: g[c],
                g2: g2[c],
                weight: weight[c],
            }),
            extinction_m2,
        }))
    }

    /// The size distribution as given; for haze the default (lognormal, median 0.1 µm,
    /// σ_g 2) or a given lognormal with its median radius in [0.05, 1] µm.
    fn haze_distribution(&self, keys: &Keys) -> Result<Option<SizeDistribution>, SceneError> {
        Ok(match (self.kind, self.distribution) {
            (FieldKind::Haze, None) => Some(SizeDistribution::Lognormal {
                median_radius_um: 0.1,
                sigma_g: 2.0,
            }),
            (FieldKind::Haze, Some(d)) => {
                let SizeDistribution::Lognormal {
                    median_radius_um, ..
                } = d
                else {
                    fail!(
                        keys.at("distribution"),
                        "field {:?} (haze): distribution must be lognormal (kind = \
                         \"lognormal\", median_radius_um, sigma_g)",
                        self.name
                    );
                };
                if !(0.05..=1.0).contains(&median_radius_um) {
                    fail!(
                        keys.at("distribution"),
                        "field {:?} (haze): median_radius_um = {median_radius_um} is outside \
                         the allowed range [0.05, 1] µm of aerosols (cloud droplets are kind \
                         = \"cloud\")",
                        self.name
                    );
                }
                Some(d)
            }
            (_, d) => d,
        })
    }

    /// A sphere field's validated size distribution (required), its size at least
    /// [`MIN_RADIUS_UM`]; liquid water must lie in
    /// [−12, 99] °C, where its density is known.
    fn sphere_distribution(
        &self,
        keys: &Keys,
        distribution: Option<SizeDistribution>,
        material: Material,
        temperature_c: f64,
    ) -> Result<SizeDistribution, SceneError> {
        let d = distribution.ok_or_else(|| {
            keys.at("kind").error(format!(
                "field {:?} ({:?}) needs a distribution",
                self.name, self.kind
            ))
        })?;
        let d = d.validated().map_err(|e| {
            keys.at("distribution")
                .error(format!("field {:?}: distribution: {e}", self.name))
        })?;
        let size = match d {
            SizeDistribution::Lognormal {
                median_radius_um, ..
            } => Some(("median_radius_um", median_radius_um)),
            SizeDistribution::Gamma { r_eff_um, .. } => Some(("r_eff_um", r_eff_um)),
            SizeDistribution::Monodisperse { radius_um } => Some(("radius_um", radius_um)),
            SizeDistribution::MarshallPalmer { .. } => None,
        };
        if let Some((key, radius)) = size.filter(|&(_, r)| r < MIN_RADIUS_UM) {
            fail!(
                keys.at("distribution"),
                "field {:?}: {key} = {} is below the smallest radius a field takes, \
                 {MIN_RADIUS_UM} µm: a smaller particle's extinction cross-section falls under \
                 the tables' 1e-30 m² (1e-6 µm water: 1.1e-36 m² at 650 nm)",
                self.name,
                grid::Shown(radius)
            );
        }
        if material == Material::Water
            && mie::refractive::water_density_kg_m3(temperature_c).is_err()
        {
            fail!(
                keys.at("temperature_c"),
                "temperature_c = {temperature_c} is outside the allowed range [-12, 99] °C for liquid water"
            );
        }
        Ok(d)
    }

    /// A crystal field's validated population: habit (default column for ice, aggregate for
    /// snow), aspect ratio, median maximum dimension in µm, its σ_g and roughness; no sphere
    /// distribution.
    fn crystal(
        &self,
        keys: &Keys,
        distribution: Option<SizeDistribution>,
    ) -> Result<mie::crystal::CrystalField, SceneError> {
        if distribution.is_some() {
            fail!(
                keys.at("distribution"),
                "field {:?} ({:?}): crystals take habit, aspect_ratio, max_dimension_um, dimension_sigma_g and roughness, not a sphere distribution",
                self.name,
                self.kind
            );
        }
        let snow = self.kind == FieldKind::Snow;
        let habit = self
            .habit
            .as_deref()
            .unwrap_or(if snow { "aggregate" } else { "column" });
        let default_ar = match habit {
            "plate" => 0.2,
            "column" => 2.0,
            "aggregate" => 1.0,
            other => fail!(
                keys.at("habit"),
                "habit = {other:?} is not one of \"plate\", \"column\", \"aggregate\""
            ),
        };
        let crystal = mie::crystal::CrystalField {
            aspect_ratio: self.aspect_ratio.unwrap_or(default_ar),
            max_dimension_um: self
                .max_dimension_um
                .unwrap_or(if snow { 2000.0 } else { 100.0 }),
            sigma_g: self.dimension_sigma_g.unwrap_or(1.5),
            roughness: self.roughness.unwrap_or(if snow { 0.7 } else { 0.0 }),
        };
        crystal.validated().map_err(|e| {
            let key = match e.to_string() {
                t if t.starts_with("aspect") => "aspect_ratio",
                t if t.starts_with("maximum") => "max_dimension_um",
                t if t.starts_with("σ_g") => "dimension_sigma_g",
                _ => "roughness",
            };
            keys.at(key)
                .error(format!("field {:?}: {key}: {e}", self.name))
        })
    }
}

/// A distribution's `kind` as a scene writes it.
fn distribution_kind(d: &SizeDistribution) -> &'static str {
    match d {
        SizeDistribution::Lognormal { .. } => "lognormal",
        SizeDistribution::Gamma { .. } => "gamma",
        SizeDistribution::MarshallPalmer { .. } => "marshall_palmer",
        SizeDistribution::Monodisperse { .. } => "monodisperse",
    }
}

/// The values a sweep has when its `count` is not given: a log sweep one value per
/// [`DEFAULT_SWEEP_RATIO`] step of the key (at least 2), a linear one 8.
pub fn default_sweep_count(spacing: Spacing, from: f64, to: f64) -> usize {
    match spacing {
        Spacing::Log => ((to / from).ln() / DEFAULT_SWEEP_RATIO.ln()).ceil() as usize + 1,
        Spacing::Linear => 8,
    }
    .max(2)
}

/// The ratio of neighbouring values of a default log sweep: the largest at which a cloud
/// sweep's interpolation error at its midpoints stays within the `standard` preset's noise of
/// Ams_1 (docs/scenes.md, "Swept fields", `docs/sweeps/interpolation.md`: median 0.60 % against 0.64 %
/// at ×1.19, 0.78 % against 0.68 % at ×1.30); rain and ice stay within theirs up to ×1.5.
pub const DEFAULT_SWEEP_RATIO: f64 = 1.2;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_scene_parses_with_all_four_kinds() {
        let s = Scene::parse(DEFAULT_SCENE, "default").unwrap();
        let kinds: Vec<FieldKind> = s.fields.iter().map(|f| f.kind).collect();
        for k in [
            FieldKind::Cloud,
            FieldKind::Rain,
            FieldKind::Ice,
            FieldKind::Snow,
        ] {
            assert!(kinds.contains(&k), "{k:?} missing");
        }
        assert_eq!(s.n_max, 26);
        assert_eq!(s.theta_step_deg, 0.18);
    }

    fn error_of(text: &str) -> String {
        Scene::parse(text, "s.toml").unwrap_err().to_string()
    }

    /// A sphere field smaller than 1 nm is refused at parse, naming its key and value (a
    /// monodisperse 1e-6 µm cloud was baked and then refused by the manifest's cross-section
    /// floor); 1 nm itself is accepted.
    #[test]
    fn particles_below_a_nanometre_are_refused_before_the_bake() {
        let field = |d: &str| {
            format!("{HEAD}[[field]]\nname = \"c\"\nkind = \"cloud\"\ndistribution = {d}\n")
        };
        for (d, needle) in [
            (
                "{ kind = \"monodisperse\", radius_um = 1e-6 }",
                "field \"c\": radius_um = 1e-6 is below the smallest radius a field takes, 0.001 µm",
            ),
            (
                "{ kind = \"gamma\", r_eff_um = 0.0005, v_eff = 0.1 }",
                "field \"c\": r_eff_um = 0.0005 is below",
            ),
            (
                "{ kind = \"lognormal\", median_radius_um = 1e-4, sigma_g = 1.5 }",
                "field \"c\": median_radius_um = 0.0001 is below",
            ),
        ] {
            let e = error_of(&field(d));
            assert!(e.contains(needle), "{d}: {e}");
        }
        assert!(
            Scene::parse(
                &field("{ kind = \"monodisperse\", radius_um = 0.001 }"),
                "s"
            )
            .is_ok()
        );
    }

    const HEAD: &str = "[scene]\nname = \"t\"\n";
    const RAIN: &str = "[[field]]\nname = \"rain\"\nkind = \"rain\"\ndistribution = { kind = \"lognormal\", median_radius_um = 500, sigma_g = 1.4 }\n";

    const CLOUD: &str = "[[field]]\nname = \"cloud\"\nkind = \"cloud\"\ndistribution = { kind = \"gamma\", r_eff_um = 10, v_eff = 0.1 }\n";

    #[test]
    fn a_swept_field_becomes_one_member_per_value() {
        let text = format!(
            "{HEAD}{CLOUD}sweep = {{ key = \"r_eff_um\", from = 4, to = 32, count = 4 }}\n{RAIN}"
        );
        let s = Scene::parse(&text, "s").unwrap();
        let names: Vec<&str> = s.fields.iter().map(|f| f.name.as_str()).collect();
        assert_eq!(
            names,
            ["cloud@00", "cloud@01", "cloud@02", "cloud@03", "rain"]
        );
        assert_eq!(s.sweeps.len(), 1);
        let sweep = &s.sweeps[0];
        assert_eq!(
            (sweep.key.as_str(), sweep.spacing),
            ("r_eff_um", Spacing::Log)
        );
        // Log spacing: 4, 8, 16, 32 (the ends exact).
        for (v, want) in sweep.values.iter().zip([4.0, 8.0, 16.0, 32.0]) {
            assert!((v - want).abs() < 1e-12 * want, "{v} vs {want}");
        }
        for (f, v) in s.fields.iter().zip(&sweep.values) {
            let Some(SizeDistribution::Gamma { r_eff_um, v_eff }) = f.distribution else {
                panic!("{f:?}");
            };
            assert_eq!((r_eff_um, v_eff), (*v, 0.1));
        }
        // Linear, crystals, and the default count (one value per ×1.2 step).
        let ice = "[[field]]\nname = \"ice\"\nkind = \"ice\"\nsweep = { key = \"roughness\", from = 0, to = 0.6, count = 3, spacing = \"linear\" }\n";
        let s = Scene::parse(&format!("{HEAD}{ice}"), "s").unwrap();
        let r: Vec<f64> = s
            .fields
            .iter()
            .map(|f| f.crystal.unwrap().roughness)
            .collect();
        assert_eq!(r, [0.0, 0.3, 0.6]);
        let text = format!("{HEAD}{CLOUD}sweep = {{ key = \"r_eff_um\", from = 4, to = 32 }}\n");
        let s = Scene::parse(&text, "s").unwrap();
        let n = (8f64.ln() / DEFAULT_SWEEP_RATIO.ln()).ceil() as usize + 1;
        assert_eq!(s.sweeps[0].values.len(), n);
    }

    #[test]
    fn bad_sweeps_are_refused_naming_key_line_and_range() {
        let sweep = |body: &str| format!("{HEAD}{CLOUD}sweep = {{ {body} }}\n");
        for (body, needle) in [
            (
                "key = \"r_eff_um\", from = 4, to = 32, count = 0",
                "line 7: field \"cloud\": sweep count = 0 is outside the allowed range [2, 64]",
            ),
            (
                "key = \"r_eff_um\", from = 4, to = 32, count = 65",
                "count = 65 is outside the allowed range [2, 64]",
            ),
            (
                "key = \"r_eff_um\", from = 32, to = 4",
                "line 7: field \"cloud\": sweep from = 32, to = 4: from must be less than to",
            ),
            (
                "key = \"v_eff\", from = 0.1, to = 0.3",
                "line 7: field \"cloud\": sweep key = \"v_eff\" cannot sweep a gamma distribution",
            ),
            (
                "key = \"median_radius_um\", from = 4, to = 32",
                "cannot sweep a gamma distribution",
            ),
            (
                "key = \"r_eff_um\", from = 0, to = 32, spacing = \"linear\"",
                "line 7: field \"cloud\": sweep of r_eff_um at r_eff_um = 0: field \"cloud\": \
                 distribution:",
            ),
            (
                "key = \"r_eff_um\", from = 0, to = 32",
                "a log sweep needs from > 0",
            ),
            ("key = \"r_eff_um\", from = 4, to = 32, step = 2", "line 7"),
            // Values that round to one another: refused before any member is baked.
            (
                "key = \"r_eff_um\", from = 10, to = 10.000000000000004, count = 64",
                "line 7: field \"cloud\": sweep from = 10, to = 10.000000000000004, count = 64: \
                 values 0 and 1 (10 and 10.000000000000002) have the same logarithm (a log sweep \
                 this narrow cannot hold 64 distinct values)",
            ),
            (
                "key = \"r_eff_um\", from = 1, to = 1.000000000000001, count = 9, \
                 spacing = \"linear\"",
                "values 1 and 2 are both 1.0000000000000002 (a linear sweep this narrow cannot hold 9",
            ),
            (
                "key = \"r_eff_um\", from = 1e-6, to = 1.000000000000001e-6, count = 2",
                "values 0 and 1 (1e-6 and 1.000000000000001e-6) have the same logarithm",
            ),
            // Numbers far from 1 in exponent form, not hundreds of digits.
            (
                "key = \"r_eff_um\", from = 1e-300, to = 1e-301",
                "sweep from = 1e-300, to = 1e-301: from must be less than to",
            ),
        ] {
            let e = error_of(&sweep(body));
            assert!(e.contains(needle), "{body}: {e}");
        }
        // A later field of a swept field's name.
        let e = error_of(&format!(
            "{HEAD}{CLOUD}sweep = {{ key = \"r_eff_um\", from = 4, to = 32 }}\n{}",
            RAIN.replace("\"rain\"\nkind", "\"cloud\"\nkind")
        ));
        assert!(e.contains("line 9") && e.contains("used twice"), "{e}");
    }

    #[test]
    fn malformed_scenes_name_the_key_and_line() {
        let e = error_of(&format!("{HEAD}colour = 3\n{RAIN}"));
        assert!(e.contains("line 3") && e.contains("colour"), "{e}");
        let e = error_of(&format!(
            "{HEAD}{}",
            RAIN.replace("median_radius_um = 500", "median_radius_um = -5")
        ));
        assert!(
            e.contains("line 6") && e.contains("-5") && e.contains("(0, ∞)"),
            "{e}"
        );
        let e = error_of(&format!("{HEAD}n_max = 0\n{RAIN}"));
        assert!(e.contains("line 3") && e.contains("n_max = 0"), "{e}");
        let e = error_of(&format!("{HEAD}theta_step_deg = 0.7\n{RAIN}"));
        assert!(
            e.contains("line 3") && e.contains("theta_step_deg = 0.7"),
            "{e}"
        );
    }

    #[test]
    fn names_and_temperatures_out_of_range_are_refused_before_any_work() {
        // A field name too long for a file name, a scene name with a terminal escape, ice at
        // NaN and at 1000 °C: each named with its line.
        let long = "n".repeat(300);
        let e = error_of(&format!(
            "{HEAD}{}",
            RAIN.replace("name = \"rain\"", &format!("name = \"{long}\""))
        ));
        assert!(e.contains("line 4") && e.contains("1 to 200"), "{e}");
        let e = error_of(&format!("[scene]\nname = \"a\\u001b[2Jb\"\n{RAIN}"));
        assert!(
            e.contains("line 2") && e.contains("control characters"),
            "{e}"
        );
        let ice = "[[field]]\nname = \"ice\"\nkind = \"ice\"\ntemperature_c = T\n";
        for t in ["nan", "1000", "-101"] {
            let e = error_of(&format!("{HEAD}{}", ice.replace('T', t)));
            assert!(e.contains("line 6") && e.contains("[-100, 0]"), "{t}: {e}");
        }
        assert!(Scene::parse(&format!("{HEAD}{}", ice.replace('T', "-40")), "s").is_ok());
        // Tables too large for memory: 10000 orders at 0.01° (1.8e8 values per channel).
        let e = error_of(&format!(
            "{HEAD}n_max = 10000\ntheta_step_deg = 0.01\n{RAIN}"
        ));
        assert!(
            e.contains("line 3") && e.contains("texels per channel exceeds"),
            "{e}"
        );
        assert!(Scene::parse(&format!("{HEAD}n_max = 500\n{RAIN}"), "s").is_ok());
        assert!(Scene::parse(&format!("{HEAD}theta_step_deg = 0.01\n{RAIN}"), "s").is_ok());
    }

    #[test]
    fn haze_is_aerosol_spheres_with_a_default_size_and_an_optional_index() {
        let haze = "[[field]]\nname = \"haze\"\nkind = \"haze\"\n";
        let s = Scene::parse(&format!("{HEAD}{haze}"), "s").unwrap();
        let f = &s.fields[0];
        assert_eq!(f.kind, FieldKind::Haze);
        assert_eq!(f.material, Material::Water);
        assert_eq!(
            f.distribution,
            Some(SizeDistribution::Lognormal {
                median_radius_um: 0.1,
                sigma_g: 2.0
            })
        );
        assert_eq!(f.refractive_index, None);
        let given = format!("{HEAD}{haze}refractive_index = [1.53, 0.008]\n");
        let f = Scene::parse(&given, "s").unwrap().fields[0].clone();
        assert_eq!(
            f.refractive_index(550.0).unwrap(),
            num_complex::Complex64::new(1.53, 0.008)
        );
        // Refused, naming the key, its value, the range and the line.
        for (extra, needle) in [
            (
                "distribution = { kind = \"lognormal\", median_radius_um = 5, sigma_g = 1.5 }\n",
                "line 6: field \"haze\" (haze): median_radius_um = 5 is outside the allowed range [0.05, 1] µm",
            ),
            (
                "distribution = { kind = \"gamma\", r_eff_um = 0.3, v_eff = 0.1 }\n",
                "line 6: field \"haze\" (haze): distribution must be lognormal",
            ),
            (
                "refractive_index = [0.9, 0]\n",
                "line 6: refractive_index = [0.9, 0]: n = 0.9 is outside the allowed range (1, 3]",
            ),
            (
                "refractive_index = [1.5, -1]\n",
                "line 6: refractive_index = [1.5, -1]: κ = -1 is outside the allowed range [0, 10]",
            ),
        ] {
            let e = error_of(&format!("{HEAD}{haze}{extra}"));
            assert!(e.contains(needle), "{extra}: {e}");
        }
        let ice = "[[field]]\nname = \"ice\"\nkind = \"ice\"\nrefractive_index = [1.31, 0]\n";
        let e = error_of(&format!("{HEAD}{ice}"));
        assert!(e.contains("refractive_index is for spheres"), "{e}");
    }

    #[test]
    fn an_hg_field_takes_its_lobe_and_refuses_what_is_not_one() {
        // HEAD is two lines, the field's [[field]] line 3, name 4, kind 5, then the keys.
        let hg = "[[field]]\nname = \"lobe\"\nkind = \"hg\"\n";
        let one = format!("{HEAD}{hg}g = 0.8\nextinction_m2 = 1e-12\n");
        let f = Scene::parse(&one, "s").unwrap().fields[0].clone();
        assert_eq!(f.kind, FieldKind::Hg);
        let h = f.hg.unwrap();
        assert_eq!(h.lobes, [mie::hg::HgLobe::one(0.8); 3]);
        assert_eq!(h.extinction_m2, [1e-12; 3]);
        assert_eq!((f.distribution, f.crystal), (None, None));
        let two = format!("{HEAD}{hg}g = 0.9\ng2 = -0.2\nweight = 0.7\nextinction_m2 = 1\n");
        let h = Scene::parse(&two, "s").unwrap().fields[0].hg.unwrap();
        let l = h.lobes[2];
        assert_eq!((l.g, l.g2, l.weight), (0.9, -0.2, 0.7));
        // One value per channel with rgb3; refused with the spectral default, and out of range
        // naming the channel.
        let rgb3 = "[scene]\nname = \"t\"\nspectral = \"rgb3\"\n";
        let per = "g = [0.8, 0.85, 0.9]\nextinction_m2 = [1e-12, 2e-12, 3e-12]\n";
        let h = Scene::parse(&format!("{rgb3}{hg}{per}"), "s")
            .unwrap()
            .fields[0]
            .hg
            .unwrap();
        assert_eq!(h.lobes.map(|l| l.g), [0.8, 0.85, 0.9]);
        assert_eq!(h.extinction_m2, [1e-12, 2e-12, 3e-12]);
        let e = error_of(&format!("{HEAD}{hg}{per}"));
        assert!(
            e.contains(
                "line 6: g = [0.8, 0.85, 0.9]: one value per channel needs spectral = \"rgb3\""
            ),
            "{e}"
        );
        let e = error_of(&format!(
            "{rgb3}{hg}g = [0.8, 1.2, 0.9]\nextinction_m2 = 1\n"
        ));
        assert!(
            e.contains(
                "line 7: g = [0.8, 1.2, 0.9]: the G value 1.2 is outside the allowed range (−1, 1)"
            ),
            "{e}"
        );
        for (extra, needle) in [
            (
                "extinction_m2 = 1e-12\n",
                "line 5: field \"lobe\" (hg): g, the lobe's asymmetry parameter in (−1, 1), is missing",
            ),
            ("g = 0.5\n", "line 5: field \"lobe\" (hg): extinction_m2"),
            (
                "g = 1\nextinction_m2 = 1e-12\n",
                "line 6: g = 1 is outside the allowed range (−1, 1)",
            ),
            (
                "g = 0.5\ng2 = 0.2\nextinction_m2 = 1e-12\n",
                "line 7: field \"lobe\" (hg): g2 needs weight",
            ),
            (
                "g = 0.5\ng2 = 0.2\nweight = 1.5\nextinction_m2 = 1e-12\n",
                "line 8: weight = 1.5 is outside the allowed range (0, 1)",
            ),
            (
                "g = 0.5\nextinction_m2 = 2\n",
                "line 7: extinction_m2 = 2 is outside the allowed range [1e-30, 1] m²",
            ),
            (
                "g = 0.5\nextinction_m2 = 1e-12\ndistribution = { kind = \"gamma\", r_eff_um = 10, v_eff = 0.1 }\n",
                "line 8: field \"lobe\" (hg): distribution is a key of particles",
            ),
            (
                "g = 0.5\nextinction_m2 = 1e-12\ntemperature_c = 5\n",
                "line 8: field \"lobe\" (hg): temperature_c is a key of particles",
            ),
        ] {
            let e = error_of(&format!("{HEAD}{hg}{extra}"));
            assert!(e.contains(needle), "{extra}: {e}");
        }
        let e = error_of(&format!("{HEAD}{CLOUD}g = 0.8\n"));
        assert!(
            e.contains("line 7: field \"cloud\" (cloud): g is a key of kind = \"hg\" fields"),
            "{e}"
        );
    }

    /// A tabulated field reads its file beside the scene, with one column or one per
    /// channel, and refuses a missing key, a file it cannot read, a column count that fits no
    /// wavelength list and a bad value, naming the scene's line, the file and its line.
    #[test]
    fn a_tabulated_field_reads_its_table_and_refuses_what_is_not_one() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("p.csv"), "theta,p\n0,2\n90,1\n180,1\n").unwrap();
        std::fs::write(dir.path().join("rgb.csv"), "0,2,3,4\n180,1,1,1\n").unwrap();
        std::fs::write(dir.path().join("neg.csv"), "0,1\n90,-1\n180,1\n").unwrap();
        let parse = |text: &str| Scene::parse_in(text, "s.toml", Some(dir.path()));
        let table = "[[field]]\nname = \"t\"\nkind = \"tabulated\"\n";
        let f = parse(&format!(
            "{HEAD}{table}file = \"p.csv\"\nextinction_m2 = 1e-12\n"
        ))
        .unwrap()
        .fields
        .remove(0);
        let t = f.tabulated.unwrap();
        assert_eq!((t.file.as_str(), t.theta_deg.len()), ("p.csv", 3));
        assert_eq!(t.columns, [vec![2.0, 1.0, 1.0]]);
        let rgb3 = "[scene]\nname = \"t\"\nspectral = \"rgb3\"\n";
        let three = format!("{table}file = \"rgb.csv\"\nextinction_m2 = 1\n");
        assert_eq!(
            parse(&format!("{rgb3}{three}")).unwrap().fields[0]
                .tabulated
                .as_ref()
                .unwrap()
                .columns
                .len(),
            3
        );
        let error = |text: String| parse(&text).unwrap_err().to_string();
        for (text, needle) in [
            (
                format!("{HEAD}{three}"),
                "line 6: field \"t\" (tabulated): file rgb.csv has 3 columns of p after θ; give \
                 one (every wavelength) or one per wavelength of the scene (31)",
            ),
            (
                format!("{HEAD}{table}file = \"neg.csv\"\nextinction_m2 = 1\n"),
                "line 6: field \"t\" (tabulated): file neg.csv line 2: p = -1",
            ),
            (
                format!("{HEAD}{table}file = \"none.csv\"\nextinction_m2 = 1\n"),
                "line 6: field \"t\" (tabulated): file none.csv: cannot be read",
            ),
            (
                format!("{HEAD}{table}extinction_m2 = 1\n"),
                "line 5: field \"t\" (tabulated): file, the table of p(θ)",
            ),
            (
                format!("{HEAD}{table}file = \"p.csv\"\n"),
                "line 5: field \"t\" (tabulated): extinction_m2",
            ),
            (
                format!("{HEAD}{table}file = \"p.csv\"\nextinction_m2 = 1\ng = 0.5\n"),
                "line 8: field \"t\" (tabulated): g is a key of kind = \"hg\" fields",
            ),
            (
                format!("{HEAD}{CLOUD}file = \"p.csv\"\n"),
                "line 7: field \"cloud\" (cloud): file is a key of kind = \"tabulated\" fields",
            ),
        ] {
            let e = error(text.clone());
            assert!(e.contains(needle), "{text}: {e}");
        }
    }

    /// A given albedo is one value or one per channel (rgb3 only), each in (0, 1].
    #[test]
    fn a_given_albedo_is_one_value_or_one_per_channel() {
        let f = Scene::parse(&format!("{HEAD}{CLOUD}albedo = 0.9\n"), "s").unwrap();
        assert_eq!(f.fields[0].albedo, Some([0.9; 3]));
        let rgb3 = "[scene]\nname = \"t\"\nspectral = \"rgb3\"\n";
        let f = Scene::parse(&format!("{rgb3}{CLOUD}albedo = [0.9, 0.95, 1]\n"), "s").unwrap();
        assert_eq!(f.fields[0].albedo, Some([0.9, 0.95, 1.0]));
        for (text, needle) in [
            (
                format!("{HEAD}{CLOUD}albedo = [0.9, 0.95, 1]\n"),
                "line 7: albedo = [0.9, 0.95, 1.0]: one value per channel needs spectral = \"rgb3\"",
            ),
            (
                format!("{rgb3}{CLOUD}albedo = [0.9, 0, 1]\n"),
                "line 8: albedo = [0.9, 0.0, 1.0]: the G value 0 is outside the allowed range (0, 1]",
            ),
            (
                format!("{HEAD}{CLOUD}albedo = 1.5\n"),
                "line 7: albedo = 1.5 is outside the allowed range (0, 1]",
            ),
        ] {
            let e = error_of(&text);
            assert!(e.contains(needle), "{text}: {e}");
        }
    }

    #[test]
    fn optical_depth_sets_the_number_of_orders() {
        let s = Scene::parse(&format!("{HEAD}max_optical_depth = 16\n{RAIN}"), "s").unwrap();
        assert_eq!(s.n_max, 36); // 16 + 4·4 + 4
    }
}
