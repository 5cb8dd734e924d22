//! OpenVDB files' scalar grids as a dense box of f32 values.
//!
//! The file format is OpenVDB's (file versions 222 to 224, written by OpenVDB 3.0 and
//! later, Houdini, Blender and EmberGen among them): a header, then per grid a descriptor,
//! its compression flags, metadata, an index-to-world transform, the tree's topology and the
//! leaves' values. Read here: float and double grids of the standard 5-4-3 tree, saved at
//! full width or as halves, raw, zlib- or blosc-compressed (blosc through c-blosc, which
//! validates each chunk before it decompresses), with the active-mask compression OpenVDB
//! uses by default; transforms that scale and translate (no rotation or shear).
//!
//! Every length in the file is checked against the bytes left before it is used, so a
//! truncated or corrupted file is refused with the byte where reading failed, and nothing
//! is allocated beyond the file's size and the dense box's, which the caller bounds.
//!
//! The dense box is the active voxels' bounding box (what OpenVDB's
//! `evalActiveVoxelBoundingBox` reports); every voxel of it takes the grid's value there, as
//! OpenVDB's accessor would return it: a leaf's value (active or not), else a tile's, else
//! the background.

mod blosc;
mod bytes;
mod tree;
mod values;

use bytes::Bytes;
use values::{ACTIVE_MASK, BLOSC, Stored, ZIP};

/// Why a file or grid cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum VdbError {
    /// The file does not start with OpenVDB's magic number.
    #[error("not an OpenVDB file (its first bytes are not OpenVDB's magic number 0x56444220)")]
    NotVdb,
    /// The file ends before a part it announces.
    #[error("truncated: {what} at byte {at} needs {need} bytes, and the file ends at byte {len}")]
    Truncated {
        /// What was being read.
        what: &'static str,
        /// Where.
        at: usize,
        /// Bytes it needs.
        need: usize,
        /// The file's length.
        len: usize,
    },
    /// A grid of that name is not in the file.
    #[error("no grid named {name:?}; the file holds {}", list(.names))]
    NoGrid {
        /// The name asked for.
        name: String,
        /// The file's grids.
        names: Vec<String>,
    },
    /// The file says something impossible.
    #[error("corrupt: {0}")]
    Corrupt(String),
    /// The file is valid but holds what photometeor does not read.
    #[error("{0}")]
    Unsupported(String),
    /// The grid is larger than the caller allows.
    #[error("{0}")]
    TooLarge(String),
}

fn list(names: &[String]) -> String {
    if names.is_empty() {
        "no grids".into()
    } else {
        format!(
            "the grids {}",
            names
                .iter()
                .map(|n| format!("{n:?}"))
                .collect::<Vec<_>>()
                .join(", ")
        )
    }
}

/// The file versions read: NODE_MASK_COMPRESSION (OpenVDB 3.0) to MULTIPASS_IO.
pub const VERSIONS: std::ops::RangeInclusive<u32> = 222..=224;

/// One grid's entry in the file's list.
#[derive(Debug, Clone)]
struct Descriptor {
    /// The name shown (OpenVDB's unique name up to its ASCII record separator).
    name: String,
    /// The tree's type, e.g. `Tree_float_5_4_3` (without `_HalfFloat`).
    tree: String,
    /// The type name ended in `_HalfFloat`.
    half: bool,
    /// The grid whose tree this one shares, if any.
    parent: String,
    grid_pos: u64,
    block_pos: u64,
}

/// An opened file: its version and its grids.
#[derive(Debug)]
pub struct Archive<'a> {
    data: &'a [u8],
    /// The file format version.
    pub version: u32,
    /// The OpenVDB library version that wrote it (major, minor).
    pub library: (u32, u32),
    grids: Vec<Descriptor>,
}

/// An index-to-world transform that scales and translates: world = scale · index +
/// translation, voxel centres at integer indices.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transform {
    /// The voxel's size along x, y, z (world units; > 0).
    pub scale: [f64; 3],
    /// The world position of index (0, 0, 0).
    pub translation: [f64; 3],
}

/// One grid read into a dense box.
#[derive(Debug, Clone)]
pub struct Grid {
    /// Its name in the file.
    pub name: String,
    /// `float` or `double`.
    pub value_type: &'static str,
    /// Saved as 16-bit halves.
    pub half: bool,
    /// How its values were stored: "none", "zip" or "blosc", with "+ active mask".
    pub compression: String,
    /// Index to world.
    pub transform: Transform,
    /// The tree's background value.
    pub background: f32,
    /// Active voxels, tiles counted by the voxels they cover.
    pub active_voxels: u64,
    /// The active voxels' bounding box, inclusive index corners.
    pub index_min: [i32; 3],
    /// See `index_min`.
    pub index_max: [i32; 3],
    /// Voxels along x, y, z of the box.
    pub dims: [usize; 3],
    /// The box's values, x fastest, then y, then z.
    pub values: Vec<f32>,
    /// Leaf nodes in the tree.
    pub leaves: usize,
    /// Tiles that are active or differ from the background.
    pub tiles: usize,
}

