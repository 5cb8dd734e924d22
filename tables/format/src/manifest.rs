//! `DIR/manifest.json`: what a bake produced, for renderers and for `photometeor inspect`.
//!
//! [`Manifest`] lists the grid, the channel definitions and one [`FieldEntry`] per field, in
//! the scene's order; the numbers a renderer needs besides the textures (F_i, g, σ_ext, albedo,
//! n_iso) and every input that produced them. [`write_manifest`] writes it atomically as pretty
//! JSON; [`read_manifest`] refuses a directory with a pending commit ([`crate::commit`]), then
//! checks the schema version before anything else. [`BakeDir`] reads a field's EXR and checks
//! it against its entry: size and CRC-32, field name, Δθ, K, N and F_i.
//!
//! # Determinism
//! Fields are a `Vec` (scene order) and maps are `BTreeMap`s or fixed structs, so the same
//! manifest serializes to the same bytes. `serde_json` writes every finite `f64` as its
//! shortest round-trip decimal; non-finite numbers (which JSON cannot hold) are refused by
//! [`Manifest::check`] before writing.
//!
//! # Example (abridged)
//! ```json
//! {
//!   "schema": 2,
//!   "tool": "photometeor",
//!   "tool_version": "0.1.0",
//!   "theta_step_deg": 0.18,
//!   "angle_count": 1001,
//!   "channels": { "mode": "spectral", "...": "..." },
//!   "fields": [
//!     {
//!       "name": "rain", "file": "rain.exr", "bytes": 266881, "crc32": "1c0ffee5",
//!       "kind": "rain", "n_max": 26,
//!       "forward_fraction": { "R": [0.97, "..."], "G": ["..."], "B": ["..."] },
//!       "forward_peak_fraction": { "R": ["..."], "G": ["..."], "B": ["..."] },
//!       "g": { "R": 0.87, "G": 0.88, "B": 0.88 },
//!       "sigma_ext_m2": { "R": 1.6e-6, "G": "...", "B": "..." },
//!       "albedo": { "R": 1.0, "G": 1.0, "B": 1.0 },
//!       "n_isotropic": { "R": { "1e-2": 9, "1e-4": 17, "1e-6": null }, "G": {}, "B": {} },
//!       "microphysics": { "...": "..." },
//!       "quality": { "...": "..." },
//!       "content_hash": "3f2a…"
//!     }
//!   ]
//! }
//! ```

use std::collections::BTreeMap;
use std::io;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use serde_json::Value;
use thiserror::Error;

use crate::atomic::{read_regular_file, write_file_atomically};
use crate::sections::{Channels, FieldKind, Microphysics, QualityRecord};
use crate::side::SideTable;

/// The manifest's layout version; [`read_manifest`] rejects any other.
pub const MANIFEST_SCHEMA_VERSION: u32 = 2;

/// The manifest's file name inside the bake directory.
pub const MANIFEST_FILE: &str = "manifest.json";

/// The ε keys of [`FieldEntry::n_isotropic`], largest first.
pub const N_ISOTROPIC_EPSILONS: [&str; 3] = ["1e-2", "1e-4", "1e-6"];

/// One value per colour channel, serialized as `{"R": …, "G": …, "B": …}`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct PerChannel<T> {
    /// Red.
    #[serde(rename = "R")]
    pub r: T,
    /// Green.
    #[serde(rename = "G")]
    pub g: T,
    /// Blue.
    #[serde(rename = "B")]
    pub b: T,
}

impl<T> PerChannel<T> {
    /// The three values in the order R, G, B.
    pub fn as_array(&self) -> [&T; 3] {
        [&self.r, &self.g, &self.b]
    }

    /// Builds from `[R, G, B]`.
    pub fn from_array([r, g, b]: [T; 3]) -> Self {
        Self { r, g, b }
    }
}

/// The whole `manifest.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// [`MANIFEST_SCHEMA_VERSION`].
    pub schema: u32,
    /// The producing tool, `"photometeor"`.
    pub tool: String,
    /// Its version (`CARGO_PKG_VERSION` of the binary).
    pub tool_version: String,
    /// Δθ in degrees.
    pub theta_step_deg: f64,
    /// K = 180°/Δθ + 1, the width of every EXR.
    pub angle_count: usize,
    /// How R, G and B were formed (spectral mode, wavelengths, weights).
    pub channels: Channels,
    /// One entry per field, in the scene's order (a swept field's members among them).
    pub fields: Vec<FieldEntry>,
    /// The swept fields: each a key over increasing values, one member field per value;
    /// absent when the bake has none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub sweeps: Vec<SweepEntry>,
}

/// A field swept over one microphysical key (the sweep axis): the member fields in
/// [`Manifest::fields`] hold its values, in order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SweepEntry {
    /// The swept field's name in the scene (volumes name it); no field has this name.
    pub name: String,
    /// The swept key, in the scene's words (e.g. `r_eff_um`).
    pub key: String,
    /// How the values were spaced: `"log"` or `"linear"`.
    pub spacing: String,
    /// The values, strictly increasing, in the key's unit.
    pub values: Vec<f64>,
    /// The member fields' names, one per value (`<name>@<k>`).
    pub fields: Vec<String>,
}

