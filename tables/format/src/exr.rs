//! One OpenEXR file per particle field: the baked Ams_n rows and F_i, as renderers read them
//! ("the EXR contract").
//!
//! [`write_field_exr`] writes a [`FieldImage`] atomically; [`read_field_exr`] reads one back and
//! checks every point of the contract below, so `photometeor inspect` and the runtime never
//! see a file that breaks it.
//!
//! # The contract
//! - One single-part, flat (not deep), single-resolution, scanline EXR per field; ZIP (lossless)
//!   compression; 32-bit float samples only.
//! - Channels exactly `R`, `G`, `B`: linear radiance per unit solid angle, unit 1/sr. Extra
//!   layers (e.g. per-wavelength rows) may follow as further 32-bit float channels under their
//!   own names, such as `lambda_550.Y`. Channels are stored in the file's (alphabetical) order,
//!   all with sampling 1×1 and `pLinear` = 0.
//! - Data window (0, 0)–(K − 1, N − 1); the display window is the same.
//!   - width K = 180°/Δθ + 1, the number of angle samples (1001 at 0.18°): column k ↔
//!     θ_k = k·Δθ, the bin average over [θ_k − Δθ/2, θ_k + Δθ/2] ∩ [0°, 180°] (see
//!     `grid::ThetaGrid`), forward-peak energy inside bin 0;
//!   - height N = n_max: row r (top row r = 0) ↔ Ams_{r+1}.
//! - Header attributes (see [`attr`]):
//!
//!   | name                                  | EXR type | value                                |
//!   |---------------------------------------|----------|--------------------------------------|
//!   | `photometeor/schema`                  | `int`    | [`EXR_SCHEMA_VERSION`] (1)           |
//!   | `photometeor/field`                   | `string` | the field's name, UTF-8              |
//!   | `photometeor/theta_step_deg`          | `double` | Δθ in degrees                        |
//!   | `photometeor/n_max`                   | `int`    | N, the number of rows                |
//!   | `photometeor/forward_fraction_R`/`_G`/`_B` | `string` | F_1..F_N, see below             |
//!
//! # Encoding of F_i
//! OpenEXR has a `floatvector` attribute type, but it holds 32-bit floats and the `exr` crate has
//! no typed variant for it. F_i is therefore a `string` attribute: the N values F_1..F_N as
//! decimal numbers separated by `,` (no spaces), each in the shortest form that parses back to
//! the identical `f64`, as JSON writers print them (ryu: `0.9731`, `1.0`, `5e-324`), e.g.
//! `0.9731,0.9512,0.5`. Any correctly rounding decimal parser (`str::parse::<f64>`, Python
//! `float`, C `strtod`) recovers the values bit for bit.
//!
//! # Determinism
//! The same [`FieldImage`] gives byte-identical files. The `exr` crate keeps custom attributes
//! in a `HashMap` and writes them in its (randomly seeded) iteration order; the writer
//! therefore re-sorts the header's attribute records by name after encoding, as the OpenEXR
//! reference library does (its header is a `std::map`). The records only move within the
//! header, whose length does not change, so the chunk offset table stays valid.
//!
//! # Bounds
//! Every size an EXR's header declares is checked against the file's own size and a stated
//! bound before anything is allocated for it ([`check_declared_size`], in every reader of this
//! crate and in [`decode_channels`]): the compression must be none or ZIP (deflate, whose
//! expansion is at most [`MAX_DEFLATE_RATIO`]), the samples at most [`decoded_bound`] of the
//! file's length, and every chunk the data window implies must have room in the file (16 bytes
//! at least: its offset-table entry, line number and size). The contract's own sizes — K from
//! Δθ, the rows from N or the header's lists — are then compared with the data window, still
//! before the pixels are decoded. A flipped bit in a header is refused naming the declared size
//! and the file's, instead of sizing an allocation.
//!
//! # Atomicity
//! The image is encoded in memory and written by [`crate::write_file_atomically`]: a temporary file
//! in the destination's directory, fsync, rename over the destination, fsync of the directory.
//! Any error before the rename removes the temporary file; a reader sees either the old file or
//! the complete new one.

use std::io::{self, Cursor};
use std::path::{Path, PathBuf};

use exr::meta::MetaData;
use exr::meta::attribute::{AttributeValue, SampleType, Text};
use exr::prelude::{
    AnyChannel, AnyChannels, Blocks, Compression, Encoding, FlatSamples, Image, Layer,
    LayerAttributes, LineOrder, ReadChannels, ReadLayers, SmallVec, Vec2, WritableImage,
};
use grid::ThetaGrid;
use ndarray::{Array2, Array3, ArrayView1, Axis, s};
use thiserror::Error;

use crate::atomic::{read_regular_file, write_file_atomically};

/// The largest EXR a reader accepts (bytes): 4 channels × 18001 angles × 2000 orders of f32 is
/// 288 MB uncompressed; anything larger is not a bake.
pub const MAX_EXR_BYTES: u64 = 512 << 20;

