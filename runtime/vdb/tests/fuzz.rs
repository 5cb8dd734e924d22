//! Mutated OpenVDB files through the reader: no panic, no abort, and no allocation beyond a
//! bound set by the file's size and the dense box allowed.
//!
//! The seeds are the files the OpenVDB library writes for `openvdb.rs` (`write_cases.py`);
//! each case flips, overwrites (with the values lengths and counts are most often corrupted
//! to), deletes, duplicates or truncates bytes of one: 10⁵ cases (6 s), or
//! `PHOTOMETEOR_FUZZ_CASES=N cargo test -p photometeor-vdb --test fuzz -- --nocapture`.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

/// The system allocator, counting the bytes live and their peak.
struct Counting;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

// SAFETY: every call is forwarded to the system allocator unchanged; only counters change.
#[allow(unsafe_code)]
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let now = LIVE.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
        PEAK.fetch_max(now, Ordering::Relaxed);
        // SAFETY: the caller's layout, passed on.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
        // SAFETY: a pointer this allocator gave out, with its layout.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// SplitMix64: a small deterministic generator.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// One to four mutations of `bytes`.
fn mutate(bytes: &mut Vec<u8>, rng: &mut Rng) {
    const WORDS: [u64; 9] = [
        0,
        1,
        2,
        7,
        0x7FFF_FFFF,
        0xFFFF_FFFF,
        1 << 40,
        u64::MAX,
        1 << 63,
    ];
    for _ in 0..1 + rng.below(4) {
        let at = rng.below(bytes.len());
        match rng.below(6) {
            0 => bytes[at] ^= 1 << rng.below(8),
            1 => bytes[at] = rng.next() as u8,
            2 => {
                let w = WORDS[rng.below(WORDS.len())].to_le_bytes();
                let n = if rng.below(2) == 0 { 4 } else { 8 };
                for (k, &b) in w.iter().take(n).enumerate() {
                    if let Some(x) = bytes.get_mut(at + k) {
                        *x = b;
                    }
                }
            }
            3 => {
                let n = rng.below(64).min(bytes.len() - at);
                bytes.drain(at..at + n);
            }
            4 => {
                let n = rng.below(64).min(bytes.len() - at);
                let piece: Vec<u8> = bytes[at..at + n].to_vec();
                bytes.splice(at..at, piece);
            }
            _ => bytes.truncate(at.max(1)),
        }
        if bytes.is_empty() {
            bytes.push(0);
        }
    }
}

#[test]
fn mutated_files_are_refused_or_read_within_the_bound() {
    let dir = tempfile::tempdir().unwrap();
    let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/write_cases.py");
    let out = std::process::Command::new("/usr/bin/python3")
        .arg(&script)
        .arg(dir.path())
        .output()
        .expect("running /usr/bin/python3 (scripts/test installs python3-openvdb)");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let seeds: Vec<Vec<u8>> = [
        "dense.vdb",
        "dense_zip.vdb",
        "dense_none.vdb",
        "dense_active.vdb",
        "half.vdb",
        "half_zip.vdb",
        "tiles.vdb",
        "tiles_zip.vdb",
        "transformed.vdb",
        "two_grids.vdb",
    ]
    .iter()
    .map(|f| std::fs::read(dir.path().join(f)).unwrap())
    .collect();
    let cases: usize = std::env::var("PHOTOMETEOR_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(100_000);
    // The dense box allowed: 2^16 voxels (256 KiB as f32); the seeds' boxes fit it.
    const MAX_VALUES: u64 = 1 << 16;
    let largest = seeds.iter().map(Vec::len).max().unwrap();
    let (mut rng, mut read, mut refused, mut worst) = (Rng(0x5EED), 0, 0, 0usize);
    for case in 0..cases {
        let mut bytes = seeds[case % seeds.len()].clone();
        mutate(&mut bytes, &mut rng);
        let base = LIVE.load(Ordering::Relaxed);
        PEAK.store(base, Ordering::Relaxed);
        let outcome = std::panic::catch_unwind(|| {
            vdb::Archive::parse(&bytes).and_then(|a| {
                let name = a.names().first().cloned().unwrap_or_default();
                a.read(&name, MAX_VALUES)
            })
        });
        worst = worst.max(PEAK.load(Ordering::Relaxed) - base);
        match outcome {
            Ok(Ok(_)) => read += 1,
            Ok(Err(_)) => refused += 1,
            Err(_) => panic!("case {case} panicked"),
        }
    }
    // The bound: a few times the file (its node masks and leaf list) plus the dense box as
    // f32 and f64 scratch, far below what an unchecked length (up to 2^64) would ask.
    let bound = 8 * largest + 16 * MAX_VALUES as usize + (1 << 20);
    eprintln!(
        "{cases} mutated files: {read} read, {refused} refused, no panic; the most memory one \
         took {worst} bytes (bound {bound})"
    );
    assert!(
        worst <= bound,
        "a case took {worst} bytes, over the bound {bound}"
    );
    assert!(read > 0 && refused > 0);
}