impl SweepEntry {
    /// The coordinate the members are equally spaced in: ln value for a log sweep, the value
    /// for a linear one (what the shaders' `ams_sweep` takes as `at_value`).
    pub fn at(&self, value: f64) -> f64 {
        if self.spacing == "log" {
            value.ln()
        } else {
            value
        }
    }

    /// The members on either side of `value` and their shares of the number density, given
    /// each member's extinction cross-section `sigma_ext` (m², one channel): with t linear in
    /// ln value (log spacing) or in value (linear) between the members' values, clamped to the
    /// ends, `[(k, (1 − t)·σ/σ_k), (k + 1, t·σ/σ_k+1)]` with σ = σ_k^(1−t)·σ_k+1^t. A renderer
    /// mixing the two members with these shares (as it mixes any two fields in one place,
    /// Riley et al. 2004 Eq. 6, weight ∝ share × σ_sca) then has the extinction σ, exact where
    /// σ_ext follows a power of the value (∝ r² for large drops), and the phase functions
    /// weighted 1 − t and t (for albedo 1; nearly so for clouds).
    pub fn shares(&self, value: f64, sigma_ext: &[f64]) -> [(usize, f64); 2] {
        let v = &self.values;
        let last = v.len() - 1;
        let value = if value.is_nan() {
            v[0]
        } else {
            value.clamp(v[0], v[last])
        };
        let k = v.partition_point(|&x| x <= value).clamp(1, last) - 1;
        let t = ((self.at(value) - self.at(v[k])) / (self.at(v[k + 1]) - self.at(v[k])))
            .clamp(0.0, 1.0);
        // Two members whose coordinates round to one value (a sweep narrower than the
        // logarithm's resolution) give 0/0: take the lower one.
        let t = if t.is_nan() { 0.0 } else { t };
        let (s0, s1) = (sigma_ext[k], sigma_ext[k + 1]);
        let sigma = s0.powf(1.0 - t) * s1.powf(t);
        [(k, (1.0 - t) * sigma / s0), (k + 1, t * sigma / s1)]
    }

    /// Its members are fields of the manifest, one per value, of one kind; the values are
    /// finite and strictly increasing; the name is no field's and no earlier sweep's.
    fn check(&self, fields: &[FieldEntry], earlier: &[SweepEntry]) -> Result<(), String> {
        let at = |what: String| format!("sweep {:?}: {what}", self.name);
        if earlier.iter().any(|s| s.name == self.name) || fields.iter().any(|f| f.name == self.name)
        {
            return Err(at("name given twice".into()));
        }
        if self.values.len() < 2 || self.values.len() != self.fields.len() {
            return Err(at(format!(
                "{} values and {} fields: a sweep has at least 2 values, one field each",
                self.values.len(),
                self.fields.len()
            )));
        }
        if !(self.values.iter().all(|v| v.is_finite())
            && self.values.windows(2).all(|w| w[0] < w[1]))
        {
            return Err(at(format!(
                "values {:?} are not finite and strictly increasing",
                self.values
            )));
        }
        if !matches!(self.spacing.as_str(), "log" | "linear") {
            return Err(at(format!(
                "spacing {:?} is not log or linear",
                self.spacing
            )));
        }
        let mut kind = None;
        for name in &self.fields {
            let Some(f) = fields.iter().find(|f| &f.name == name) else {
                return Err(at(format!("member {name:?} is not a field of the bake")));
            };
            if kind.is_some_and(|k| k != f.kind) {
                return Err(at(format!("member {name:?} is of another kind")));
            }
            kind = Some(f.kind);
        }
        Ok(())
    }
}

/// The manifest entry of one particle field.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FieldEntry {
    /// The field's name in the scene (also `photometeor/field` in its EXR).
    pub name: String,
    /// Its EXR, relative to the bake directory: always `<name>.exr`.
    pub file: String,
    /// The EXR's size in bytes; readers refuse a file of another size.
    pub bytes: u64,
    /// CRC-32 (IEEE) of the EXR's bytes, 8 lowercase hex digits; readers refuse a file that
    /// does not match (a file of another generation, a corrupted copy).
    pub crc32: String,
    /// What the field is made of.
    pub kind: FieldKind,
    /// N, the number of rows Ams_1..Ams_N.
    pub n_max: usize,
    /// F_1..F_N per channel (Riley et al. 2004 Eq. 23).
    pub forward_fraction: PerChannel<Vec<f64>>,
    /// Per channel and row: the fraction of the row's energy in the unresolved forward peak
    /// kept inside bin 0.
    pub forward_peak_fraction: PerChannel<Vec<f64>>,
    /// Asymmetry parameter g = ⟨cos θ⟩ per channel.
    pub g: PerChannel<f64>,
    /// Extinction cross-section per particle, m², per channel.
    pub sigma_ext_m2: PerChannel<f64>,
    /// Single-scattering albedo per channel.
    pub albedo: PerChannel<f64>,
    /// Per channel: ε (`"1e-2"`, `"1e-4"`, `"1e-6"`) → the smallest n with
    /// max_k |4π Ams_n(θ_k) − 1| < ε, or `null` when no n ≤ N reaches it.
    pub n_isotropic: PerChannel<BTreeMap<String, Option<u32>>>,
    /// Every microphysics input of the field, as the scene gave it.
    pub microphysics: Microphysics,
    /// Every quality input (preset and the numbers it set) and the sampling noise of Ams_1 per
    /// channel: for crystal fields the rays traced (`crystal_rays`) and the noise they reached
    /// (`crystal_noise`), for drops the size sampling's (`size_noise`).
    pub quality: QualityRecord,
    /// Hash of every input that affects the field's result, lowercase hex.
    pub content_hash: String,
    /// The field's single-scattering optics per wavelength (`crate::single`), for spectral
    /// path tracing; absent in bakes written before it existed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub single_scattering: Option<FileRef>,
    /// The field's Poisson mixtures M(D, θ) (`crate::poisson`), for the `max` model; absent in
    /// bakes written before it existed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub poisson: Option<FileRef>,
    /// σ_tr/σ_t = 1 − α g per channel: the transport cross-section of the diffusion equation
    /// over the extinction cross-section (Max et al. 2004 §2); absent in older bakes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub transport_factor: Option<PerChannel<f64>>,
    /// The point-light kernel of the field's Ams_1 (`crate::biri`), for the `biri` model;
    /// absent in bakes written before it existed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub biri_kernel: Option<FileRef>,
}