/// The most bytes of samples any EXR read here may declare (2 GiB): a bake's largest table
/// (4 channels × 18001 angles × 2000 orders of f32) is 288 MB, a render frame of 8192² pixels
/// with its 7 channels 1.9 GB.
pub const MAX_DECODED_BYTES: u64 = 2 << 30;

/// Deflate's largest expansion: one compressed byte never stands for more than 1032 bytes
/// (RFC 1951: a 258-byte match in as little as 2 bits).
pub const MAX_DEFLATE_RATIO: u64 = 1032;

/// The most bytes of samples an EXR of `file_len` bytes can decode to, as its readers enforce
/// before allocating (see "Bounds"): [`MAX_DEFLATE_RATIO`] per byte of a ZIP file, at most
/// [`MAX_DECODED_BYTES`]. The largest single allocation a reader makes is twice this (the
/// samples as `f64`) or the file itself.
pub fn decoded_bound(file_len: u64) -> u64 {
    MAX_DECODED_BYTES.min(MAX_DEFLATE_RATIO.saturating_mul(file_len))
}

/// Version of the EXR layout written in `photometeor/schema`; a reader rejects any other.
pub const EXR_SCHEMA_VERSION: i32 = 1;

/// The colour channels in the order of [`FieldImage::ams`]'s first axis.
pub const RGB_CHANNELS: [&str; 3] = ["R", "G", "B"];

/// Names of the `photometeor/` header attributes.
pub mod attr {
    /// `int`: the layout version, [`super::EXR_SCHEMA_VERSION`].
    pub const SCHEMA: &str = "photometeor/schema";
    /// `string`: the field's name (UTF-8).
    pub const FIELD: &str = "photometeor/field";
    /// `double`: Δθ in degrees.
    pub const THETA_STEP_DEG: &str = "photometeor/theta_step_deg";
    /// `int`: N, the number of rows (scatter orders).
    pub const N_MAX: &str = "photometeor/n_max";
    /// `string`: F_1..F_N per channel R, G, B, comma-separated shortest round-trip decimals.
    pub const FORWARD_FRACTION: [&str; 3] = [
        "photometeor/forward_fraction_R",
        "photometeor/forward_fraction_G",
        "photometeor/forward_fraction_B",
    ];
}

/// The baked tables of one particle field, as stored in its EXR.
///
/// # Texel order
/// `ams[[c, r, k]]`: channel c ∈ {R, G, B} (index into [`RGB_CHANNELS`]), row r = 0..N − 1 ↔
/// Ams_{r+1}, column k = 0..K − 1 ↔ θ_k = k·Δθ. Values are in 1/sr.
#[derive(Debug, Clone, PartialEq)]
pub struct FieldImage {
    /// The field's name as the scene gives it (`photometeor/field`).
    pub field: String,
    /// Δθ in degrees; must divide 180°.
    pub theta_step_deg: f64,
    /// Ams_n per channel R, G, B: shape (3, N, K), `ams[[c, n − 1, k]]`.
    pub ams: Array3<f64>,
    /// F_1..F_N per channel R, G, B: shape (3, N), `forward_fraction[[c, n − 1]]`.
    pub forward_fraction: Array2<f64>,
    /// Further channels, each `(channel name, rows)` with rows of shape (N, K), e.g.
    /// per-wavelength rows under `lambda_550.Y`. May be empty. [`read_field_exr`] returns them
    /// in the file's channel order, which is alphabetical.
    pub extra_layers: Vec<(String, Array2<f64>)>,
}

impl FieldImage {
    /// An image from nested rows, `rows[c][r][k]` and `forward_fraction[c][r]`; ragged rows
    /// are refused naming the channel and row.
    pub fn from_rows(
        field: impl Into<String>,
        theta_step_deg: f64,
        rows: &[Vec<Vec<f64>>; 3],
        forward_fraction: &[Vec<f64>; 3],
    ) -> Result<Self, IoError> {
        let field = field.into();
        let n = rows[0].len();
        let k = rows[0].first().map_or(0, Vec::len);
        let invalid = |what: String| IoError::InvalidImage {
            field: field.clone(),
            what,
        };
        for (c, name) in RGB_CHANNELS.iter().enumerate() {
            if rows[c].len() != n {
                return Err(invalid(format!(
                    "channel {name} has {} rows, expected N = {n} (as channel R)",
                    rows[c].len()
                )));
            }
            if let Some(r) = rows[c].iter().position(|row| row.len() != k) {
                return Err(invalid(format!(
                    "channel {name} row {r} has {} columns, expected {k} (as row 0 of R)",
                    rows[c][r].len()
                )));
            }
            if forward_fraction[c].len() != n {
                return Err(invalid(format!(
                    "forward_fraction {name} has {} values, expected N = {n}",
                    forward_fraction[c].len()
                )));
            }
        }
        let ams = Array3::from_shape_fn((3, n, k), |(c, r, kk)| rows[c][r][kk]);
        let forward_fraction = Array2::from_shape_fn((3, n), |(c, r)| forward_fraction[c][r]);
        Ok(Self {
            field,
            theta_step_deg,
            ams,
            forward_fraction,
            extra_layers: Vec::new(),
        })
    }

