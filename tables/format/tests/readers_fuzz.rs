//! Property tests of every reader of a bake — `manifest.json`, a field's EXR and its three
//! side tables — on mutated copies of a real bake's files (`tests/data/fuzz-seed`, baked from
//! its `scene.toml`): bits flipped anywhere or in the header, truncations, header fields (data
//! window, attribute sizes, chunk offsets and sizes) and manifest values set to huge, negative
//! or mistyped values. Each case must end in `Ok` or an error — no panic, no abort — and no
//! single allocation may exceed the stated bound: for an EXR of L bytes twice
//! `format::exr::decoded_bound(L)` (its samples as f64) or L, plus 1 MiB for the exr crate's
//! reading buffers; for a manifest 32 bytes per byte of JSON plus 1 MiB.
//!
//! CI runs `PHOTOMETEOR_FUZZ_CASES` cases per reader (default 256, a few seconds); the long run
//! and its result are in docs/accuracy.md ("Readers under mutation"). Failing cases proptest
//! finds are kept in `tests/data/fuzz-regressions.txt` and replayed first.

use std::cell::Cell;
use std::path::{Path, PathBuf};

use format::exr::{decode_field_exr, decoded_bound};
use format::{decode_biri_exr, decode_poisson_exr, decode_single_exr, parse_manifest};
use proptest::prelude::*;
use proptest::test_runner::TestRunner;

#[path = "../../../tests/common/fuzz.rs"]
mod fuzz;
use fuzz::largest_allocation;

/// Slack for fixed-size buffers of the readers (the exr crate reads its offset table in steps
/// of 65535 entries, 512 KiB).
const SLACK: usize = 1 << 20;

/// The stated bound of one allocation while an EXR of `len` bytes is read.
fn exr_bound(len: usize) -> usize {
    (2 * decoded_bound(len as u64) as usize).max(len) + SLACK
}

/// The stated bound of one allocation while a manifest of `len` bytes is read.
fn manifest_bound(len: usize) -> usize {
    32 * len + SLACK
}

fn seed_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/fuzz-seed")
}

fn seed(name: &str) -> Vec<u8> {
    std::fs::read(seed_dir().join(name)).unwrap()
}

fn runner() -> TestRunner {
    fuzz::runner("tests/data/fuzz-regressions.txt")
}

// ---- EXR mutations ----

/// Where an EXR's header and chunk table keep their sizes: the i32 fields (attribute sizes,
/// box2i coordinates, ints, chunk line numbers and sizes) and the u64 chunk offsets.
struct ExrLayout {
    header_end: usize,
    i32_fields: Vec<usize>,
    u64_fields: Vec<usize>,
}

fn i32_at(bytes: &[u8], at: usize) -> i32 {
    i32::from_le_bytes(bytes[at..at + 4].try_into().unwrap())
}

/// Walks the header records `name\0type\0size value` of a single-part scanline EXR (OpenEXR
/// file layout), then its offset table and chunk headers.
fn exr_layout(bytes: &[u8]) -> ExrLayout {
    let mut pos = 8;
    let mut i32_fields = Vec::new();
    let mut height = 0;
    while bytes[pos] != 0 {
        let name_end = pos + bytes[pos..].iter().position(|&b| b == 0).unwrap();
        let name = &bytes[pos..name_end];
        let type_end = name_end + 1 + bytes[name_end + 1..].iter().position(|&b| b == 0).unwrap();
        let kind = &bytes[name_end + 1..type_end];
        let size_at = type_end + 1;
        let size = i32_at(bytes, size_at) as usize;
        i32_fields.push(size_at);
        let value = size_at + 4;
        match kind {
            b"box2i" => {
                i32_fields.extend((0..4).map(|i| value + 4 * i));
                if name == b"dataWindow" {
                    height = (i32_at(bytes, value + 12) - i32_at(bytes, value + 4) + 1) as usize;
                }
            }
            b"int" => i32_fields.push(value),
            b"chlist" => {
                // name\0, pixel type, pLinear + reserved, x and y sampling per channel.
                let mut c = value;
                while bytes[c] != 0 {
                    c += bytes[c..].iter().position(|&b| b == 0).unwrap() + 1;
                    i32_fields.extend([c, c + 8, c + 12]);
                    c += 16;
                }
            }
            _ => {}
        }
        pos = value + size;
    }
    let header_end = pos + 1;
    let chunks = height.div_ceil(16);
    let u64_fields: Vec<usize> = (0..chunks).map(|i| header_end + 8 * i).collect();
    for &at in &u64_fields {
        let offset = u64::from_le_bytes(bytes[at..at + 8].try_into().unwrap()) as usize;
        i32_fields.extend([offset, offset + 4]);
    }
    ExrLayout {
        header_end,
        i32_fields,
        u64_fields,
    }
}

