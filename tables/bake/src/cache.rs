//! The bake cache: one record per field under `DIR/.cache/<hash>.bin`, keyed by the hash of
//! every input that changes the field's numbers ([`content_hash`]).
//!
//! A record carries the key it was computed for and a SHA-256 of its payload; a record whose
//! key or checksum does not match, or that does not decode, is reported and recomputed, never
//! used.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use crate::error::BakeError;
use crate::plan::BakePlan;
use crate::scene::Field;

/// Version of everything that changes a baked number; part of every cache key.
pub const COMPUTE_VERSION: u32 = 14;

/// Version of the record layout; a record of another layout is recomputed.
const RECORD_LAYOUT: u32 = 4;

/// Hash of every input that affects the field's result, lowercase hex.
pub fn content_hash(plan: &BakePlan, field: &Field) -> String {
    let key = serde_json::json!({
        "compute_version": COMPUTE_VERSION,
        "field": field,
        "spectral": plan.scene.spectral,
        "theta_step_deg": plan.scene.theta_step_deg,
        "n_max": plan.scene.n_max,
        "poisson_max_depth": plan.scene.poisson_max_depth,
        "knobs": plan.knobs,
    });
    hex(&Sha256::digest(key.to_string().as_bytes()))
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// The cache file of a field with content hash `hash` in bake directory `dir`.
pub fn record_path(dir: &Path, hash: &str) -> PathBuf {
    dir.join(".cache").join(format!("{hash}.bin"))
}

#[derive(Serialize, Deserialize)]
struct Envelope {
    layout: u32,
    key: String,
    sha256: String,
    payload: Vec<u8>,
}

/// What reading a record found.
#[derive(Debug)]
pub enum Lookup<T> {
    /// No record for this key.
    Missing,
    /// A record that matches its key and checksum.
    Hit(T),
    /// A record that cannot be used (why); it is recomputed and overwritten.
    Rejected(String),
}

/// Reads the record of `key` at `path`.
pub fn read<T: for<'de> Deserialize<'de>>(path: &Path, key: &str) -> Lookup<T> {
    let bytes = match format::read_regular_file(path, 1 << 30) {
        Ok(b) => b,
        Err((_, e)) if e.kind() == std::io::ErrorKind::NotFound => return Lookup::Missing,
        Err((op, e)) => return Lookup::Rejected(format!("{op}: {e}")),
    };
    let config = bincode::config::standard();
    let Ok((envelope, _)) = bincode::serde::decode_from_slice::<Envelope, _>(&bytes, config) else {
        return Lookup::Rejected("not a cache record of this version".into());
    };
    if envelope.layout != RECORD_LAYOUT {
        return Lookup::Rejected(format!("record layout {}", envelope.layout));
    }
    if envelope.key != key {
        return Lookup::Rejected(format!(
            "it was computed for key {}, not {key}",
            envelope.key
        ));
    }
    if hex(&Sha256::digest(&envelope.payload)) != envelope.sha256 {
        return Lookup::Rejected("its checksum does not match its contents".into());
    }
    match bincode::serde::decode_from_slice::<T, _>(&envelope.payload, config) {
        Ok((value, _)) => Lookup::Hit(value),
        Err(e) => Lookup::Rejected(format!("the payload does not decode: {e}")),
    }
}

/// Writes the record of `key` to `path` atomically.
pub fn write<T: Serialize>(path: &Path, key: &str, value: &T) -> Result<(), BakeError> {
    let config = bincode::config::standard();
    let encode_error = |e: bincode::error::EncodeError| BakeError::Io {
        path: path.to_path_buf(),
        op: "encoding the cache record",
        source: std::io::Error::other(e.to_string()),
    };
    let payload = bincode::serde::encode_to_vec(value, config).map_err(encode_error)?;
    let envelope = Envelope {
        layout: RECORD_LAYOUT,
        key: key.to_string(),
        sha256: hex(&Sha256::digest(&payload)),
        payload,
    };
    let bytes = bincode::serde::encode_to_vec(&envelope, config).map_err(encode_error)?;
    format::write_file_atomically(path, &bytes).map_err(|(op, source)| BakeError::Io {
        path: path.to_path_buf(),
        op,
        source,
    })
}
