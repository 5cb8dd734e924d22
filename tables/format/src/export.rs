//! The files `photometeor export` writes for other programs: a KTX 2.0 texture (Bevy's chromatic
//! phase curve), an N × 1 RGBA EXR of the same curve, and NumPy `.npy` arrays. Writers only:
//! what the values mean (the cos θ grid, the resampling and its cost) is `runtime::export`'s.
//!
//! - [`ktx2_rgba32f_bytes`]: KTX 2.0 (Khronos, *KTX File Format Specification* 2.0), one 2D
//!   image of `width` × 1 texels, `VK_FORMAT_R32G32B32A32_SFLOAT`, one mip level, no
//!   supercompression, a basic data format descriptor (Khronos Data Format Specification 1.3:
//!   RGBSDA, BT.709 primaries, linear transfer, four 32-bit signed-float samples) and the
//!   key/value pairs given (after `KTXwriter`), sorted by key as the specification requires.
//! - [`curve_exr_bytes`]: the same texels as a `width` × 1 scanline EXR with channels R, G, B,
//!   A (32-bit float, ZIP), header attributes as given.
//! - [`npy_f64_bytes`]: NumPy's format 1.0, little-endian f64, C order.

use std::collections::BTreeMap;
use std::path::PathBuf;

use exr::meta::attribute::{AttributeValue, Text};

use crate::exr::{IoError, encode_layer, utf8_text};

/// `VK_FORMAT_R32G32B32A32_SFLOAT`.
pub const VK_FORMAT_R32G32B32A32_SFLOAT: u32 = 109;

/// The KTX 2.0 file identifier.
pub const KTX2_IDENTIFIER: [u8; 12] = [
    0xAB, 0x4B, 0x54, 0x58, 0x20, 0x32, 0x30, 0xBB, 0x0D, 0x0A, 0x1A, 0x0A,
];

fn push_u32(out: &mut Vec<u8>, v: u32) {
    out.extend_from_slice(&v.to_le_bytes());
}

fn push_u64(out: &mut Vec<u8>, v: u64) {
    out.extend_from_slice(&v.to_le_bytes());
}

fn pad_to(out: &mut Vec<u8>, align: usize) {
    while !out.len().is_multiple_of(align) {
        out.push(0);
    }
}

/// The basic data format descriptor of R32G32B32A32_SFLOAT, linear, BT.709 primaries.
fn rgba32f_dfd() -> Vec<u8> {
    const SAMPLES: u32 = 4;
    let block_size = 24 + 16 * SAMPLES;
    let mut d = Vec::new();
    push_u32(&mut d, 4 + block_size); // dfdTotalSize
    push_u32(&mut d, 0); // vendorId 0 (Khronos), descriptorType 0 (basic)
    push_u32(&mut d, 2 | (block_size << 16)); // versionNumber 2, descriptorBlockSize
    // colorModel RGBSDA (1), colorPrimaries BT709 (1), transferFunction LINEAR (1), flags 0
    d.extend_from_slice(&[1, 1, 1, 0]);
    d.extend_from_slice(&[0, 0, 0, 0]); // texelBlockDimension: 1×1×1×1
    d.extend_from_slice(&[16, 0, 0, 0, 0, 0, 0, 0]); // bytesPlane0 = 16
    for (i, channel) in [0u8, 1, 2, 15].into_iter().enumerate() {
        // bitOffset, bitLength − 1, channelType | FLOAT (0x80) | SIGNED (0x40)
        d.extend_from_slice(&((32 * i) as u16).to_le_bytes());
        d.push(31);
        d.push(channel | 0xC0);
        d.extend_from_slice(&[0, 0, 0, 0]); // samplePosition
        push_u32(&mut d, (-1.0f32).to_bits()); // sampleLower
        push_u32(&mut d, 1.0f32.to_bits()); // sampleUpper
    }
    d
}

