//! One node's values as OpenVDB stores them (its `io::readCompressedValues`): a byte saying
//! which inactive values are left out and how to restore them, those values, a selection
//! mask, then the stored values — all of them, or the active ones only — as f32, f64 or half,
//! raw, zlib- or blosc-compressed.

use crate::VdbError;
use crate::bytes::{Bytes, bit};
use std::io::Read;

/// The grid's compression flags (OpenVDB's `COMPRESS_*`).
pub(crate) const ZIP: u32 = 0x1;
pub(crate) const ACTIVE_MASK: u32 = 0x2;
pub(crate) const BLOSC: u32 = 0x4;

/// How one grid's values are stored.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Stored {
    /// The compression flags.
    pub compression: u32,
    /// Bytes of one value in memory: 4 (float) or 8 (double).
    pub width: usize,
    /// The values were saved as 16-bit halves.
    pub half: bool,
    /// The tree's background value, from which left-out inactive values are restored.
    pub background: f64,
}

impl Stored {
    /// One value at full width (backgrounds, tiles and inactive values are never halved).
    pub(crate) fn value(&self, b: &mut Bytes, what: &'static str) -> Result<f64, VdbError> {
        let s = b.take(self.width, what)?;
        Ok(decode(s, self.width))
    }

    /// `count` values of one node whose active voxels are `active` (a mask of `count` bits),
    /// into `out` (cleared first).
    pub(crate) fn node(
        &self,
        b: &mut Bytes,
        count: usize,
        active: &[u64],
        out: &mut Vec<f64>,
    ) -> Result<(), VdbError> {
        let at = b.pos();
        let flag = b.u8("a node's value flag")?;
        if flag > 6 {
            return Err(VdbError::Corrupt(format!(
                "a node's value flag at byte {at} is {flag}; OpenVDB writes 0 to 6"
            )));
        }
        // The flags' meanings (OpenVDB's NO_MASK_OR_INACTIVE_VALS … NO_MASK_AND_ALL_VALS).
        let bg = self.background;
        let mut inactive = [if flag == 0 { bg } else { -bg }, bg];
        if matches!(flag, 2 | 4 | 5) {
            inactive[0] = self.value(b, "an inactive value")?;
            if flag == 5 {
                inactive[1] = self.value(b, "an inactive value")?;
            }
        }
        let selection = if (3..=5).contains(&flag) {
            Some(b.mask(count / 64, "a selection mask")?)
        } else {
            None
        };
        let only_active = self.compression & ACTIVE_MASK != 0 && flag != 6;
        let stored = if only_active {
            active.iter().map(|w| w.count_ones() as usize).sum()
        } else {
            count
        };
        let width = if self.half { 2 } else { self.width };
        // Halves are read by OpenVDB's HalfReader, which reads nothing at all for no values
        // (not even a chunk's size, which full-width values always have).
        let raw = if self.half && stored == 0 {
            Vec::new()
        } else {
            self.payload(b, stored * width)?
        };
        let mut values = raw.chunks_exact(width).map(|c| decode(c, width));
        out.clear();
        if only_active {
            for n in 0..count {
                out.push(if bit(active, n) {
                    values.next().expect("one stored value per active voxel")
                } else {
                    let chosen = selection.as_ref().is_some_and(|s| bit(s, n));
                    inactive[usize::from(chosen)]
                });
            }
        } else {
            out.extend(values);
        }
        Ok(())
    }

    /// `bytes` bytes of stored values, decompressed (OpenVDB's `readData`): blosc first, then
    /// zlib, else raw. A compressed chunk is preceded by its size (i64); a size ≤ 0 says the
    /// chunk was written raw, `−size` bytes.
    fn payload<'a>(&self, b: &mut Bytes<'a>, bytes: usize) -> Result<Vec<u8>, VdbError> {
        if self.compression & (BLOSC | ZIP) == 0 {
            return Ok(b.take(bytes, "a node's values")?.to_vec());
        }
        let at = b.pos();
        let size = b.i64("a compressed chunk's size")?;
        if size <= 0 {
            let n = size.unsigned_abs();
            if n != bytes as u64 {
                return Err(VdbError::Corrupt(format!(
                    "a raw chunk at byte {at} holds {n} bytes where the node needs {bytes}"
                )));
            }
            return Ok(b.take(bytes, "a node's values")?.to_vec());
        }
        let n = usize::try_from(size).unwrap_or(usize::MAX);
        let chunk = b.take(n, "a compressed chunk")?;
        let out = if self.compression & BLOSC != 0 {
            crate::blosc::decompress(chunk, bytes)
        } else {
            unzip(chunk, bytes)
        };
        out.map_err(|why| VdbError::Corrupt(format!("the compressed chunk at byte {at}: {why}")))
    }
}

/// A zlib chunk holding at least `bytes` bytes: the first `bytes` of it.
fn unzip(chunk: &[u8], bytes: usize) -> Result<Vec<u8>, String> {
    let mut out = vec![0u8; bytes];
    flate2::read::ZlibDecoder::new(chunk)
        .read_exact(&mut out)
        .map_err(|e| format!("zlib: {e}"))?;
    Ok(out)
}

/// One little-endian value of `width` bytes: 2 (half), 4 (f32) or 8 (f64).
fn decode(c: &[u8], width: usize) -> f64 {
    match width {
        2 => f64::from(half::f16::from_bits(u16::from_le_bytes([c[0], c[1]])).to_f32()),
        4 => f64::from(f32::from_le_bytes([c[0], c[1], c[2], c[3]])),
        _ => f64::from_le_bytes(std::array::from_fn(|i| c[i])),
    }
}