/// One change to a file's bytes; positions are taken modulo what they index.
#[derive(Debug, Clone)]
enum Mutation {
    /// Flips bit `bit` of byte `at`.
    Flip { at: usize, bit: u8 },
    /// Flips a bit inside the header (EXR) or the first KiB (JSON).
    FlipHeader { at: usize, bit: u8 },
    /// Keeps the first `at` bytes.
    Truncate { at: usize },
    /// Sets byte `at`.
    Byte { at: usize, value: u8 },
    /// Sets one of the header's i32 size fields (EXR) or one of the manifest's values (JSON).
    Field { which: usize, value: i64 },
    /// Sets one of the chunk offsets (EXR).
    Offset { which: usize, value: u64 },
}

/// Values that break sizes: zero, negatives, one bit past the real values, huge.
fn interesting_i64() -> impl Strategy<Value = i64> {
    prop_oneof![
        Just(0i64),
        Just(1),
        Just(-1),
        Just(1000),
        Just(1 << 16),
        Just((1 << 27) + 1000),
        Just(1 << 30),
        Just(i64::from(i32::MAX)),
        Just(i64::from(i32::MIN)),
        Just(i64::MAX),
        any::<i32>().prop_map(i64::from),
    ]
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        (any::<usize>(), 0u8..8).prop_map(|(at, bit)| Mutation::Flip { at, bit }),
        (any::<usize>(), 0u8..8).prop_map(|(at, bit)| Mutation::FlipHeader { at, bit }),
        any::<usize>().prop_map(|at| Mutation::Truncate { at }),
        (any::<usize>(), any::<u8>()).prop_map(|(at, value)| Mutation::Byte { at, value }),
        (any::<usize>(), interesting_i64())
            .prop_map(|(which, value)| Mutation::Field { which, value }),
        (
            any::<usize>(),
            prop_oneof![
                Just(0u64),
                Just(8),
                Just(u64::MAX),
                Just(1 << 40),
                any::<u64>()
            ]
        )
            .prop_map(|(which, value)| Mutation::Offset { which, value }),
    ]
}

fn mutate_exr(seed: &[u8], layout: &ExrLayout, mutations: &[Mutation]) -> Vec<u8> {
    let mut b = seed.to_vec();
    for m in mutations {
        if b.is_empty() {
            break;
        }
        match *m {
            Mutation::Flip { at, bit } => {
                let at = at % b.len();
                b[at] ^= 1 << bit;
            }
            Mutation::FlipHeader { at, bit } => {
                let at = at % layout.header_end.min(b.len());
                b[at] ^= 1 << bit;
            }
            Mutation::Truncate { at } => b.truncate(at % b.len()),
            Mutation::Byte { at, value } => {
                let at = at % b.len();
                b[at] = value;
            }
            Mutation::Field { which, value } => {
                let at = layout.i32_fields[which % layout.i32_fields.len()];
                if at + 4 <= b.len() {
                    b[at..at + 4].copy_from_slice(&(value as i32).to_le_bytes());
                }
            }
            Mutation::Offset { which, value } => {
                if !layout.u64_fields.is_empty() {
                    let at = layout.u64_fields[which % layout.u64_fields.len()];
                    if at + 8 <= b.len() {
                        b[at..at + 8].copy_from_slice(&value.to_le_bytes());
                    }
                }
            }
        }
    }
    b
}

/// Runs `read` on mutated copies of the seed `name`: no panic, no allocation over the bound.
fn fuzz_exr(name: &str, read: fn(&[u8], &Path) -> bool) {
    let seed = seed(name);
    let layout = exr_layout(&seed);
    let path = PathBuf::from(name);
    assert!(read(&seed, &path), "the unmutated {name} must read");
    let worst = Cell::new((0usize, 0usize));
    let read_ok = Cell::new(0u32);
    runner()
        .run(&proptest::collection::vec(mutation(), 1..4), |mutations| {
            let bytes = mutate_exr(&seed, &layout, &mutations);
            let largest = largest_allocation(|| {
                if read(&bytes, &path) {
                    read_ok.set(read_ok.get() + 1);
                }
            });
            let bound = exr_bound(bytes.len());
            prop_assert!(
                largest <= bound,
                "{name}: an allocation of {largest} bytes, over the bound {bound} for {} bytes",
                bytes.len()
            );
            if largest > worst.get().0 {
                worst.set((largest, bound));
            }
            Ok(())
        })
        .unwrap();
    eprintln!(
        "{name}: {} cases ({} still read), largest allocation {} bytes (its bound {})",
        fuzz::cases(),
        read_ok.get(),
        worst.get().0,
        worst.get().1
    );
}

#[test]
fn field_exr_reader_survives_mutations() {
    fuzz_exr("cloud.exr", |b, p| decode_field_exr(b, p).is_ok());
}

#[test]
fn single_scattering_reader_survives_mutations() {
    fuzz_exr("cloud.single.exr", |b, p| decode_single_exr(b, p).is_ok());
}

#[test]
fn poisson_reader_survives_mutations() {
    fuzz_exr("cloud.poisson.exr", |b, p| decode_poisson_exr(b, p).is_ok());
}

#[test]
fn biri_reader_survives_mutations() {
    fuzz_exr("cloud.biri.exr", |b, p| decode_biri_exr(b, p).is_ok());
}

// ---- manifest mutations ----

