//! The typed sections of a manifest: [`Channels`] (how R, G and B were formed), and per field
//! its [`FieldKind`], [`Microphysics`] (every input of the field) and [`QualityRecord`] (the
//! preset, its numbers and the sampling noise reached).
//!
//! # Byte identity
//! These sections were first written as `serde_json::Value` objects, whose keys serialize in
//! sorted order; the structs declare their fields in that order, and per-channel maps in them
//! are written `B`, `G`, `R` ([`sorted_rgb`]), so a bake's manifest keeps its bytes. The parts
//! that are the solver's own types (a size distribution, a crystal population, the preset's
//! knobs) stay JSON values here: this crate does not link the solver; `photometeor-bake` reads
//! them as its types.

use std::fmt;

use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::manifest::PerChannel;

/// What a particle field is made of.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FieldKind {
    /// Cloud droplets: spheres, water by default.
    Cloud,
    /// Raindrops: spheres, water by default.
    Rain,
    /// Ice crystals: hexagonal prisms, columns by default.
    Ice,
    /// Snow: rough ice crystals, aggregates by default.
    Snow,
    /// Haze: aerosol spheres (lognormal, 0.05–1 µm median radius), water by default or a
    /// given refractive index; its phase function makes light shafts visible.
    Haze,
    /// A given Henyey–Greenstein lobe (one or two terms) with a given extinction
    /// cross-section: what an engine's lobe renders like, beside the real particles.
    Hg,
    /// A given phase-function table (from a file) with a given extinction cross-section: a
    /// benchmark's or another code's phase function.
    Tabulated,
}

impl FieldKind {
    /// Every kind, in declaration order.
    pub const ALL: [FieldKind; 7] = [
        FieldKind::Cloud,
        FieldKind::Rain,
        FieldKind::Ice,
        FieldKind::Snow,
        FieldKind::Haze,
        FieldKind::Hg,
        FieldKind::Tabulated,
    ];

    /// The kind's name as scenes and manifests write it: `cloud`, `rain`, `ice`, `snow`,
    /// `haze`, `hg`, `tabulated`.
    pub fn name(self) -> &'static str {
        match self {
            FieldKind::Cloud => "cloud",
            FieldKind::Rain => "rain",
            FieldKind::Ice => "ice",
            FieldKind::Snow => "snow",
            FieldKind::Haze => "haze",
            FieldKind::Hg => "hg",
            FieldKind::Tabulated => "tabulated",
        }
    }

    /// A phase function given by the scene (hg, tabulated) rather than computed from particles.
    pub fn is_given(self) -> bool {
        matches!(self, FieldKind::Hg | FieldKind::Tabulated)
    }

    /// Spheres (cloud, rain, haze) rather than crystals (ice, snow).
    pub fn is_drops(self) -> bool {
        matches!(self, FieldKind::Cloud | FieldKind::Rain | FieldKind::Haze)
    }
}

impl fmt::Display for FieldKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A name that is not a [`FieldKind`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("field kind {0:?} is none of cloud, rain, ice, snow, haze, hg, tabulated")]
pub struct UnknownFieldKind(pub String);

impl std::str::FromStr for FieldKind {
    type Err = UnknownFieldKind;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        FieldKind::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| UnknownFieldKind(s.to_string()))
    }
}

/// What the particles are made of (the manifest's `microphysics.material`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Material {
    /// Liquid water.
    Water,
    /// Ice Ih.
    Ice,
}

impl Material {
    /// The temperatures (°C) at which the bake has the material's refractive index: liquid
    /// water [−12, 99] (IAPWS R9-97's range as the bake uses it), ice [−100, 0].
    pub fn temperature_range_c(self) -> (f64, f64) {
        match self {
            Material::Water => (-12.0, 99.0),
            Material::Ice => (-100.0, 0.0),
        }
    }

    /// `water` or `ice`.
    pub fn name(self) -> &'static str {
        match self {
            Material::Water => "water",
            Material::Ice => "ice",
        }
    }
}

/// How the bake sampled the spectrum (`channels.mode`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(into = "SamplingRecord", try_from = "SamplingRecord")]
pub enum SpectralSampling {
    /// Three wavelengths, one per channel.
    Rgb3,
    /// `count` wavelengths over [`min_nm`, `max_nm`] mixed by colour-matching weights.
    Spectral {
        /// The number of wavelengths.
        count: usize,
        /// The range's lower end (nm).
        min_nm: f64,
        /// The range's upper end (nm).
        max_nm: f64,
    },
}