    /// N, the number of rows (Ams_1..Ams_N).
    pub fn n_max(&self) -> usize {
        self.ams.len_of(Axis(1))
    }

    /// K, the number of angle samples.
    pub fn angle_count(&self) -> usize {
        self.ams.len_of(Axis(2))
    }

    /// Row Ams_{r+1} of channel c, θ_0..θ_{K−1}.
    pub fn row(&self, c: usize, r: usize) -> ArrayView1<'_, f64> {
        self.ams.slice(s![c, r, ..])
    }

    /// F_1..F_N of channel c.
    pub fn forward_fractions(&self, c: usize) -> ArrayView1<'_, f64> {
        self.forward_fraction.row(c)
    }

    /// Every check the writer makes before touching the disk: Δθ divides 180°, N ≥ 1, every
    /// channel is N × K with K = 180°/Δθ + 1, N values of F_i per channel, extra layer names
    /// valid and distinct, every value finite also as a 32-bit float.
    pub fn check(&self) -> Result<(), IoError> {
        let invalid = |what: String| IoError::InvalidImage {
            field: self.field.clone(),
            what,
        };
        let grid = ThetaGrid::new(self.theta_step_deg)
            .map_err(|e| invalid(format!("theta_step_deg: {e}")))?;
        let k_expected = grid.len();
        let n = self.n_max();
        if n == 0 {
            return Err(invalid("no rows: N = n_max must be at least 1".into()));
        }
        if self.field.is_empty() {
            return Err(invalid("the field name is empty".into()));
        }
        if self.ams.len_of(Axis(0)) != 3 {
            return Err(invalid(format!(
                "{} colour channels, expected 3 (R, G, B)",
                self.ams.len_of(Axis(0))
            )));
        }
        if self.forward_fraction.dim() != (3, n) {
            let (c, r) = self.forward_fraction.dim();
            return Err(invalid(format!(
                "forward_fraction has shape {c} × {r}, expected 3 × N = 3 × {n}"
            )));
        }
        let check_rows = |channel: &str, rows: ndarray::ArrayView2<f64>| -> Result<(), IoError> {
            if rows.nrows() != n {
                return Err(invalid(format!(
                    "channel {channel} has {} rows, expected N = {n} (as channel R)",
                    rows.nrows()
                )));
            }
            if rows.ncols() != k_expected {
                return Err(invalid(format!(
                    "channel {channel} rows have {} columns, expected K = 180°/{}° + 1 = {k_expected}",
                    rows.ncols(),
                    self.theta_step_deg
                )));
            }
            for ((r, k), &v) in rows.indexed_iter() {
                if !v.is_finite() || !(v as f32).is_finite() {
                    return Err(IoError::NonFinite {
                        field: self.field.clone(),
                        channel: channel.to_string(),
                        row: r,
                        column: k,
                        value: v,
                    });
                }
            }
            Ok(())
        };
        for (c, name) in RGB_CHANNELS.iter().enumerate() {
            check_rows(name, self.ams.index_axis(Axis(0), c))?;
            let f = self.forward_fraction.row(c);
            if let Some(i) = f.iter().position(|v| !v.is_finite()) {
                return Err(invalid(format!(
                    "forward_fraction {name} F_{} = {} is not finite",
                    i + 1,
                    f[i]
                )));
            }
        }
        for (i, (name, rows)) in self.extra_layers.iter().enumerate() {
            check_channel_name(name)
                .map_err(|why| invalid(format!("extra layer {name:?}: {why}")))?;
            if self.extra_layers[..i]
                .iter()
                .any(|(other, _)| other == name)
            {
                return Err(invalid(format!("extra layer {name:?} is given twice")));
            }
            check_rows(name, rows.view())?;
        }
        Ok(())
    }
}

/// An extra channel name: 1..=255 printable ASCII characters, not one of R, G, B.
fn check_channel_name(name: &str) -> Result<(), &'static str> {
    if name.is_empty() || name.len() > 255 {
        return Err("a channel name must have 1 to 255 characters");
    }
    if !name.bytes().all(|b| b.is_ascii_graphic()) {
        return Err("a channel name must be printable ASCII without spaces");
    }
    if RGB_CHANNELS.contains(&name) {
        return Err("R, G and B are the colour channels, not extra layers");
    }
    Ok(())
}