/// A further file of a field: its name in the bake directory, size and CRC-32.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FileRef {
    /// Relative to the bake directory: `<name>.single.exr`.
    pub file: String,
    /// Size in bytes.
    pub bytes: u64,
    /// CRC-32 (IEEE) of the bytes, 8 lowercase hex digits.
    pub crc32: String,
}

/// A failed consistency check of a [`Manifest`] (see [`Manifest::check`]).
#[derive(Debug, Clone, PartialEq, Error)]
#[error("{what}")]
pub struct ManifestCheck {
    /// What was checked and what was found.
    pub what: String,
}

impl From<String> for ManifestCheck {
    fn from(what: String) -> Self {
        Self { what }
    }
}

/// The largest manifest a reader accepts (bytes); a bake of 1000 fields stays far below.
pub const MAX_MANIFEST_BYTES: u64 = 64 << 20;

/// The largest N a manifest may list, as a scene allows it.
pub const MAX_N: usize = 10_000;

/// The extinction cross-sections per particle a manifest may hold (m²): above a nanometre
/// sphere's (Rayleigh, ~10⁻²⁹ m² at 400 nm) and below a one-metre square (a hailstone of
/// 10 cm radius has 2πr² ≈ 0.06 m²); anything outside is a corrupt value, not a particle.
pub const SIGMA_EXT_RANGE_M2: (f64, f64) = (1e-30, 1.0);

/// What went wrong writing or reading a manifest. Every variant names the file.
#[derive(Debug, Error)]
pub enum ManifestError {
    /// The operating system refused a read or write.
    #[error("{}: {op}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// What was being done.
        op: &'static str,
        /// The underlying error.
        source: io::Error,
    },
    /// Not valid JSON, or not the manifest's structure (the message has the key, line and
    /// column).
    #[error("{}: {}{error}", path.display(), key.as_ref().map_or(String::new(), |k| format!("{k}: ")))]
    Json {
        /// The file.
        path: PathBuf,
        /// Where in the manifest the value is (`fields.1.microphysics.temperature_c`), when the
        /// JSON is valid but a value has the wrong type.
        key: Option<String>,
        /// The parser's error, with line and column.
        error: serde_json::Error,
    },
    /// A schema version this reader does not know.
    #[error("{}: schema {found}, expected {expected}", path.display())]
    Schema {
        /// The file.
        path: PathBuf,
        /// What the file says (`missing` if absent).
        found: String,
        /// [`MANIFEST_SCHEMA_VERSION`].
        expected: u32,
    },
    /// The directory's last bake stopped while publishing its files.
    #[error(transparent)]
    Pending(#[from] crate::commit::CommitError),
    /// The manifest is well-formed JSON but inconsistent.
    #[error("{}: {what}", path.display())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// The failed check.
        what: String,
    },
}

impl Manifest {
    /// Consistency checks made on write and on read: schema, K = 180°/Δθ + 1, unique field
    /// names, plain file names, N values per channel for F_i and the peak fractions, finite
    /// numbers, known ε keys, a lowercase hex hash.
    pub fn check(&self) -> Result<(), ManifestCheck> {
        self.check_inner().map_err(ManifestCheck::from)
    }

    /// [`Manifest::check`]'s checks: the manifest's own keys, then each field in turn.
    fn check_inner(&self) -> Result<(), String> {
        self.channels.check()?;
        if self.schema != MANIFEST_SCHEMA_VERSION {
            return Err(format!(
                "schema {}, expected {MANIFEST_SCHEMA_VERSION}",
                self.schema
            ));
        }
        let grid = grid::ThetaGrid::new(self.theta_step_deg).map_err(|e| e.to_string())?;
        if self.angle_count != grid.len() {
            return Err(format!(
                "angle_count {}, expected 180°/{}° + 1 = {}",
                self.angle_count,
                self.theta_step_deg,
                grid.len()
            ));
        }
        for (i, f) in self.fields.iter().enumerate() {
            f.check(i, &self.fields[..i])?;
        }
        for (i, s) in self.sweeps.iter().enumerate() {
            s.check(&self.fields, &self.sweeps[..i])?;
        }
        Ok(())
    }