impl Grid {
    /// The world position of the box's lower corner (the lower faces of its first voxels).
    pub fn world_min(&self) -> [f64; 3] {
        let t = &self.transform;
        std::array::from_fn(|a| {
            t.translation[a] + t.scale[a] * (f64::from(self.index_min[a]) - 0.5)
        })
    }

    /// The world position of the box's upper corner.
    pub fn world_max(&self) -> [f64; 3] {
        let t = &self.transform;
        std::array::from_fn(|a| {
            t.translation[a] + t.scale[a] * (f64::from(self.index_max[a]) + 0.5)
        })
    }
}

impl<'a> Archive<'a> {
    /// Reads the header and the grids' descriptors of a file held in `data`.
    pub fn parse(data: &'a [u8]) -> Result<Self, VdbError> {
        let mut b = Bytes::new(data);
        if data.len() < 8 || b.i64("the magic number")? != 0x5644_4220 {
            return Err(VdbError::NotVdb);
        }
        let version = b.u32("the file version")?;
        if !VERSIONS.contains(&version) {
            return Err(VdbError::Unsupported(format!(
                "file format version {version}: photometeor reads versions {} to {} (OpenVDB 3.0 \
                 and later)",
                VERSIONS.start(),
                VERSIONS.end()
            )));
        }
        let library = (b.u32("the library version")?, b.u32("the library version")?);
        if b.u8("the grid offsets flag")? != 1 {
            return Err(VdbError::Unsupported(
                "a file without grid offsets (a stream, not a file)".into(),
            ));
        }
        b.take(36, "the file's UUID")?;
        metadata(&mut b)?;
        let count = b.u32("the grid count")?;
        let mut grids = Vec::new();
        for _ in 0..count {
            let unique = b.string("a grid's name")?;
            let name = unique.split('\x1e').next().unwrap_or_default().to_string();
            let typed = b.string("a grid's type")?;
            let (tree, half) = match typed.strip_suffix("_HalfFloat") {
                Some(t) => (t.to_string(), true),
                None => (typed, false),
            };
            let parent = b.string("a grid's instance parent")?;
            let grid_pos = b.u64("a grid's position")?;
            let block_pos = b.u64("a grid's block position")?;
            let end_pos = b.u64("a grid's end position")?;
            grids.push(Descriptor {
                name,
                tree,
                half,
                parent,
                grid_pos,
                block_pos,
            });
            b.seek(end_pos, "the next grid's descriptor")?;
        }
        Ok(Archive {
            data,
            version,
            library,
            grids,
        })
    }

    /// The grids' names, in the file's order.
    pub fn names(&self) -> Vec<String> {
        self.grids.iter().map(|g| g.name.clone()).collect()
    }

    /// Grid `name` read into its dense box, refused if the box holds more than `max_values`
    /// voxels (before the box is allocated).
    pub fn read(&self, name: &str, max_values: u64) -> Result<Grid, VdbError> {
        let gd = self
            .grids
            .iter()
            .find(|g| g.name == name)
            .ok_or_else(|| VdbError::NoGrid {
                name: name.into(),
                names: self.names(),
            })?;
        let width = match gd.tree.as_str() {
            "Tree_float_5_4_3" => 4,
            "Tree_double_5_4_3" => 8,
            other => {
                return Err(VdbError::Unsupported(format!(
                    "grid {name:?} is a {other} grid: photometeor reads scalar density grids \
                     (Tree_float_5_4_3 or Tree_double_5_4_3)"
                )));
            }
        };
        if !gd.parent.is_empty() {
            return Err(VdbError::Unsupported(format!(
                "grid {name:?} is an instance of grid {:?} (it shares that grid's tree); \
                 instanced grids are not read: save the file without instancing",
                gd.parent
            )));
        }
        let mut b = Bytes::new(self.data);
        b.seek(gd.grid_pos, "the grid")?;
        let compression = b.u32("the grid's compression flags")?;
        if compression & !(ZIP | ACTIVE_MASK | BLOSC) != 0 {
            return Err(VdbError::Corrupt(format!(
                "grid {name:?}'s compression flags are {compression:#x}; OpenVDB writes \
                 combinations of 0x1 (zip), 0x2 (active mask) and 0x4 (blosc)"
            )));
        }
        let meta = metadata(&mut b)?;
        if meta.class.as_deref() == Some("level set") {
            return Err(VdbError::Unsupported(format!(
                "grid {name:?} is a level set (signed distances, not densities): convert it to a \
                 fog volume first (OpenVDB's sdfToFogVolume, Houdini's Convert VDB)"
            )));
        }
        let transform = transform(&mut b)?;
        let mut stored = Stored {
            compression,
            width,
            half: gd.half || meta.half,
            background: 0.0,
        };
        let topology = tree::Topology::read(&mut b, &mut stored)?;
        let (active_voxels, bounds) = topology.active();
        let (index_min, index_max) = bounds.ok_or_else(|| {
            VdbError::Unsupported(format!(
                "grid {name:?} has no active voxels: nothing to render"
            ))
        })?;
        let dims: [u64; 3] =
            std::array::from_fn(|a| (i64::from(index_max[a]) - i64::from(index_min[a]) + 1) as u64);
        let voxels = dims
            .iter()
            .try_fold(1u64, |p, &d| p.checked_mul(d))
            .unwrap_or(u64::MAX);
        if voxels > max_values {
            return Err(VdbError::TooLarge(format!(
                "grid {name:?}'s active voxels span {} × {} × {} = {voxels} voxels (index {:?} \
                 to {:?}), {:.2} GiB as f32, more than the {max_values} voxels a dense copy may \
                 hold",
                dims[0],
                dims[1],
                dims[2],
                index_min,
                index_max,
                4.0 * voxels as f64 / f64::from(1u32 << 30)
            )));
        }
        b.seek(gd.block_pos, "the grid's values")?;
        let values = topology.dense(&mut b, &stored, index_min, index_max)?;
        let (leaves, tiles) = topology.counts();
        Ok(Grid {
            name: name.into(),
            value_type: if width == 4 { "float" } else { "double" },
            half: stored.half,
            compression: compression_name(compression),
            transform,
            background: stored.background as f32,
            active_voxels,
            index_min,
            index_max,
            dims: dims.map(|d| d as usize),
            values,
            leaves,
            tiles,
        })
    }
}