/// What went wrong writing or reading a field's EXR. Every variant names the field or the file.
#[derive(Debug, Error)]
pub enum IoError {
    /// The image to write breaks the contract (shape, Δθ, names); nothing was written.
    #[error("field {field:?}: {what}; nothing was written")]
    InvalidImage {
        /// The field's name.
        field: String,
        /// The failed check.
        what: String,
    },
    /// A texel is NaN, infinite, or overflows a 32-bit float; nothing was written.
    #[error(
        "field {field:?}: channel {channel} row {row} (Ams_{n}) column {column} is {value}, expected a finite 32-bit float; nothing was written",
        n = row + 1
    )]
    NonFinite {
        /// The field's name.
        field: String,
        /// The channel (`R`, `G`, `B` or an extra layer).
        channel: String,
        /// Row r (Ams_{r+1}).
        row: usize,
        /// Column k (θ_k).
        column: usize,
        /// The offending value.
        value: f64,
    },
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
    /// The `exr` crate could not encode the image (a bug if [`FieldImage::check`] passed).
    #[error("{}: encoding the EXR failed: {source}", path.display())]
    Encode {
        /// The destination file.
        path: PathBuf,
        /// The underlying error.
        source: exr::error::Error,
    },
    /// The file is not a complete, readable OpenEXR file (truncated, corrupt, or not EXR).
    #[error("{}: not a complete OpenEXR file (truncated or corrupt?): {source}", path.display())]
    Unreadable {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: exr::error::Error,
    },
    /// The file is a valid EXR but breaks the photometeor contract.
    #[error("{}: {check}", path.display())]
    Contract {
        /// The file.
        path: PathBuf,
        /// The failed check.
        check: ContractError,
    },
}

impl IoError {
    /// The file the error names, if it names one (not for an image refused before writing).
    pub fn path(&self) -> Option<&Path> {
        match self {
            IoError::Io { path, .. }
            | IoError::Encode { path, .. }
            | IoError::Unreadable { path, .. }
            | IoError::Contract { path, .. } => Some(path),
            IoError::InvalidImage { .. } | IoError::NonFinite { .. } => None,
        }
    }
}