    /// The manifest as written: pretty JSON and a final newline.
    pub fn to_json_bytes(&self) -> Vec<u8> {
        let mut bytes = serde_json::to_vec_pretty(self).expect("a manifest always serializes");
        bytes.push(b'\n');
        bytes
    }
}

/// The consistency checks of one entry, in the order [`Manifest::check`] makes them; each
/// error names the field.
impl FieldEntry {
    /// Every check of the entry at index `i`; `earlier` are the entries before it.
    fn check(&self, i: usize, earlier: &[FieldEntry]) -> Result<(), String> {
        self.check_names(i, earlier)?;
        self.check_record()?;
        self.check_channel_values()?;
        self.check_forward_fractions()?;
        self.check_derived()
    }

    /// `what`, prefixed with the field's name.
    fn at(&self, what: String) -> String {
        format!("field {:?}: {what}", self.name)
    }

    /// A non-empty name no earlier entry has, a plain file-name stem (≤ 200 bytes), and the
    /// bake's own names for the EXR and the side tables.
    fn check_names(&self, i: usize, earlier: &[FieldEntry]) -> Result<(), String> {
        if self.name.is_empty() {
            return Err(format!("field {i}: empty name"));
        }
        if earlier.iter().any(|o| o.name == self.name) {
            return Err(self.at("name given twice".into()));
        }
        let plain = Path::new(&self.name)
            .file_name()
            .is_some_and(|n| n == self.name.as_str());
        if !plain || self.name.starts_with('.') || self.name.len() > 200 {
            return Err(self.at(format!(
                "name {:?} must be a plain file name stem (no path, no leading '.', at most 200 bytes)",
                self.name
            )));
        }
        if self.file != format!("{}.exr", self.name) {
            return Err(self.at(format!(
                "file {:?} is not the bake's own name for this field, expected \"{}.exr\"",
                self.file, self.name
            )));
        }
        for (key, file, own) in [
            (
                "single_scattering",
                &self.single_scattering,
                crate::single::single_file_name(&self.name),
            ),
            (
                "poisson",
                &self.poisson,
                crate::poisson::poisson_file_name(&self.name),
            ),
            (
                "biri_kernel",
                &self.biri_kernel,
                crate::biri::biri_file_name(&self.name),
            ),
        ] {
            if let Some(file) = file
                && file.file != own
            {
                return Err(self.at(format!(
                    "{key} file {:?} is not the bake's own name, expected {own:?}",
                    file.file
                )));
            }
        }
        Ok(())
    }

    /// The transport factor in [0, 2], an 8-digit lowercase CRC-32, N in [1, [`MAX_N`]], the
    /// microphysics and quality records (of this field), and file sizes within an EXR's limit
    /// (bytes).
    fn check_record(&self) -> Result<(), String> {
        if let Some(t) = &self.transport_factor
            && let Some((c, v)) = ["R", "G", "B"]
                .iter()
                .zip(t.as_array())
                .find(|(_, v)| !(v.is_finite() && (0.0..=2.0).contains(*v)))
        {
            return Err(self.at(format!(
                "transport_factor.{c} = {v}, expected 1 − α g in [0, 2]"
            )));
        }
        if self.crc32.len() != 8
            || !self
                .crc32
                .bytes()
                .all(|b| b.is_ascii_hexdigit() && !b.is_ascii_uppercase())
        {
            return Err(self.at(format!(
                "crc32 {:?} is not 8 lowercase hex digits",
                self.crc32
            )));
        }
        if !(1..=MAX_N).contains(&self.n_max) {
            return Err(self.at(format!("n_max = {}, expected 1 to {MAX_N}", self.n_max)));
        }
        if self.microphysics.name != self.name || self.microphysics.kind != self.kind {
            return Err(self.at(format!(
                "microphysics names field {:?} of kind {}, the entry {:?} of kind {}",
                self.microphysics.name, self.microphysics.kind, self.name, self.kind
            )));
        }
        self.microphysics.check().map_err(|e| self.at(e))?;
        self.quality.check().map_err(|e| self.at(e))?;
        for (key, size) in std::iter::once(("bytes", self.bytes)).chain(
            [
                ("single_scattering.bytes", &self.single_scattering),
                ("poisson.bytes", &self.poisson),
                ("biri_kernel.bytes", &self.biri_kernel),
            ]
            .into_iter()
            .filter_map(|(k, r)| r.as_ref().map(|r| (k, r.bytes))),
        ) {
            if size > crate::exr::MAX_EXR_BYTES {
                return Err(self.at(format!(
                    "{key} = {size}, more than the {} bytes a bake's EXR may have",
                    crate::exr::MAX_EXR_BYTES
                )));
            }
        }
        Ok(())
    }