fn compression_name(c: u32) -> String {
    let codec = if c & BLOSC != 0 {
        "blosc"
    } else if c & ZIP != 0 {
        "zip"
    } else {
        "none"
    };
    if c & ACTIVE_MASK != 0 {
        format!("{codec} + active mask")
    } else {
        codec.into()
    }
}

/// What photometeor reads of a metadata block.
struct Meta {
    /// `is_saved_as_half_float`.
    half: bool,
    /// `class`: "fog volume", "level set", "staggered" or "unknown".
    class: Option<String>,
}

/// A metadata block: a count, then per entry a name, a type name and a sized value.
fn metadata(b: &mut Bytes) -> Result<Meta, VdbError> {
    let count = b.u32("a metadata count")?;
    let mut meta = Meta {
        half: false,
        class: None,
    };
    for _ in 0..count {
        let name = b.string("a metadata name")?;
        let kind = b.string("a metadata type")?;
        let size = b.u32("a metadata value's size")? as usize;
        let value = b.take(size, "a metadata value")?;
        match (name.as_str(), kind.as_str()) {
            ("is_saved_as_half_float", "bool") => {
                meta.half = value.first().is_some_and(|&v| v != 0)
            }
            ("class", "string") => meta.class = Some(String::from_utf8_lossy(value).into_owned()),
            _ => {}
        }
    }
    Ok(meta)
}

/// The grid's transform: a map's type name, then its data. Maps that scale and translate are
/// read; an affine map only where it has no rotation or shear.
fn transform(b: &mut Bytes) -> Result<Transform, VdbError> {
    let map = b.string("the transform's type")?;
    let (scale, translation) = match map.as_str() {
        "UniformScaleMap" | "ScaleMap" => {
            let scale = b.vec3d("the transform")?;
            b.take(4 * 24, "the transform")?;
            (scale, [0.0; 3])
        }
        "UniformScaleTranslateMap" | "ScaleTranslateMap" => {
            let translation = b.vec3d("the transform")?;
            let scale = b.vec3d("the transform")?;
            b.take(4 * 24, "the transform")?;
            (scale, translation)
        }
        "TranslationMap" => ([1.0; 3], b.vec3d("the transform")?),
        "AffineMap" => {
            let m: Vec<f64> = (0..16)
                .map(|_| b.f64("the transform"))
                .collect::<Result<_, _>>()?;
            // Row vectors: world = [i j k 1] · M, the translation in the last row.
            let off_diagonal = [1, 2, 3, 4, 6, 7, 8, 9, 11];
            if off_diagonal.iter().any(|&i| m[i] != 0.0) || m[15] != 1.0 {
                return Err(VdbError::Unsupported(
                    "the transform rotates or shears the grid (an affine map with off-diagonal \
                     terms): photometeor reads transforms that scale and translate"
                        .into(),
                ));
            }
            ([m[0], m[5], m[10]], [m[12], m[13], m[14]])
        }
        other => {
            return Err(VdbError::Unsupported(format!(
                "the transform is a {other}: photometeor reads transforms that scale and \
                 translate (UniformScaleMap, ScaleMap, ScaleTranslateMap, TranslationMap, or \
                 an AffineMap without rotation)"
            )));
        }
    };
    if let Some(a) = (0..3).find(|&a| !(scale[a].is_finite() && scale[a] > 0.0)) {
        return Err(VdbError::Unsupported(format!(
            "the transform's scale along {} is {}: a voxel's size must be finite and > 0",
            ["x", "y", "z"][a],
            scale[a]
        )));
    }
    if translation.iter().any(|t| !t.is_finite()) {
        return Err(VdbError::Corrupt(format!(
            "the transform's translation {translation:?} is not finite"
        )));
    }
    Ok(Transform { scale, translation })
}