/// A failed check of the EXR contract, see the [module docs](self).
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ContractError {
    /// Not exactly one part, tiled, deep, or with several resolution levels.
    #[error("wrong layout: {0}, expected one flat single-resolution scanline part")]
    Layout(String),
    /// R, G or B is missing.
    #[error("wrong channel set: found [{}], expected R, G, B (+ extra layers)", found.join(", "))]
    Channels {
        /// The channels in the file.
        found: Vec<String>,
    },
    /// A channel is not 32-bit float or is subsampled.
    #[error("channel {channel}: {found}, expected 32-bit float with sampling 1×1")]
    SampleType {
        /// The channel.
        channel: String,
        /// What it is.
        found: String,
    },
    /// The data window does not match the attributes.
    #[error("wrong size: {0}")]
    Size(String),
    /// A `photometeor/` attribute is missing.
    #[error("missing attribute {0}")]
    MissingAttribute(&'static str),
    /// A `photometeor/` attribute has the wrong type or an unusable value.
    #[error("attribute {name}: found {found}, expected {expected}")]
    BadAttribute {
        /// The attribute.
        name: &'static str,
        /// What the file holds.
        found: String,
        /// What the contract wants.
        expected: String,
    },
    /// The file disagrees with its manifest entry.
    #[error("{0}")]
    Manifest(String),
    /// A texel is NaN or infinite.
    #[error("channel {channel} row {row} column {column} is {value}, expected a finite value")]
    NonFinite {
        /// The channel.
        channel: String,
        /// Row r.
        row: usize,
        /// Column k.
        column: usize,
        /// The value.
        value: f32,
    },
}

/// Writes `field` to `path` as one EXR following the [contract](self), atomically.
///
/// The image is checked first ([`FieldImage::check`]); on any error no file is created and an
/// existing file at `path` is left untouched.
pub fn write_field_exr(path: impl AsRef<Path>, field: &FieldImage) -> Result<(), IoError> {
    let path = path.as_ref();
    field.check()?;
    let bytes = encode_field_exr(field).map_err(|source| IoError::Encode {
        path: path.to_path_buf(),
        source,
    })?;
    write_file_atomically(path, &bytes).map_err(|(op, source)| IoError::Io {
        path: path.to_path_buf(),
        op,
        source,
    })
}

/// Encodes a checked image into the bytes of an EXR file, with the header canonicalized.
/// The bytes of `field`'s EXR after [`FieldImage::check`]: what [`write_field_exr`] writes.
pub fn field_exr_bytes(field: &FieldImage) -> Result<Vec<u8>, IoError> {
    field.check()?;
    encode_field_exr(field).map_err(|source| IoError::Encode {
        path: PathBuf::from(format!("{}.exr", field.field)),
        source,
    })
}

fn encode_field_exr(field: &FieldImage) -> Result<Vec<u8>, exr::error::Error> {
    let n = field.n_max();
    let k = field.angle_count();
    let flatten = |rows: ndarray::ArrayView2<f64>| -> Vec<f32> {
        // Row-major, top row first: sample (x = k, y = r) at index r·K + k.
        rows.iter().map(|&v| v as f32).collect()
    };
    let mut channels: Vec<(Text, Vec<f32>)> = RGB_CHANNELS
        .iter()
        .enumerate()
        .map(|(c, name)| (Text::from(*name), flatten(field.ams.index_axis(Axis(0), c))))
        .collect();
    for (name, rows) in &field.extra_layers {
        let name = Text::new_or_none(name).expect("checked: printable ASCII");
        channels.push((name, flatten(rows.view())));
    }
    let n_i32 = i32::try_from(n).expect("N fits an EXR int");
    let mut attributes = vec![
        (attr::SCHEMA, AttributeValue::I32(EXR_SCHEMA_VERSION)),
        (attr::FIELD, AttributeValue::Text(utf8_text(&field.field))),
        (
            attr::THETA_STEP_DEG,
            AttributeValue::F64(field.theta_step_deg),
        ),
        (attr::N_MAX, AttributeValue::I32(n_i32)),
    ];
    for (c, name) in attr::FORWARD_FRACTION.iter().enumerate() {
        let values: Vec<f64> = field.forward_fraction.row(c).to_vec();
        attributes.push((name, f64_list_attribute(&values)));
    }
    encode_layer((k, n), channels, attributes)
}

/// One scanline ZIP layer of 32-bit float `channels` (row-major, top row first) of `size` =
/// (width, height) with the `attributes`, encoded in memory with the header's attribute
/// records sorted by name (see "Determinism"). Both contracts' files are written by it.
pub(crate) fn encode_layer(
    size: (usize, usize),
    channels: Vec<(Text, Vec<f32>)>,
    attributes: Vec<(&str, AttributeValue)>,
) -> Result<Vec<u8>, exr::error::Error> {
    let mut list: SmallVec<[AnyChannel<FlatSamples>; 4]> = channels
        .into_iter()
        .map(|(name, values)| AnyChannel::new(name, FlatSamples::F32(values)))
        .collect();
    for channel in &mut list {
        // pLinear = 0 for every channel: all hold radiance-like values. The crate would guess
        // from the name and mark e.g. `lambda_550.Y` as perceptually linear (only lossy
        // compressors read the flag, but the header should not depend on a name heuristic).
        channel.quantize_linearly = false;
    }
    let mut layer_attributes = LayerAttributes::default();
    for (name, value) in attributes {
        layer_attributes.other.insert(
            Text::new_or_none(name).expect("ASCII attribute name"),
            value,
        );
    }
    let encoding = Encoding {
        compression: Compression::ZIP16,
        blocks: Blocks::ScanLines,
        line_order: LineOrder::Increasing,
    };
    let layer = Layer::new(
        Vec2(size.0, size.1),
        layer_attributes,
        encoding,
        AnyChannels::sort(list),
    );
    let mut bytes = Vec::new();
    Image::from_layer(layer)
        .write()
        .non_parallel()
        .to_buffered(Cursor::new(&mut bytes))?;
    sort_header_attributes(&mut bytes)?;
    Ok(bytes)
}

/// A `string` attribute holding [`format_f64_list`] of `values`.
pub(crate) fn f64_list_attribute(values: &[f64]) -> AttributeValue {
    AttributeValue::Text(utf8_text(&format_f64_list(values)))
}

/// An EXR `string` holding the UTF-8 bytes of `s` (EXR strings are byte strings; the `exr`
/// crate's `Text::from(&str)` would store Latin-1 instead).
pub(crate) fn utf8_text(s: &str) -> Text {
    Text::from_slice_unchecked(s.as_bytes())
}

/// `values` as shortest round-trip decimals separated by `,` (see "Encoding of F_i").
pub fn format_f64_list(values: &[f64]) -> String {
    values
        .iter()
        .map(|&v| match serde_json::Number::from_f64(v) {
            // ryu's shortest round-trip form: `0.97`, `1.0`, `5e-324`.
            Some(n) => n.to_string(),
            None => v.to_string(),
        })
        .collect::<Vec<_>>()
        .join(",")
}

/// Parses the output of [`format_f64_list`]; the error names the bad value's position.
pub fn parse_f64_list(text: &str) -> Result<Vec<f64>, String> {
    if text.is_empty() {
        return Ok(Vec::new());
    }
    text.split(',')
        .enumerate()
        .map(|(i, s)| match s.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(format!("value {} {s:?} is not a finite number", i + 1)),
        })
        .collect()
}