    /// N finite values per channel for F_i and the peak fractions; finite g, σ_ext and
    /// albedo; albedo in [0, 1], g in [−1, 1], σ_ext in [`SIGMA_EXT_RANGE_M2`] (m²).
    fn check_channel_values(&self) -> Result<(), String> {
        for (key, per) in [
            ("forward_fraction", &self.forward_fraction),
            ("forward_peak_fraction", &self.forward_peak_fraction),
        ] {
            for (c, v) in ["R", "G", "B"].iter().zip(per.as_array()) {
                if v.len() != self.n_max {
                    return Err(self.at(format!(
                        "{key}.{c} has {} values, expected n_max = {}",
                        v.len(),
                        self.n_max
                    )));
                }
                if let Some(j) = v.iter().position(|x| !x.is_finite()) {
                    return Err(self.at(format!("{key}.{c}[{j}] = {} is not finite", v[j])));
                }
            }
        }
        for (key, per) in [
            ("g", &self.g),
            ("sigma_ext_m2", &self.sigma_ext_m2),
            ("albedo", &self.albedo),
        ] {
            for (c, v) in ["R", "G", "B"].iter().zip(per.as_array()) {
                if !v.is_finite() {
                    return Err(self.at(format!("{key}.{c} = {v} is not finite")));
                }
            }
        }
        for (c, v) in ["R", "G", "B"].iter().zip(self.albedo.as_array()) {
            if !(0.0..=1.0).contains(v) {
                return Err(self.at(format!("albedo.{c} = {v} is outside [0, 1]")));
            }
        }
        for (c, v) in ["R", "G", "B"].iter().zip(self.g.as_array()) {
            if !(-1.0..=1.0).contains(v) {
                return Err(self.at(format!("g.{c} = {v} is outside [-1, 1]")));
            }
        }
        for (c, v) in ["R", "G", "B"].iter().zip(self.sigma_ext_m2.as_array()) {
            if !(SIGMA_EXT_RANGE_M2.0..=SIGMA_EXT_RANGE_M2.1).contains(v) {
                return Err(self.at(format!(
                    "sigma_ext_m2.{c} = {v:e} is outside [{:e}, {}] m², the extinction \
                     cross-sections one particle can have",
                    SIGMA_EXT_RANGE_M2.0, SIGMA_EXT_RANGE_M2.1
                )));
            }
        }
        Ok(())
    }

    /// F_i in [0, 1] with |F_i − ½| not rising with n (the forward hemisphere's excess, or a
    /// backward-peaked field's deficit, fades toward isotropy with each scattering: F_n − ½ is
    /// a sum of the odd Legendre moments' n-th powers, docs/physics.md §7; below ½ where the
    /// phase function leans backward, as small strongly absorbing high-index spheres' do, and
    /// alternating about ½ where g < 0); the forward peak's fraction in [0, 1], within F_i and
    /// not rising with n.
    fn check_forward_fractions(&self) -> Result<(), String> {
        for (c, v) in ["R", "G", "B"].iter().zip(self.forward_fraction.as_array()) {
            if let Some(i) = v.iter().position(|x| !(0.0..=1.0).contains(x)) {
                return Err(self.at(format!(
                    "forward_fraction.{c}: F_{} = {} is outside [0, 1]",
                    i + 1,
                    v[i]
                )));
            }
            let off = |i: usize| (v[i] - 0.5).abs();
            if let Some(i) = (1..v.len()).find(|&i| off(i) > off(i - 1) + 1e-12) {
                return Err(self.at(format!(
                    "forward_fraction.{c}: F_{} = {} is further from ½ than F_{} = {}: forward \
                     fractions tend to ½ with each scattering",
                    i + 1,
                    v[i],
                    i,
                    v[i - 1]
                )));
            }
        }
        for ((c, v), ff) in ["R", "G", "B"]
            .iter()
            .zip(self.forward_peak_fraction.as_array())
            .zip(self.forward_fraction.as_array())
        {
            // The exact forward δ is part of the forward hemisphere's energy, and its
            // share of row n, Σ_j a_j f_j^n, cannot rise with n.
            if let Some(i) = v.iter().position(|x| !(0.0..=1.0).contains(x)) {
                return Err(self.at(format!(
                    "forward_peak_fraction.{c}[{i}] = {} is outside [0, 1]",
                    v[i]
                )));
            }
            if let Some(i) = (0..v.len()).find(|&i| v[i] > ff[i] + 1e-12) {
                return Err(self.at(format!(
                    "forward_peak_fraction.{c}[{i}] = {} exceeds F_{} = {}: the forward peak is part of the forward fraction",
                    v[i],
                    i + 1,
                    ff[i]
                )));
            }
            if let Some(i) = (1..v.len()).find(|&i| v[i] > v[i - 1] + 1e-12) {
                return Err(self.at(format!(
                    "forward_peak_fraction.{c}[{i}] = {} exceeds [{}] = {}: the forward peak's share cannot rise with n",
                    v[i],
                    i - 1,
                    v[i - 1]
                )));
            }
        }
        Ok(())
    }

