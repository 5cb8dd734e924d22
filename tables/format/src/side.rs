//! The layout a field's side tables share — [`crate::single`], [`crate::poisson`] and
//! [`crate::biri`] — and the one codec that writes and reads all three.
//!
//! # The shared contract
//! - One single-part, flat, single-resolution, scanline EXR; ZIP compression; the table's
//!   32-bit float channels ([`SideTable::CHANNELS`]), sampling 1×1, `pLinear` = 0.
//! - Data window (0, 0)–(K − 1, J − 1): column k ↔ θ_k = k·Δθ, the field's angle grid
//!   (`grid::ThetaGrid`, K = 180°/Δθ + 1); row j ↔ the j-th value of the table's first list
//!   ([`SideTable::LISTS`]`[0]`: its wavelengths or optical depths), so J is that list's length.
//! - Header attributes: [`attr::SCHEMA`] (`int`, [`SideTable::SCHEMA_VERSION`]),
//!   [`attr::FIELD`] (`string`, the field's name, UTF-8), [`attr::THETA_STEP_DEG`] (`double`,
//!   Δθ in degrees) and each of the table's lists as a `string` encoded as F_i in the field's
//!   EXR (`crate::exr`, "Encoding of F_i"), so a reader recovers the f64 values bit for bit.
//!   The header's records are sorted by name, so the same table gives the same bytes.
//!
//! # Reading, in order
//! Each step before anything is allocated by what it checks: the header, and the sizes it
//! declares against the file's (`crate::exr`, "Bounds"); the channel set and sample types; the
//! schema, field name and Δθ; the lists; the data window against K × J; only then the pixels,
//! and last the table's own checks ([`SideTable::check`]). A bake's reader then compares the
//! field, Δθ and K with the manifest and the file's size and CRC-32 with its entry
//! ([`crate::BakeDir::read_side`]).

use std::path::{Path, PathBuf};

use exr::meta::attribute::{AttributeValue, Text};
use grid::ThetaGrid;
use ndarray::{Array2, ArrayView2};

use crate::exr::{Checked, ContractError, IoError, encode_layer, f64_list_attribute, utf8_text};

/// Names of the header attributes every side table has.
pub mod attr {
    /// `int`: the table's [`super::SideTable::SCHEMA_VERSION`].
    pub const SCHEMA: &str = "photometeor/schema";
    /// `string`: the field's name.
    pub const FIELD: &str = "photometeor/field";
    /// `double`: Δθ in degrees.
    pub const THETA_STEP_DEG: &str = "photometeor/theta_step_deg";
}

/// One kind of side table: its names, its lists of numbers, its planes of samples and its
/// checks, in the shared layout (see the [module docs](self)).
pub trait SideTable: Sized {
    /// What the file holds, as errors name it ("single-scattering table").
    const WHAT: &'static str;
    /// `photometeor/schema`; a reader rejects any other.
    const SCHEMA_VERSION: i32;
    /// The channels, in the order of [`Self::planes`].
    const CHANNELS: &'static [&'static str];
    /// The `string` attributes holding lists of numbers, in the order of [`Self::lists`]; the
    /// first is the rows' axis.
    const LISTS: &'static [&'static str];

    /// The file name of field `field`'s table inside a bake directory.
    fn file_name(field: &str) -> String;
    /// The field's name.
    fn field(&self) -> &str;
    /// Δθ in degrees.
    fn theta_step_deg(&self) -> f64;
    /// The lists, in the order of [`Self::LISTS`].
    fn lists(&self) -> Vec<&[f64]>;
    /// The samples per channel, in the order of [`Self::CHANNELS`]: J × K each.
    fn planes(&self) -> Vec<ArrayView2<'_, f64>>;
    /// The table from what a file holds, in the orders above (shapes not yet checked).
    fn from_parts(
        field: String,
        theta_step_deg: f64,
        lists: Vec<Vec<f64>>,
        planes: Vec<Array2<f64>>,
    ) -> Self;
    /// Every check the writer makes before encoding and a reader after decoding: the grid,
    /// shapes, ranges, finite values.
    fn check(&self) -> Result<(), String>;
}

/// The bytes of `t`'s EXR after [`SideTable::check`] (deterministic: the header's attributes
/// sorted by name).
pub fn encode<T: SideTable>(t: &T) -> Result<Vec<u8>, IoError> {
    t.check().map_err(|what| IoError::InvalidImage {
        field: t.field().to_string(),
        what: format!("{}: {what}", T::WHAT),
    })?;
    let planes = t.planes();
    let (j, k) = planes[0].dim();
    let channels = T::CHANNELS
        .iter()
        .zip(&planes)
        .map(|(name, plane)| (Text::from(*name), plane.iter().map(|&v| v as f32).collect()))
        .collect();
    let mut attributes = vec![
        (attr::SCHEMA, AttributeValue::I32(T::SCHEMA_VERSION)),
        (attr::FIELD, AttributeValue::Text(utf8_text(t.field()))),
        (
            attr::THETA_STEP_DEG,
            AttributeValue::F64(t.theta_step_deg()),
        ),
    ];
    for (name, values) in T::LISTS.iter().zip(t.lists()) {
        attributes.push((name, f64_list_attribute(values)));
    }
    encode_layer((k, j), channels, attributes).map_err(|source| IoError::Encode {
        path: PathBuf::from(T::file_name(t.field())),
        source,
    })
}

/// Decodes and checks the bytes of a `T` EXR (see "Reading, in order"); `path` names the file
/// in errors.
pub fn decode<T: SideTable>(bytes: &[u8], path: &Path) -> Result<T, IoError> {
    let file = Checked::read(bytes, path)?;
    let names = file.channel_names();
    let mut sorted = names.clone();
    sorted.sort();
    let mut expected: Vec<&str> = T::CHANNELS.to_vec();
    expected.sort();
    if sorted != expected {
        return Err(file.contract(ContractError::Channels { found: names }));
    }
    file.check_sample_types()?;
    file.schema(attr::SCHEMA, T::SCHEMA_VERSION)?;
    let field = file.text(attr::FIELD)?;
    let theta_step_deg = file.double(attr::THETA_STEP_DEG)?;
    let grid = ThetaGrid::new(theta_step_deg).map_err(|e| {
        file.bad(
            attr::THETA_STEP_DEG,
            theta_step_deg.to_string(),
            &format!("a step dividing 180° ({e})"),
        )
    })?;
    let lists = T::LISTS
        .iter()
        .map(|name| file.f64_list(name, "comma-separated finite decimals"))
        .collect::<Result<Vec<_>, _>>()?;
    let (k, j) = (grid.len(), lists[0].len());
    file.expect_size(
        k,
        j,
        &format!(
            "K = 180°/{theta_step_deg}° + 1, J = the {} values of {}",
            j,
            T::LISTS[0]
        ),
    )?;
    let channels = file.channels()?;
    let planes = T::CHANNELS
        .iter()
        .map(|name| {
            let samples = &channels
                .iter()
                .find(|(n, _)| n == name)
                .expect("the channel set is checked above")
                .1;
            Array2::from_shape_fn((j, k), |(r, c)| f64::from(samples[r * k + c]))
        })
        .collect();
    let t = T::from_parts(field, theta_step_deg, lists, planes);
    t.check()
        .map_err(|why| file.contract(ContractError::Size(why)))?;
    Ok(t)
}