/// Sorts the attribute records of a single-part EXR header by name, in place.
///
/// Layout (OpenEXR file layout, "Header"): magic (4 bytes), version and flags (4), then
/// records `name\0 type\0 size:i32le value[size]`, closed by a single `\0`. Only the order of
/// records changes, so the header length and every offset after it stay the same.
fn sort_header_attributes(bytes: &mut [u8]) -> Result<(), exr::error::Error> {
    let bad = || exr::error::Error::Invalid("header layout while canonicalizing attributes".into());
    let start = 8;
    let mut pos = start;
    let mut records: Vec<(Vec<u8>, std::ops::Range<usize>)> = Vec::new();
    loop {
        let first = *bytes.get(pos).ok_or_else(bad)?;
        if first == 0 {
            break;
        }
        let record_start = pos;
        let name_len = bytes[pos..].iter().position(|&b| b == 0).ok_or_else(bad)?;
        let name = bytes[pos..pos + name_len].to_vec();
        pos += name_len + 1;
        let type_len = bytes
            .get(pos..)
            .ok_or_else(bad)?
            .iter()
            .position(|&b| b == 0)
            .ok_or_else(bad)?;
        pos += type_len + 1;
        let size_bytes: [u8; 4] = bytes
            .get(pos..pos + 4)
            .ok_or_else(bad)?
            .try_into()
            .map_err(|_| bad())?;
        let size = usize::try_from(i32::from_le_bytes(size_bytes)).map_err(|_| bad())?;
        pos += 4 + size;
        if pos > bytes.len() {
            return Err(bad());
        }
        records.push((name, record_start..pos));
    }
    let end = pos;
    let mut sorted = records.clone();
    sorted.sort_by(|a, b| a.0.cmp(&b.0));
    let mut header = Vec::with_capacity(end - start);
    for (_, range) in &sorted {
        header.extend_from_slice(&bytes[range.clone()]);
    }
    bytes[start..end].copy_from_slice(&header);
    Ok(())
}

/// Reads and checks the EXR of one field (see the [contract](self)).
///
/// Errors name the file and the failed check: not an EXR or truncated
/// ([`IoError::Unreadable`]), or a [`ContractError`] (layout, channel set, sample type, size,
/// missing or malformed attribute, non-finite texel).
pub fn read_field_exr(path: impl AsRef<Path>) -> Result<FieldImage, IoError> {
    let path = path.as_ref();
    let bytes = read_exr_bytes(path)?;
    decode_field_exr(&bytes, path)
}

/// The bytes of an EXR file, read only if it is a regular file of at most [`MAX_EXR_BYTES`].
pub fn read_exr_bytes(path: &Path) -> Result<Vec<u8>, IoError> {
    read_regular_file(path, MAX_EXR_BYTES).map_err(|(op, source)| IoError::Io {
        path: path.to_path_buf(),
        op,
        source,
    })
}

/// The header of a single-part EXR, read and checked for the layout both photometeor
/// contracts share (one flat, single-resolution, scanline part), with the attribute and pixel
/// accessors their decoders use; errors name the file.
pub(crate) struct Checked<'a> {
    path: &'a Path,
    bytes: &'a [u8],
    header: exr::meta::header::Header,
}

impl<'a> Checked<'a> {
    /// Reads the header of `bytes` (from `path`) and checks the layout.
    pub(crate) fn read(bytes: &'a [u8], path: &'a Path) -> Result<Self, IoError> {
        let meta = MetaData::read_from_buffered(Cursor::new(bytes), true).map_err(|source| {
            IoError::Unreadable {
                path: path.to_path_buf(),
                source,
            }
        })?;
        if meta.headers.len() != 1 {
            return Err(IoError::Contract {
                path: path.to_path_buf(),
                check: ContractError::Layout(format!("{} parts", meta.headers.len())),
            });
        }
        let checked = Self {
            path,
            bytes,
            header: meta.headers.into_iter().next().expect("one part"),
        };
        if checked.header.deep {
            return Err(checked.contract(ContractError::Layout("deep data".into())));
        }
        if !matches!(
            checked.header.blocks,
            exr::meta::BlockDescription::ScanLines
        ) {
            return Err(checked.contract(ContractError::Layout("tiled".into())));
        }
        check_declared_size(&checked.header, bytes.len() as u64)
            .map_err(|why| checked.contract(ContractError::Size(why)))?;
        Ok(checked)
    }

    /// The data window must start at (0, 0) and be `width` × `height`, the contract's sizes:
    /// checked before any pixel is decoded. `what` says where the sizes come from.
    pub(crate) fn expect_size(
        &self,
        width: usize,
        height: usize,
        what: &str,
    ) -> Result<(), IoError> {
        let position = self.header.own_attributes.layer_position;
        if position != Vec2(0, 0) {
            return Err(self.contract(ContractError::Size(format!(
                "data window starts at ({}, {}), expected (0, 0)",
                position.0, position.1
            ))));
        }
        let (w, h) = (self.header.layer_size.0, self.header.layer_size.1);
        if (w, h) != (width, height) {
            return Err(self.contract(ContractError::Size(format!(
                "data window is {w} × {h}, expected {width} × {height} ({what})"
            ))));
        }
        Ok(())
    }

    /// The header.
    pub(crate) fn header(&self) -> &exr::meta::header::Header {
        &self.header
    }

    /// A contract failure of this file.
    pub(crate) fn contract(&self, check: ContractError) -> IoError {
        IoError::Contract {
            path: self.path.to_path_buf(),
            check,
        }
    }

    /// The channel names in the file's order.
    pub(crate) fn channel_names(&self) -> Vec<String> {
        self.header
            .channels
            .list
            .iter()
            .map(|c| String::from_utf8_lossy(c.name.bytes()).into_owned())
            .collect()
    }