    /// The transport factor equal to 1 − α g from the entry's own albedo and g, known
    /// n_isotropic ε keys, and a lowercase hex content hash.
    fn check_derived(&self) -> Result<(), String> {
        if let Some(t) = &self.transport_factor {
            for (c, ((t, a), g)) in ["R", "G", "B"].iter().zip(
                t.as_array()
                    .into_iter()
                    .zip(self.albedo.as_array())
                    .zip(self.g.as_array()),
            ) {
                if (t - (1.0 - a * g)).abs() > 1e-12 {
                    return Err(self.at(format!(
                        "transport_factor.{c} = {t}, but 1 − α g = {} from the entry's albedo and g",
                        1.0 - a * g
                    )));
                }
            }
        }
        for (c, map) in ["R", "G", "B"].iter().zip(self.n_isotropic.as_array()) {
            if let Some(k) = map
                .keys()
                .find(|k| !N_ISOTROPIC_EPSILONS.contains(&k.as_str()))
            {
                return Err(self.at(format!(
                    "n_isotropic.{c} has key {k:?}, expected one of {N_ISOTROPIC_EPSILONS:?}"
                )));
            }
        }
        let hex = |s: &str| {
            !s.is_empty()
                && s.bytes()
                    .all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))
        };
        if !hex(&self.content_hash) {
            return Err(self.at(format!(
                "content_hash {:?} is not lowercase hex",
                self.content_hash
            )));
        }
        Ok(())
    }
}

/// Writes `DIR/manifest.json` atomically (see [`write_file_atomically`]) after
/// [`Manifest::check`]. `dir` must exist; on any error an existing manifest is untouched.
pub fn write_manifest(dir: impl AsRef<Path>, manifest: &Manifest) -> Result<(), ManifestError> {
    let path = dir.as_ref().join(MANIFEST_FILE);
    manifest.check().map_err(|e| ManifestError::Invalid {
        path: path.clone(),
        what: format!("{}; nothing was written", e.what),
    })?;
    write_file_atomically(&path, &manifest.to_json_bytes())
        .map_err(|(op, source)| ManifestError::Io { path, op, source })
}

/// Reads `DIR/manifest.json`: the schema version is checked first (so a newer layout fails
/// with [`ManifestError::Schema`], not with a missing key), then the structure, then
/// [`Manifest::check`].
pub fn read_manifest(dir: impl AsRef<Path>) -> Result<Manifest, ManifestError> {
    crate::commit::check_no_pending_commit(dir.as_ref())?;
    let path = dir.as_ref().join(MANIFEST_FILE);
    let bytes =
        read_regular_file(&path, MAX_MANIFEST_BYTES).map_err(|(op, source)| ManifestError::Io {
            path: path.clone(),
            op,
            source,
        })?;
    parse_manifest(&bytes, &path)
}

/// Parses and checks the bytes of a `manifest.json` as [`read_manifest`] does; `path` names it
/// in errors.
pub fn parse_manifest(bytes: &[u8], path: &Path) -> Result<Manifest, ManifestError> {
    let path = path.to_path_buf();
    if bytes.len() as u64 > MAX_MANIFEST_BYTES {
        return Err(ManifestError::Invalid {
            path,
            what: format!(
                "{} bytes, more than the {MAX_MANIFEST_BYTES} a manifest may have",
                bytes.len()
            ),
        });
    }
    let value: Value = serde_json::from_slice(bytes).map_err(|error| ManifestError::Json {
        path: path.clone(),
        key: None,
        error,
    })?;
    match value.get("schema") {
        Some(Value::Number(n)) if n.as_u64() == Some(u64::from(MANIFEST_SCHEMA_VERSION)) => {}
        found => {
            return Err(ManifestError::Schema {
                path,
                found: found.map_or("missing".to_string(), Value::to_string),
                expected: MANIFEST_SCHEMA_VERSION,
            });
        }
    }
    // Deserialize from the bytes (not the Value) so errors keep their line and column.
    let manifest: Manifest =
        serde_path_to_error::deserialize(&mut serde_json::Deserializer::from_slice(bytes))
            .map_err(|e| ManifestError::Json {
                path: path.clone(),
                key: Some(e.path().to_string()),
                error: e.into_inner(),
            })?;
    manifest
        .check()
        .map_err(|e| ManifestError::Invalid { path, what: e.what })?;
    Ok(manifest)
}

/// A bake directory opened for reading: its checked manifest, and fields read through it.
#[derive(Debug, Clone)]
pub struct BakeDir {
    /// The directory.
    pub dir: PathBuf,
    /// Its manifest, checked.
    pub manifest: Manifest,
}

impl BakeDir {
    /// Reads and checks `DIR/manifest.json` (see [`read_manifest`]).
    pub fn open(dir: impl AsRef<Path>) -> Result<Self, ManifestError> {
        let dir = dir.as_ref().to_path_buf();
        let manifest = read_manifest(&dir)?;
        Ok(Self { dir, manifest })
    }

    /// The entry of field `name`.
    pub fn entry(&self, name: &str) -> Option<&FieldEntry> {
        self.manifest.fields.iter().find(|f| f.name == name)
    }

