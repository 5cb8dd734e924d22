//! Blosc chunks, decompressed by c-blosc (the library OpenVDB itself links), the one place
//! this crate calls C.
#![allow(unsafe_code)]

use std::ffi::c_void;

/// A blosc chunk holding exactly `bytes` bytes, decompressed.
///
/// c-blosc's `blosc_cbuffer_validate` checks the chunk's header against the chunk's length
/// before anything is decompressed ("guarantees that it is safe to attempt decompression"),
/// and `blosc_decompress_ctx` never writes past the size it is given, which is `bytes`, and
/// which the header must state.
pub(crate) fn decompress(chunk: &[u8], bytes: usize) -> Result<Vec<u8>, String> {
    let mut nbytes = 0usize;
    // SAFETY: the pointer and length are those of a live slice; `nbytes` is a valid out
    // pointer. c-blosc reads at most `chunk.len()` bytes.
    let ok = unsafe {
        blosc_src::blosc_cbuffer_validate(chunk.as_ptr().cast(), chunk.len(), &mut nbytes)
    };
    if ok != 0 {
        return Err("not a valid blosc chunk".into());
    }
    if nbytes != bytes {
        return Err(format!(
            "blosc says it holds {nbytes} bytes where the node needs {bytes}"
        ));
    }
    let mut out = vec![0u8; bytes];
    // SAFETY: the chunk was validated above for its own length; `out` is a live buffer of
    // `bytes` bytes, and c-blosc writes at most `destsize` = `bytes` bytes into it.
    let n = unsafe {
        blosc_src::blosc_decompress_ctx(
            chunk.as_ptr().cast(),
            out.as_mut_ptr().cast::<c_void>(),
            bytes,
            1,
        )
    };
    if usize::try_from(n).ok() != Some(bytes) {
        return Err(format!("blosc could not decompress it (returned {n})"));
    }
    Ok(out)
}