    /// Every channel is 32-bit float with sampling 1×1.
    pub(crate) fn check_sample_types(&self) -> Result<(), IoError> {
        for (channel, name) in self.header.channels.list.iter().zip(self.channel_names()) {
            if channel.sample_type != SampleType::F32 || channel.sampling != Vec2(1, 1) {
                return Err(self.contract(ContractError::SampleType {
                    channel: name,
                    found: format!(
                        "{:?} with sampling {}×{}",
                        channel.sample_type, channel.sampling.0, channel.sampling.1
                    ),
                }));
            }
        }
        Ok(())
    }

    /// The attribute `name`, or a missing-attribute failure.
    pub(crate) fn get(&self, name: &'static str) -> Result<&AttributeValue, IoError> {
        self.header
            .own_attributes
            .other
            .get(&Text::new_or_none(name).expect("ASCII attribute name"))
            .ok_or_else(|| self.contract(ContractError::MissingAttribute(name)))
    }

    /// A malformed-attribute failure.
    pub(crate) fn bad(&self, name: &'static str, found: String, expected: &str) -> IoError {
        self.contract(ContractError::BadAttribute {
            name,
            found,
            expected: expected.to_string(),
        })
    }

    /// A UTF-8 `string` attribute.
    pub(crate) fn text(&self, name: &'static str) -> Result<String, IoError> {
        match self.get(name)? {
            AttributeValue::Text(t) => String::from_utf8(t.bytes().to_vec())
                .map_err(|_| self.bad(name, "bytes that are not UTF-8".into(), "a UTF-8 string")),
            other => Err(self.bad(name, format!("{other:?}"), "a string")),
        }
    }

    /// A `string` attribute holding a [`format_f64_list`]; `expected` describes it in errors.
    pub(crate) fn f64_list(&self, name: &'static str, expected: &str) -> Result<Vec<f64>, IoError> {
        parse_f64_list(&self.text(name)?).map_err(|why| self.bad(name, why, expected))
    }

    /// A `double` attribute.
    pub(crate) fn double(&self, name: &'static str) -> Result<f64, IoError> {
        match self.get(name)? {
            AttributeValue::F64(v) => Ok(*v),
            other => Err(self.bad(name, format!("{other:?}"), "a double")),
        }
    }

    /// The `int` attribute `name` must be `version`.
    pub(crate) fn schema(&self, name: &'static str, version: i32) -> Result<(), IoError> {
        match self.get(name)? {
            AttributeValue::I32(v) if *v == version => Ok(()),
            other => Err(self.bad(name, format!("{other:?}"), &format!("int {version}"))),
        }
    }

    /// The pixels, channel by channel in the file's order, each checked to hold width ×
    /// height samples: a truncated or corrupt chunk fails here.
    pub(crate) fn channels(&self) -> Result<Channels, IoError> {
        let (channels, width, height) =
            decode_channels(self.bytes).map_err(|source| IoError::Unreadable {
                path: self.path.to_path_buf(),
                source,
            })?;
        for (name, samples) in &channels {
            if samples.len() != width * height {
                return Err(self.contract(ContractError::Size(format!(
                    "channel {name} has {} samples, expected {width} × {height}",
                    samples.len()
                ))));
            }
        }
        Ok(channels)
    }
}

/// Named channels of 32-bit float samples, in a file's order.
pub type Channels = Vec<(String, Vec<f32>)>;

/// Checks the sizes `header` declares against a file of `file_len` bytes (see "Bounds"): the
/// compression is none or ZIP, the samples fit [`decoded_bound`] of the file, and every chunk
/// of the data window has room in it. The error names the declared sizes and the file's.
pub fn check_declared_size(
    header: &exr::meta::header::Header,
    file_len: u64,
) -> Result<(), String> {
    let (w, h) = (header.layer_size.0 as u64, header.layer_size.1 as u64);
    let ratio = match header.compression {
        Compression::Uncompressed => 1,
        Compression::ZIP1 | Compression::ZIP16 => MAX_DEFLATE_RATIO,
        other => {
            return Err(format!(
                "compression {other}, expected ZIP (or none): the only ones whose expansion is bounded here"
            ));
        }
    };
    let channels = header.channels.list.len() as u64;
    let declared = header.channels.bytes_per_pixel as u64 * w * h;
    let bound = MAX_DECODED_BYTES.min(ratio.saturating_mul(file_len));
    if declared > bound || channels * 4 * w * h > MAX_DECODED_BYTES {
        return Err(format!(
            "the header declares a {w} × {h} data window of {channels} channel(s), {declared} bytes of samples, \
             but a {file_len}-byte file ({}) decodes to at most {bound} (at most {ratio} bytes per byte, \
             {MAX_DECODED_BYTES} in all)",
            header.compression
        ));
    }
    let lines = header.compression.scan_lines_per_block() as u64;
    let chunks = h.div_ceil(lines);
    if chunks.saturating_mul(16) > file_len {
        return Err(format!(
            "the header declares {h} lines in {chunks} chunks of {lines}, but a {file_len}-byte file \
             has room for at most {} (16 bytes per chunk at least)",
            file_len / 16
        ));
    }
    Ok(())
}