    /// Reads the EXR of `entry` and checks it: the EXR contract ([`crate::read_field_exr`]),
    /// then against the manifest — field name, Δθ, K, N, F_1..F_N bit for bit — and last its
    /// size and CRC-32, so a file of another generation is refused even when it fits.
    pub fn read_field(&self, entry: &FieldEntry) -> Result<crate::FieldImage, crate::IoError> {
        use crate::exr::{decode_field_exr, read_exr_bytes};
        use crate::{ContractError, IoError};
        let path = self.dir.join(&entry.file);
        let bytes = read_exr_bytes(&path)?;
        let image = decode_field_exr(&bytes, &path)?;
        let mismatch = |what: String| IoError::Contract {
            path: path.clone(),
            check: ContractError::Manifest(what),
        };
        if image.field != entry.name {
            return Err(mismatch(format!(
                "field attribute {:?}, but manifest.json lists this file for field {:?}",
                image.field, entry.name
            )));
        }
        if image.theta_step_deg != self.manifest.theta_step_deg {
            return Err(mismatch(format!(
                "Δθ = {}°, manifest.json says {}°",
                image.theta_step_deg, self.manifest.theta_step_deg
            )));
        }
        if image.angle_count() != self.manifest.angle_count {
            return Err(mismatch(format!(
                "{} angles, manifest.json says {}",
                image.angle_count(),
                self.manifest.angle_count
            )));
        }
        if image.n_max() != entry.n_max {
            return Err(mismatch(format!(
                "{} rows, manifest.json says N = {}",
                image.n_max(),
                entry.n_max
            )));
        }
        for (c, (ch, want)) in ["R", "G", "B"]
            .iter()
            .zip(entry.forward_fraction.as_array())
            .enumerate()
        {
            let f = image.forward_fractions(c);
            if let Some(i) = (0..f.len()).find(|&i| f[i].to_bits() != want[i].to_bits()) {
                return Err(mismatch(format!(
                    "F_{}.{ch} = {} in the EXR header, {} in manifest.json",
                    i + 1,
                    f[i],
                    want[i]
                )));
            }
        }
        same_generation(&bytes, entry.bytes, &entry.crc32).map_err(mismatch)?;
        Ok(image)
    }

    /// Reads every file `entry` names — its EXR ([`Self::read_field`]) and its side tables
    /// ([`Self::read_side`]) — each checked against its contract and the manifest, then against
    /// each other ([`check_single_against_entry`]): what `inspect`, `validate` and the runtime
    /// read, so a corrupt side table fails them naming the file.
    pub fn read_field_files(&self, entry: &FieldEntry) -> Result<FieldFiles, crate::IoError> {
        let image = self.read_field(entry)?;
        let single = self.read_single(entry)?;
        if let (Some(single), Some(file)) = (&single, &entry.single_scattering) {
            check_single_against_entry(single, entry, &self.manifest.channels).map_err(|what| {
                crate::IoError::Contract {
                    path: self.dir.join(&file.file),
                    check: crate::ContractError::Manifest(what),
                }
            })?;
        }
        Ok(FieldFiles {
            image,
            single,
            poisson: self.read_poisson(entry)?,
            biri: self.read_biri(entry)?,
        })
    }

    /// Reads the single-scattering EXR of `entry` (`crate::single`), if the bake has one, and
    /// checks it as [`Self::read_side`] does.
    pub fn read_single(
        &self,
        entry: &FieldEntry,
    ) -> Result<Option<crate::SingleScatter>, crate::IoError> {
        self.read_side(entry.single_scattering.as_ref(), entry)
    }

    /// Reads the Poisson-mixture EXR of `entry` (`crate::poisson`), if the bake has one, and
    /// checks it as [`Self::read_side`] does.
    pub fn read_poisson(
        &self,
        entry: &FieldEntry,
    ) -> Result<Option<crate::PoissonTable>, crate::IoError> {
        self.read_side(entry.poisson.as_ref(), entry)
    }

    /// Reads the point-light kernel EXR of `entry` (`crate::biri`), if the bake has one, and
    /// checks it as [`Self::read_side`] does.
    pub fn read_biri(
        &self,
        entry: &FieldEntry,
    ) -> Result<Option<crate::BiriTable>, crate::IoError> {
        self.read_side(entry.biri_kernel.as_ref(), entry)
    }

    /// A side table of `entry` (`file`, if listed): read within [`crate::exr::MAX_EXR_BYTES`],
    /// decoded with every check of its contract ([`crate::side::decode`]), then its field name,
    /// Δθ and angle count against the manifest, and last its size and CRC-32.
    pub fn read_side<T: SideTable>(
        &self,
        file: Option<&FileRef>,
        entry: &FieldEntry,
    ) -> Result<Option<T>, crate::IoError> {
        use crate::{ContractError, IoError};
        let Some(file) = file else {
            return Ok(None);
        };
        let path = self.dir.join(&file.file);
        let bytes = crate::exr::read_exr_bytes(&path)?;
        let table: T = crate::side::decode(&bytes, &path)?;
        let mismatch = |what: String| IoError::Contract {
            path: path.clone(),
            check: ContractError::Manifest(what),
        };
        if table.field() != entry.name {
            return Err(mismatch(format!(
                "field attribute {:?}, but manifest.json lists this file for field {:?}",
                table.field(),
                entry.name
            )));
        }
        let (step, angles) = (table.theta_step_deg(), table.planes()[0].ncols());
        if step != self.manifest.theta_step_deg || angles != self.manifest.angle_count {
            return Err(mismatch(format!(
                "Δθ = {step}° with {angles} angles, manifest.json says {}° with {}",
                self.manifest.theta_step_deg, self.manifest.angle_count
            )));
        }
        same_generation(&bytes, file.bytes, &file.crc32).map_err(mismatch)?;
        Ok(Some(table))
    }
}

