//! A grid's tree (OpenVDB's `Tree<RootNode<InternalNode<InternalNode<LeafNode, 4>, 5>>>`,
//! "5_4_3"): the topology — root tiles and children, each internal node's child and value
//! masks and tile values, each leaf's active mask — then, at the grid's block position, each
//! leaf's values in the same order. Read into a dense box over the active voxels.

use crate::VdbError;
use crate::bytes::{Bytes, bit, ones};
use crate::values::Stored;

/// The most tiles kept (each a few tens of bytes): beyond it the file is refused.
const MAX_TILES: usize = 1 << 22;

/// A constant region: a root tile (4096³ voxels), a level-5 tile (128³) or a level-4 tile
/// (8³). Only tiles that are active or differ from the background are kept.
struct Tile {
    origin: [i32; 3],
    log2: u32,
    value: f64,
    active: bool,
}

/// A leaf (8³ voxels): its origin and active mask from the topology.
struct Leaf {
    origin: [i32; 3],
    active: Vec<u64>,
}

/// A box of voxels: its lowest and highest index corners, both inside.
pub(crate) type IndexBox = ([i32; 3], [i32; 3]);

/// The tree's topology.
pub(crate) struct Topology {
    tiles: Vec<Tile>,
    leaves: Vec<Leaf>,
}

/// The origin of child `n` of a node at `origin` with 2^`log2` children a side, each
/// 2^`child` voxels a side (OpenVDB's `offsetToGlobalCoord`: x slowest, z fastest).
fn child_origin(origin: [i32; 3], n: usize, log2: u32, child: u32) -> [i32; 3] {
    let side = (1usize << log2) - 1;
    let local = [n >> (2 * log2), (n >> log2) & side, n & side];
    std::array::from_fn(|a| origin[a].wrapping_add((local[a] as i32) << child))
}

impl Topology {
    /// The topology, from the cursor just after the grid's transform; fills in the stored
    /// values' background.
    pub(crate) fn read(b: &mut Bytes, stored: &mut Stored) -> Result<Self, VdbError> {
        let buffers = b.u32("the tree's buffer count")?;
        if buffers != 1 {
            return Err(VdbError::Unsupported(format!(
                "a tree of {buffers} buffers per leaf (OpenVDB writes 1)"
            )));
        }
        stored.background = stored.value(b, "the background value")?;
        let tiles = b.u32("the root's tile count")? as usize;
        let children = b.u32("the root's child count")? as usize;
        let each = 13 + stored.width;
        if tiles.saturating_mul(each) > b.left() {
            return Err(VdbError::Corrupt(format!(
                "the root says it has {tiles} tiles, more than the file's {} bytes left hold",
                b.left()
            )));
        }
        let mut t = Topology {
            tiles: Vec::new(),
            leaves: Vec::new(),
        };
        for _ in 0..tiles {
            let origin = b.coord("a root tile")?;
            let value = stored.value(b, "a root tile")?;
            let active = b.u8("a root tile")? != 0;
            t.tile(origin, 12, value, active, stored.background)?;
        }
        for _ in 0..children {
            let origin = b.coord("a root child's origin")?;
            if origin.iter().any(|&c| c & 4095 != 0) {
                return Err(VdbError::Corrupt(format!(
                    "a root child's origin {origin:?} is not a multiple of 4096"
                )));
            }
            t.internal(b, stored, origin, 5)?;
        }
        Ok(t)
    }

    fn tile(
        &mut self,
        origin: [i32; 3],
        log2: u32,
        value: f64,
        active: bool,
        background: f64,
    ) -> Result<(), VdbError> {
        if !active && value == background {
            return Ok(());
        }
        if self.tiles.len() == MAX_TILES {
            return Err(VdbError::TooLarge(format!(
                "more than {MAX_TILES} tiles differ from the background"
            )));
        }
        self.tiles.push(Tile {
            origin,
            log2,
            value,
            active,
        });
        Ok(())
    }