/// [`SpectralSampling`] as JSON: `{"kind": "rgb3"}` or `{"count", "kind": "spectral",
/// "max_nm", "min_nm"}`, keys sorted.
#[derive(Serialize, Deserialize)]
struct SamplingRecord {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    count: Option<usize>,
    kind: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    max_nm: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    min_nm: Option<f64>,
}

impl From<SpectralSampling> for SamplingRecord {
    fn from(s: SpectralSampling) -> Self {
        match s {
            SpectralSampling::Rgb3 => SamplingRecord {
                count: None,
                kind: "rgb3".into(),
                max_nm: None,
                min_nm: None,
            },
            SpectralSampling::Spectral {
                count,
                min_nm,
                max_nm,
            } => SamplingRecord {
                count: Some(count),
                kind: "spectral".into(),
                max_nm: Some(max_nm),
                min_nm: Some(min_nm),
            },
        }
    }
}

impl TryFrom<SamplingRecord> for SpectralSampling {
    type Error = String;

    fn try_from(r: SamplingRecord) -> Result<Self, String> {
        match (r.kind.as_str(), r.count, r.min_nm, r.max_nm) {
            ("rgb3", None, None, None) => Ok(SpectralSampling::Rgb3),
            ("spectral", Some(count), Some(min_nm), Some(max_nm)) => {
                Ok(SpectralSampling::Spectral {
                    count,
                    min_nm,
                    max_nm,
                })
            }
            (kind, ..) => Err(format!(
                "channels.mode: kind {kind:?} with count {:?}, min_nm {:?}, max_nm {:?}: expected \
                 \"rgb3\" alone or \"spectral\" with all three",
                r.count, r.min_nm, r.max_nm
            )),
        }
    }
}

/// The manifest's `channels`: how the bake's wavelengths make its R, G, B channels.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Channels {
    /// The illuminant the weights assume.
    pub illuminant: String,
    /// How a channel mixes the wavelengths' phase functions.
    pub mixing: String,
    /// How the spectrum was sampled.
    pub mode: SpectralSampling,
    /// The channel names, `R`, `G`, `B`.
    pub names: Vec<String>,
    /// Per channel, the dropped negative lobe relative to the kept positive part.
    #[serde(with = "sorted_rgb")]
    pub negative_lobe_fraction: PerChannel<f64>,
    /// The colour-matching functions.
    pub observer: String,
    /// The colour space of R, G, B.
    pub space: String,
    /// The unit of the tables' values.
    pub unit: String,
    /// λ_1..λ_W (nm), in the order of the single-scattering tables' rows.
    pub wavelengths_nm: Vec<f64>,
    /// weights[c][j] ≥ 0, Σ_j weights[c][j] = 1: channel c's share of wavelength j.
    #[serde(with = "sorted_rgb")]
    pub weights: PerChannel<Vec<f64>>,
}

impl Channels {
    /// The checks of a manifest's channels: W ≥ 1 distinct positive wavelengths, W weights per
    /// channel, each ≥ 0 and summing to 1 within 10⁻⁹, names R, G, B, fractions in [0, 1].
    pub fn check(&self) -> Result<(), String> {
        let w = self.wavelengths_nm.len();
        if w == 0 {
            return Err("channels.wavelengths_nm is empty".into());
        }
        if let Some(l) = self
            .wavelengths_nm
            .iter()
            .find(|l| !(l.is_finite() && **l > 0.0))
        {
            return Err(format!(
                "channels.wavelengths_nm holds {l}, expected wavelengths > 0 nm"
            ));
        }
        if self.names != ["R", "G", "B"] {
            return Err(format!(
                "channels.names is {:?}, expected [\"R\", \"G\", \"B\"]",
                self.names
            ));
        }
        for (c, weights) in ["R", "G", "B"].iter().zip(self.weights.as_array()) {
            let sum: f64 = weights.iter().sum();
            if weights.len() != w
                || weights.iter().any(|v| !(v.is_finite() && *v >= 0.0))
                || (sum - 1.0).abs() > 1e-9
            {
                return Err(format!(
                    "channels.weights.{c} must be {w} values ≥ 0 summing to 1 (one per wavelength)"
                ));
            }
        }
        for (c, v) in ["R", "G", "B"]
            .iter()
            .zip(self.negative_lobe_fraction.as_array())
        {
            if !(v.is_finite() && (0.0..=1.0).contains(v)) {
                return Err(format!(
                    "channels.negative_lobe_fraction.{c} = {v} is outside [0, 1]"
                ));
            }
        }
        Ok(())
    }
}