/// Every file of one field, read and checked ([`BakeDir::read_field_files`]).
#[derive(Debug, Clone)]
pub struct FieldFiles {
    /// The field's tables (`<name>.exr`).
    pub image: crate::FieldImage,
    /// Its single-scattering optics per wavelength, if the bake has them.
    pub single: Option<crate::SingleScatter>,
    /// Its Poisson mixtures, if the bake has them.
    pub poisson: Option<crate::PoissonTable>,
    /// Its point-light kernel, if the bake has it.
    pub biri: Option<crate::BiriTable>,
}

/// A field's single-scattering table against its manifest entry and the bake's channels: the
/// same wavelengths; per channel c the entry's σ_ext = Σ_j w_cj σ_ext,j and albedo =
/// Σ_j w_cj σ_sca,j / σ_ext (relative 10⁻¹²); and its forward-peak fractions, the share of
/// row n held by the exact forward δ, Σ_j a_cj f_j^n with a_cj = w_cj σ_sca,j / Σ_j w_cj
/// σ_sca,j and f_j each wavelength's energy of bin 0 above bin 1 (the bake's split,
/// `tables::ams`), within 10⁻⁶ + 10⁻⁵ n of the value (the table's bins are 32-bit floats).
/// A manifest whose peak fractions are zero where the table holds a peak is refused here.
pub fn check_single_against_entry(
    single: &crate::SingleScatter,
    entry: &FieldEntry,
    channels: &Channels,
) -> Result<(), String> {
    if single.wavelengths_nm != channels.wavelengths_nm {
        return Err(format!(
            "wavelengths {:?} nm, manifest.json's channels have {:?}",
            single.wavelengths_nm, channels.wavelengths_nm
        ));
    }
    let grid = grid::ThetaGrid::new(single.theta_step_deg).map_err(|e| e.to_string())?;
    let omega = grid.bin_solid_angles();
    let split: Vec<f64> = single
        .bins
        .outer_iter()
        .map(|bins| {
            let energy: f64 = bins.iter().zip(&omega).map(|(v, o)| v * o).sum();
            let (v0, v1) = (bins[0] / energy, bins[1] / energy);
            if v0 > v1 { (v0 - v1) * omega[0] } else { 0.0 }
        })
        .collect();
    let sca_j: Vec<f64> = (0..single.wavelengths_nm.len())
        .map(|j| single.sigma_ext_m2[j] * single.albedo[j])
        .collect();
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * a.abs().max(b.abs());
    for (c, ch) in ["R", "G", "B"].iter().enumerate() {
        let w = channels.weights.as_array()[c];
        let ext: f64 = w.iter().zip(&single.sigma_ext_m2).map(|(w, s)| w * s).sum();
        let sca: f64 = w.iter().zip(&sca_j).map(|(w, s)| w * s).sum();
        let (want_ext, want_albedo) =
            (entry.sigma_ext_m2.as_array()[c], entry.albedo.as_array()[c]);
        if !close(ext, *want_ext) || !close(sca / ext, *want_albedo) {
            return Err(format!(
                "channel {ch}: the table's wavelengths give σ_ext = {ext:e} m² and albedo {}, \
                 manifest.json says {want_ext:e} m² and {want_albedo}",
                sca / ext
            ));
        }
        let peaks = entry.forward_peak_fraction.as_array()[c];
        for (i, &got) in peaks.iter().enumerate() {
            let n = i as i32 + 1;
            let want: f64 = (0..split.len())
                .map(|j| w[j] * sca_j[j] / sca * split[j].powi(n))
                .sum();
            if (got - want).abs() > 1e-6 + 1e-5 * f64::from(n) * want {
                return Err(format!(
                    "forward_peak_fraction.{ch}[{i}] = {got} in manifest.json, but the table's \
                     forward peaks give {want}"
                ));
            }
        }
    }
    Ok(())
}

/// Whether `bytes` are the file the manifest lists with `size` bytes and CRC-32 `crc32`; the
/// error says what was found.
fn same_generation(bytes: &[u8], size: u64, crc32: &str) -> Result<(), String> {
    let crc = crate::commit::crc32_hex(bytes);
    if bytes.len() as u64 != size || crc != crc32 {
        return Err(format!(
            "{} bytes with CRC-32 {crc}, manifest.json says {size} bytes with {crc32}: the file is not the one this bake wrote (from another bake, or changed since)",
            bytes.len(),
        ));
    }
    Ok(())
}