/// A KTX 2.0 file of one `texels.len()` × 1 RGBA32F image (module docs). `writer` is the
/// `KTXwriter` value; `metadata` further key/value pairs (UTF-8, no NUL).
pub fn ktx2_rgba32f_bytes(texels: &[[f32; 4]], writer: &str, metadata: &[(&str, &str)]) -> Vec<u8> {
    let mut kv: BTreeMap<&str, &str> = metadata.iter().copied().collect();
    kv.insert("KTXwriter", writer);
    let mut kvd = Vec::new();
    for (k, v) in &kv {
        let len = k.len() + 1 + v.len() + 1;
        push_u32(&mut kvd, len as u32);
        kvd.extend_from_slice(k.as_bytes());
        kvd.push(0);
        kvd.extend_from_slice(v.as_bytes());
        kvd.push(0);
        pad_to(&mut kvd, 4);
    }
    let dfd = rgba32f_dfd();
    let header_len = 12 + 9 * 4 + 4 * 4 + 2 * 8;
    let level_index_len = 3 * 8;
    let dfd_offset = header_len + level_index_len;
    let kvd_offset = dfd_offset + dfd.len();
    let data_len = texels.len() * 16;
    let mut out = Vec::with_capacity(kvd_offset + kvd.len() + 16 + data_len);
    out.extend_from_slice(&KTX2_IDENTIFIER);
    push_u32(&mut out, VK_FORMAT_R32G32B32A32_SFLOAT);
    push_u32(&mut out, 4); // typeSize
    push_u32(&mut out, texels.len() as u32); // pixelWidth
    push_u32(&mut out, 1); // pixelHeight: a 2D texture one texel high
    push_u32(&mut out, 0); // pixelDepth
    push_u32(&mut out, 0); // layerCount
    push_u32(&mut out, 1); // faceCount
    push_u32(&mut out, 1); // levelCount
    push_u32(&mut out, 0); // supercompressionScheme
    push_u32(&mut out, dfd_offset as u32);
    push_u32(&mut out, dfd.len() as u32);
    push_u32(&mut out, kvd_offset as u32);
    push_u32(&mut out, kvd.len() as u32);
    push_u64(&mut out, 0); // sgdByteOffset
    push_u64(&mut out, 0); // sgdByteLength
    // The level's data starts 16-aligned (lcm of the texel block size and 4).
    let data_offset = (kvd_offset + kvd.len()).div_ceil(16) * 16;
    push_u64(&mut out, data_offset as u64);
    push_u64(&mut out, data_len as u64);
    push_u64(&mut out, data_len as u64);
    out.extend_from_slice(&dfd);
    out.extend_from_slice(&kvd);
    pad_to(&mut out, 16);
    debug_assert_eq!(out.len(), data_offset);
    for t in texels {
        for v in t {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    out
}

/// A `texels.len()` × 1 EXR with channels R, G, B, A (module docs); `name` names it in errors.
pub fn curve_exr_bytes(
    name: &str,
    texels: &[[f32; 4]],
    attributes: &[(&str, &str)],
) -> Result<Vec<u8>, IoError> {
    let channels: Vec<(Text, Vec<f32>)> = ["A", "B", "G", "R"]
        .iter()
        .map(|&c| {
            let i = "RGBA".find(c).unwrap();
            (Text::from(c), texels.iter().map(|t| t[i]).collect())
        })
        .collect();
    let attributes = attributes
        .iter()
        .map(|&(k, v)| (k, AttributeValue::Text(utf8_text(v))))
        .collect();
    encode_layer((texels.len(), 1), channels, attributes).map_err(|source| IoError::Encode {
        path: PathBuf::from(name),
        source,
    })
}

/// A NumPy `.npy` of little-endian f64 in C order with this shape (written by `ndarray-npy`).
pub fn npy_f64_bytes(shape: &[usize], data: &[f64]) -> Vec<u8> {
    use ndarray_npy::WriteNpyExt;
    let array = ndarray::ArrayViewD::from_shape(ndarray::IxDyn(shape), data).expect("npy shape");
    let mut out = Vec::with_capacity(128 + 8 * data.len());
    array
        .write_npy(&mut out)
        .expect("writing to memory cannot fail");
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ktx2_layout_is_aligned_and_sized() {
        let texels: Vec<[f32; 4]> = (0..5).map(|i| [i as f32, 0.5, 0.25, 1.0]).collect();
        let bytes = ktx2_rgba32f_bytes(&texels, "test", &[("b", "2"), ("a", "1")]);
        assert_eq!(&bytes[..12], &KTX2_IDENTIFIER);
        let u64_at = |o: usize| u64::from_le_bytes(bytes[o..o + 8].try_into().unwrap());
        let offset = u64_at(80) as usize;
        assert_eq!(offset % 16, 0);
        assert_eq!(u64_at(88), 80);
        assert_eq!(bytes.len(), offset + 80);
        let first = f32::from_le_bytes(bytes[offset + 16..offset + 20].try_into().unwrap());
        assert_eq!(first, 1.0);
    }

    #[test]
    fn npy_header_is_padded_to_64() {
        let b = npy_f64_bytes(&[2, 3], &[0.0; 6]);
        let len = u16::from_le_bytes([b[8], b[9]]) as usize;
        assert_eq!((10 + len) % 64, 0);
        assert_eq!(b.len(), 10 + len + 48);
        assert!(
            std::str::from_utf8(&b[10..10 + len])
                .unwrap()
                .contains("(2, 3)")
        );
    }
}