/// Every value's JSON pointer in `v` (objects' members and arrays' elements, recursively).
fn pointers(v: &serde_json::Value, at: String, out: &mut Vec<String>) {
    match v {
        serde_json::Value::Object(m) => {
            for (k, x) in m {
                let p = format!("{at}/{}", k.replace('~', "~0").replace('/', "~1"));
                out.push(p.clone());
                pointers(x, p, out);
            }
        }
        serde_json::Value::Array(a) => {
            for (i, x) in a.iter().enumerate() {
                let p = format!("{at}/{i}");
                out.push(p.clone());
                pointers(x, p, out);
            }
        }
        _ => {}
    }
}

/// The replacement values of a manifest field: huge, negative, tiny, mistyped, missing.
fn replacement(value: i64) -> serde_json::Value {
    use serde_json::json;
    match value.rem_euclid(12) {
        0 => json!(1e308),
        1 => json!(-1.0),
        2 => json!(0),
        3 => json!(u64::MAX),
        4 => json!(5e-324),
        5 => json!("x"),
        6 => json!(null),
        7 => json!(true),
        8 => json!([]),
        9 => json!({}),
        10 => json!(1u64 << 40),
        _ => json!(value),
    }
}

fn mutate_manifest(
    seed: &serde_json::Value,
    pointers: &[String],
    mutations: &[Mutation],
) -> Vec<u8> {
    let mut v = seed.clone();
    let mut bytes_mutations = Vec::new();
    for m in mutations {
        match *m {
            Mutation::Field { which, value } => {
                if let Some(slot) = v.pointer_mut(&pointers[which % pointers.len()]) {
                    *slot = replacement(value);
                }
            }
            Mutation::Offset { which, .. } => {
                // Removes a member or element.
                let p = &pointers[which % pointers.len()];
                let (parent, last) = p.rsplit_once('/').unwrap();
                match v.pointer_mut(parent) {
                    Some(serde_json::Value::Object(m)) => {
                        m.remove(&last.replace("~1", "/").replace("~0", "~"));
                    }
                    Some(serde_json::Value::Array(a)) => {
                        if let Ok(i) = last.parse::<usize>()
                            && i < a.len()
                        {
                            a.remove(i);
                        }
                    }
                    _ => {}
                }
            }
            _ => bytes_mutations.push(m.clone()),
        }
    }
    let mut bytes = serde_json::to_vec_pretty(&v).unwrap();
    let header = ExrLayout {
        header_end: 1024,
        i32_fields: vec![0],
        u64_fields: vec![],
    };
    bytes = mutate_exr(&bytes, &header, &bytes_mutations);
    bytes
}

#[test]
fn manifest_reader_survives_mutations() {
    let seed_bytes = seed("manifest.json");
    let path = PathBuf::from("manifest.json");
    parse_manifest(&seed_bytes, &path).expect("the unmutated manifest must read");
    let seed: serde_json::Value = serde_json::from_slice(&seed_bytes).unwrap();
    let mut all = Vec::new();
    pointers(&seed, String::new(), &mut all);
    let worst = Cell::new((0usize, 0usize));
    let read_ok = Cell::new(0u32);
    runner()
        .run(&proptest::collection::vec(mutation(), 1..4), |mutations| {
            let bytes = mutate_manifest(&seed, &all, &mutations);
            let largest = largest_allocation(|| {
                if parse_manifest(&bytes, &path).is_ok() {
                    read_ok.set(read_ok.get() + 1);
                }
            });
            let bound = manifest_bound(bytes.len());
            prop_assert!(
                largest <= bound,
                "manifest: an allocation of {largest} bytes, over the bound {bound} for {} bytes",
                bytes.len()
            );
            if largest > worst.get().0 {
                worst.set((largest, bound));
            }
            Ok(())
        })
        .unwrap();
    eprintln!(
        "manifest.json: {} cases ({} still read), largest allocation {} bytes (its bound {})",
        fuzz::cases(),
        read_ok.get(),
        worst.get().0,
        worst.get().1
    );
}

// ---- the reproduction that started these tests ----

/// One flipped bit (bit 27 of the data window's x max) in a single-scattering table declares a
/// 134 218 729 × 3 image: the reader used to allocate 1.6 GB for it (16.6 GB in the default
/// bake, where it aborted), and now refuses it from the header, naming both sizes.
#[test]
fn a_flipped_data_window_bit_is_refused_before_any_allocation() {
    let mut bytes = seed("cloud.single.exr");
    let layout = exr_layout(&bytes);
    let window = b"dataWindow\0box2i\0";
    let at = bytes
        .windows(window.len())
        .position(|w| w == window)
        .unwrap()
        + window.len()
        + 4;
    assert!(layout.i32_fields.contains(&(at + 8)));
    bytes[at + 8 + 3] ^= 0x08;
    let mut result = None;
    let largest = largest_allocation(|| {
        result = Some(decode_single_exr(&bytes, Path::new("cloud.single.exr")));
    });
    let e = result.unwrap().unwrap_err().to_string();
    assert!(
        e.contains("cloud.single.exr")
            && e.contains("134217759 × 3")
            && e.contains("1128-byte file"),
        "{e}"
    );
    assert!(largest < 1 << 20, "{largest} bytes allocated");
}