/// The manifest's `microphysics` of a field: every input of the field as the scene gave it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Microphysics {
    /// The crystal population (ice, snow), as the solver's `CrystalField` serializes it.
    pub crystal: Option<Value>,
    /// The size distribution of spheres (cloud, rain, haze), as the solver's
    /// `SizeDistribution` serializes it.
    pub distribution: Option<Value>,
    /// What the field is made of.
    pub kind: FieldKind,
    /// What the particles are made of.
    pub material: Material,
    /// The field's name.
    pub name: String,
    /// A sphere field's given refractive index [n, κ], replacing the material's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub refractive_index: Option<[f64; 2]>,
    /// A given single-scattering albedo, in (0, 1], replacing the particles' own at every
    /// wavelength: one value, or one per channel.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub albedo: Option<ChannelValues>,
    /// A given lobe (`hg` fields), as the solver's `HgField` serializes it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hg: Option<Value>,
    /// A given table (`tabulated` fields), as the solver's `TabulatedField` serializes it
    /// (the file's name, its angles and columns as read, the cross-section), and
    /// `sphere_integral`: each column's integral over the sphere as read (the normalization
    /// found, divided out).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tabulated: Option<Value>,
    /// Temperature, °C.
    pub temperature_c: f64,
}

/// One value for every channel, or one per channel (R, G, B): how a scene gives a field's
/// optics and how the manifest records them.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum ChannelValues {
    /// The same value on every channel.
    One(f64),
    /// R, G, B.
    Three([f64; 3]),
}

impl ChannelValues {
    /// `One` where the three are equal, else `Three`.
    pub fn of(values: [f64; 3]) -> Self {
        if values[1] == values[0] && values[2] == values[0] {
            Self::One(values[0])
        } else {
            Self::Three(values)
        }
    }

    /// The three channels' values.
    pub fn channels(self) -> [f64; 3] {
        match self {
            Self::One(v) => [v; 3],
            Self::Three(v) => v,
        }
    }
}

impl Microphysics {
    /// The checks of a field's microphysics: the temperature within the material's range
    /// ([`Material::temperature_range_c`]), a given index with n in (1, 3] and κ in [0, 10],
    /// spheres with a distribution and crystals with a population.
    pub fn check(&self) -> Result<(), String> {
        let (lo, hi) = self.material.temperature_range_c();
        let t = self.temperature_c;
        if !(t.is_finite() && (lo..=hi).contains(&t)) {
            return Err(format!(
                "microphysics.temperature_c = {t} is outside [{lo}, {hi}] °C, the range of {}",
                self.material.name()
            ));
        }
        if let Some([n, kappa]) = self.refractive_index
            && !(n > 1.0 && n <= 3.0 && (0.0..=10.0).contains(&kappa))
        {
            return Err(format!(
                "microphysics.refractive_index = [{n}, {kappa}], expected n in (1, 3] and κ in [0, 10]"
            ));
        }
        if let Some(a) = self.albedo
            && let Some(v) = a.channels().into_iter().find(|a| !(*a > 0.0 && *a <= 1.0))
        {
            return Err(format!(
                "microphysics.albedo = {v} is outside the allowed range (0, 1]"
            ));
        }
        // What each kind holds (a distribution, a crystal, a lobe), and says it lacks.
        let (wanted, expected) = match self.kind {
            FieldKind::Hg => (
                (false, false, true, false),
                "a lobe (hg) and no distribution, crystal or table",
            ),
            FieldKind::Tabulated => (
                (false, false, false, true),
                "a table (tabulated) and no distribution, crystal or lobe",
            ),
            k if k.is_drops() => (
                (true, false, false, false),
                "a distribution and no crystal, lobe or table",
            ),
            _ => (
                (false, true, false, false),
                "a crystal and no distribution, lobe or table",
            ),
        };
        let held = (
            self.distribution.is_some(),
            self.crystal.is_some(),
            self.hg.is_some(),
            self.tabulated.is_some(),
        );
        if held == wanted {
            Ok(())
        } else {
            Err(format!(
                "microphysics of a {} field: expected {expected}",
                self.kind
            ))
        }
    }
}