/// Every channel of the first layer of an EXR as 32-bit floats, in the file's order, with the
/// layer's width and height (any flat EXR: `photometeor render`'s frames as well as tables).
/// The header's sizes are checked first ([`check_declared_size`]), so no allocation is sized
/// by a header the file cannot back.
pub fn decode_channels(bytes: &[u8]) -> Result<(Channels, usize, usize), exr::error::Error> {
    let meta = MetaData::read_from_buffered(Cursor::new(bytes), true)?;
    for header in &meta.headers {
        check_declared_size(header, bytes.len() as u64)
            .map_err(|why| exr::error::Error::Invalid(why.into()))?;
    }
    let image = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .pedantic()
        .non_parallel()
        .from_buffered(Cursor::new(bytes))?;
    let layer = image.layer_data;
    let channels = layer
        .channel_data
        .list
        .into_iter()
        .map(|c| {
            let name = String::from_utf8_lossy(c.name.bytes()).into_owned();
            let samples = match c.sample_data {
                FlatSamples::F32(v) => v,
                other => other.values_as_f32().collect(),
            };
            (name, samples)
        })
        .collect();
    Ok((channels, layer.size.0, layer.size.1))
}

/// Decodes and checks the bytes of a field's EXR (see [`read_field_exr`]); `path` names the
/// file in errors.
pub fn decode_field_exr(bytes: &[u8], path: &Path) -> Result<FieldImage, IoError> {
    // Layout and channel list, from the header alone.
    let file = Checked::read(bytes, path)?;
    let header = file.header();
    let position = header.own_attributes.layer_position;
    if position != Vec2(0, 0) {
        return Err(file.contract(ContractError::Size(format!(
            "data window starts at ({}, {}), expected (0, 0)",
            position.0, position.1
        ))));
    }
    let names = file.channel_names();
    if !RGB_CHANNELS
        .iter()
        .all(|rgb| names.iter().any(|n| n == rgb))
    {
        return Err(file.contract(ContractError::Channels { found: names }));
    }
    file.check_sample_types()?;

    // Attributes.
    file.schema(attr::SCHEMA, EXR_SCHEMA_VERSION)?;
    let field = file.text(attr::FIELD)?;
    let theta_step_deg = file.double(attr::THETA_STEP_DEG)?;
    let grid = ThetaGrid::new(theta_step_deg).map_err(|e| {
        file.bad(
            attr::THETA_STEP_DEG,
            theta_step_deg.to_string(),
            &format!("a step dividing 180° ({e})"),
        )
    })?;
    let n = match file.get(attr::N_MAX)? {
        AttributeValue::I32(v) if *v >= 1 => *v as usize,
        other => return Err(file.bad(attr::N_MAX, format!("{other:?}"), "an int ≥ 1")),
    };

    // Size, before anything is allocated by N or the data window.
    let (width, height) = (header.layer_size.0, header.layer_size.1);
    if width != grid.len() || height != n {
        return Err(file.contract(ContractError::Size(format!(
            "data window is {width} × {height}, expected K × N = {} × {n} (K = 180°/{theta_step_deg}° + 1, N = n_max)",
            grid.len()
        ))));
    }
    let mut lists = Vec::with_capacity(3);
    for name in attr::FORWARD_FRACTION {
        let values = file.f64_list(name, "comma-separated finite decimals F_1..F_N")?;
        if values.len() != n {
            return Err(file.bad(
                name,
                format!("{} values", values.len()),
                &format!("N = n_max = {n} values"),
            ));
        }
        lists.push(values);
    }
    let mut forward_fraction = Array2::zeros((3, n));
    for (c, values) in lists.iter().enumerate() {
        forward_fraction
            .row_mut(c)
            .assign(&ArrayView1::from(values));
    }

    // Pixels.
    let mut ams = Array3::zeros((3, height, width));
    let mut extra_layers = Vec::new();
    for (name, samples) in file.channels()? {
        if let Some(i) = samples.iter().position(|v| !v.is_finite()) {
            return Err(file.contract(ContractError::NonFinite {
                channel: name,
                row: i / width,
                column: i % width,
                value: samples[i],
            }));
        }
        let channel_rows =
            Array2::from_shape_fn((height, width), |(r, k)| f64::from(samples[r * width + k]));
        match RGB_CHANNELS.iter().position(|rgb| *rgb == name) {
            Some(c) => ams.index_axis_mut(Axis(0), c).assign(&channel_rows),
            None => extra_layers.push((name, channel_rows)),
        }
    }
    Ok(FieldImage {
        field,
        theta_step_deg,
        ams,
        forward_fraction,
        extra_layers,
    })
}