    /// An internal node of 2^`log2` children a side (5: 32³ children of 128³ voxels; 4: 16³
    /// children of 8³), its tiles and its children, depth first.
    fn internal(
        &mut self,
        b: &mut Bytes,
        stored: &Stored,
        origin: [i32; 3],
        log2: u32,
    ) -> Result<(), VdbError> {
        let count = 1usize << (3 * log2);
        let child = if log2 == 5 { 7 } else { 3 };
        let children = b.mask(count / 64, "an internal node's child mask")?;
        let active = b.mask(count / 64, "an internal node's value mask")?;
        let mut values = Vec::new();
        stored.node(b, count, &active, &mut values)?;
        for n in 0..count {
            if !bit(&children, n) {
                let o = child_origin(origin, n, log2, child);
                self.tile(o, child, values[n], bit(&active, n), stored.background)?;
            }
        }
        for n in ones(&children) {
            let o = child_origin(origin, n, log2, child);
            if log2 == 5 {
                self.internal(b, stored, o, 4)?;
            } else {
                let active = b.mask(8, "a leaf's value mask")?;
                self.leaves.push(Leaf { origin: o, active });
            }
        }
        Ok(())
    }

    /// The active voxels: their count, and their bounding box (inclusive index corners), or
    /// None where none is active.
    pub(crate) fn active(&self) -> (u64, Option<IndexBox>) {
        let mut count = 0u64;
        let mut lo = [i64::MAX; 3];
        let mut hi = [i64::MIN; 3];
        let mut grow = |a: [i64; 3], z: [i64; 3]| {
            for k in 0..3 {
                lo[k] = lo[k].min(a[k]);
                hi[k] = hi[k].max(z[k]);
            }
        };
        for t in self.tiles.iter().filter(|t| t.active) {
            count += 1u64 << (3 * t.log2);
            let a = t.origin.map(i64::from);
            grow(a, a.map(|c| c + (1i64 << t.log2) - 1));
        }
        for l in &self.leaves {
            for n in ones(&l.active) {
                count += 1;
                let c = leaf_voxel(l.origin, n);
                grow(c, c);
            }
        }
        let clamp =
            |v: [i64; 3]| v.map(|c| c.clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32);
        (count, (count > 0).then(|| (clamp(lo), clamp(hi))))
    }

    /// The values over the box `lo..=hi` (x fastest), reading the leaves' buffers from the
    /// cursor at the grid's block position: the background, then the tiles, then the leaves.
    pub(crate) fn dense(
        &self,
        b: &mut Bytes,
        stored: &Stored,
        lo: [i32; 3],
        hi: [i32; 3],
    ) -> Result<Vec<f32>, VdbError> {
        let dims: [usize; 3] =
            std::array::from_fn(|a| (i64::from(hi[a]) - i64::from(lo[a]) + 1) as usize);
        let mut out = vec![stored.background as f32; dims[0] * dims[1] * dims[2]];
        let at = |c: [i64; 3]| -> Option<usize> {
            let d: [i64; 3] = std::array::from_fn(|a| c[a] - i64::from(lo[a]));
            (0..3)
                .all(|a| d[a] >= 0 && d[a] < dims[a] as i64)
                .then(|| d[0] as usize + dims[0] * (d[1] as usize + dims[1] * d[2] as usize))
        };
        for t in &self.tiles {
            let a: [i64; 3] = std::array::from_fn(|k| i64::from(t.origin[k]).max(i64::from(lo[k])));
            let z: [i64; 3] = std::array::from_fn(|k| {
                (i64::from(t.origin[k]) + (1i64 << t.log2) - 1).min(i64::from(hi[k]))
            });
            if (0..3).any(|k| a[k] > z[k]) {
                continue;
            }
            for zz in a[2]..=z[2] {
                for y in a[1]..=z[1] {
                    for x in a[0]..=z[0] {
                        out[at([x, y, zz]).expect("inside the box")] = t.value as f32;
                    }
                }
            }
        }
        let mut values = Vec::with_capacity(512);
        for l in &self.leaves {
            let active = b.mask(8, "a leaf's buffer mask")?;
            stored.node(b, 512, &active, &mut values)?;
            for (n, &v) in values.iter().enumerate() {
                if let Some(i) = at(leaf_voxel(l.origin, n)) {
                    out[i] = v as f32;
                }
            }
        }
        Ok(out)
    }

    /// Leaves and kept tiles.
    pub(crate) fn counts(&self) -> (usize, usize) {
        (self.leaves.len(), self.tiles.len())
    }
}

/// Voxel `n` of a leaf at `origin` (x slowest, z fastest).
fn leaf_voxel(origin: [i32; 3], n: usize) -> [i64; 3] {
    let local = [n >> 6, (n >> 3) & 7, n & 7];
    std::array::from_fn(|a| i64::from(origin[a]) + local[a] as i64)
}