/// The manifest's `quality` of a field: the preset and the numbers it set, and the sampling
/// noise of Ams_1 per channel that the bake reached.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct QualityRecord {
    /// Crystal fields: the rms relative standard error of Ams_1 over θ ≥ 1° the trace reached.
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        with = "sorted_rgb_option"
    )]
    pub crystal_noise: Option<PerChannel<f64>>,
    /// Crystal fields: the rays that hit a crystal over all wavelengths.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub crystal_rays: Option<u64>,
    /// The numbers the preset set (`photometeor-bake`'s `Knobs`).
    pub knobs: Value,
    /// The Legendre degree at which the series stops.
    pub legendre_l_max: usize,
    /// The preset: `draft`, `standard` or `reference`.
    pub preset: String,
    /// Drop fields: the same noise from the finite set of sizes.
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        with = "sorted_rgb_option"
    )]
    pub size_noise: Option<PerChannel<f64>>,
    /// Drop fields: the mean number of sizes per wavelength.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sizes: Option<usize>,
}

impl QualityRecord {
    /// The checks of a field's quality record: a known preset, noise in [0, 1] per channel.
    pub fn check(&self) -> Result<(), String> {
        if !["draft", "standard", "reference"].contains(&self.preset.as_str()) {
            return Err(format!(
                "quality.preset {:?} is none of draft, standard, reference",
                self.preset
            ));
        }
        for (key, noise) in [
            ("crystal_noise", &self.crystal_noise),
            ("size_noise", &self.size_noise),
        ] {
            if let Some(noise) = noise
                && let Some((c, v)) = ["R", "G", "B"]
                    .iter()
                    .zip(noise.as_array())
                    .find(|(_, v)| !(v.is_finite() && (0.0..=1.0).contains(*v)))
            {
                return Err(format!("quality.{key}.{c} = {v} is outside [0, 1]"));
            }
        }
        Ok(())
    }

    /// The sampling behind the tables, in words: the rays traced or the sizes per wavelength.
    pub fn sampling(&self) -> Option<String> {
        match (self.crystal_rays, self.sizes) {
            (Some(rays), _) => Some(format!("{rays:.2e} rays traced")),
            (None, Some(sizes)) => Some(format!("{sizes} sizes per wavelength")),
            (None, None) => self
                .knobs
                .get("sizes")
                .and_then(Value::as_u64)
                .map(|n| format!("{n} sizes per wavelength")),
        }
    }

    /// The sampling noise of Ams_1 per channel, crystals' or drops'.
    pub fn noise(&self) -> Option<&PerChannel<f64>> {
        self.crystal_noise.as_ref().or(self.size_noise.as_ref())
    }
}

/// A [`PerChannel`] written as `{"B", "G", "R"}`: the key order of the sorted JSON objects
/// these sections were first written as (module docs); read in any order.
pub mod sorted_rgb {
    use serde::ser::SerializeMap;
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    use crate::manifest::PerChannel;

    /// Writes `B`, `G`, `R`.
    pub fn serialize<T: Serialize, S: Serializer>(
        v: &PerChannel<T>,
        s: S,
    ) -> Result<S::Ok, S::Error> {
        let mut map = s.serialize_map(Some(3))?;
        map.serialize_entry("B", &v.b)?;
        map.serialize_entry("G", &v.g)?;
        map.serialize_entry("R", &v.r)?;
        map.end()
    }

    /// Reads `R`, `G`, `B` in any order.
    pub fn deserialize<'de, T: Deserialize<'de>, D: Deserializer<'de>>(
        d: D,
    ) -> Result<PerChannel<T>, D::Error> {
        PerChannel::deserialize(d)
    }
}

/// [`sorted_rgb`] of an optional value.
pub mod sorted_rgb_option {
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    use crate::manifest::PerChannel;

    /// Writes `B`, `G`, `R`, or `null`.
    pub fn serialize<T: Serialize, S: Serializer>(
        v: &Option<PerChannel<T>>,
        s: S,
    ) -> Result<S::Ok, S::Error> {
        match v {
            Some(v) => super::sorted_rgb::serialize(v, s),
            None => s.serialize_none(),
        }
    }

    /// Reads `R`, `G`, `B` in any order, or `null`.
    pub fn deserialize<'de, T: Deserialize<'de>, D: Deserializer<'de>>(
        d: D,
    ) -> Result<Option<PerChannel<T>>, D::Error> {
        Option::<PerChannel<T>>::deserialize(d)
    }
}
