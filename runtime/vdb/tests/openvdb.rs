//! The reader against the OpenVDB library itself: files written by Debian's python3-openvdb
//! and rewritten by its vdb_tool (`write_cases.py`, run here; `scripts/test` installs both),
//! read back to the library's own active voxel count, bounding box, leaf count, background,
//! transform and values; bad files refused by name.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// The cases, written once per test binary.
fn cases() -> &'static (PathBuf, serde_json::Value) {
    static CASES: OnceLock<(tempfile::TempDir, PathBuf, serde_json::Value)> = OnceLock::new();
    let (_, dir, json) = CASES.get_or_init(|| {
        let tmp = tempfile::tempdir().unwrap();
        let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/write_cases.py");
        let out = std::process::Command::new("/usr/bin/python3")
            .arg(&script)
            .arg(tmp.path())
            .output()
            .expect("running /usr/bin/python3 (scripts/test installs python3-openvdb)");
        assert!(
            out.status.success(),
            "write_cases.py failed (scripts/test installs python3-openvdb and \
             libopenvdb-tools):\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let json: serde_json::Value =
            serde_json::from_slice(&std::fs::read(tmp.path().join("cases.json")).unwrap()).unwrap();
        let dir = tmp.path().to_path_buf();
        (tmp, dir, json)
    });
    // The pair without the TempDir, which lives as long as the process.
    static VIEW: OnceLock<(PathBuf, serde_json::Value)> = OnceLock::new();
    VIEW.get_or_init(|| (dir.clone(), json.clone()))
}

fn read(file: &str, grid: &str) -> Result<vdb::Grid, vdb::VdbError> {
    let bytes = std::fs::read(cases().0.join(file)).unwrap();
    vdb::Archive::parse(&bytes)?.read(grid, 1 << 28)
}

fn ints(v: &serde_json::Value) -> [i32; 3] {
    std::array::from_fn(|a| v[a].as_i64().unwrap() as i32)
}

fn floats(v: &serde_json::Value) -> [f64; 3] {
    std::array::from_fn(|a| v[a].as_f64().unwrap())
}

/// Every case read back to the library's answers, its values bit for bit (a half grid's
/// to the library's values rounded to half, as numpy rounds them).
#[test]
fn every_case_reads_back_as_the_library_wrote_it() {
    let (dir, json) = cases();
    let cases = json["cases"].as_object().unwrap();
    assert!(cases.len() >= 9);
    for (name, c) in cases {
        let g = read(c["file"].as_str().unwrap(), c["grid"].as_str().unwrap())
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(
            g.active_voxels,
            c["active_voxels"].as_u64().unwrap(),
            "{name}"
        );
        assert_eq!(g.index_min, ints(&c["index_min"]), "{name}");
        assert_eq!(g.index_max, ints(&c["index_max"]), "{name}");
        assert_eq!(g.leaves as u64, c["leaves"].as_u64().unwrap(), "{name}");
        assert_eq!(
            f64::from(g.background),
            c["background"].as_f64().unwrap(),
            "{name}"
        );
        assert_eq!(g.half, c["half"].as_bool().unwrap(), "{name}");
        assert_eq!(g.transform.scale, floats(&c["voxel_size"]), "{name}");
        assert_eq!(g.transform.translation, floats(&c["origin_m"]), "{name}");
        let codec = c["codec"].as_str().unwrap();
        let expected_codec = match codec {
            "active" => "none + active mask",
            "none" => "none",
            other => &format!("{other} + active mask"),
        };
        assert_eq!(g.compression, expected_codec, "{name}");
        let raw = std::fs::read(dir.join(c["raw"].as_str().unwrap())).unwrap();
        let want: Vec<u32> = raw
            .chunks_exact(4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        assert_eq!(g.values.len(), want.len(), "{name}");
        let differ = g
            .values
            .iter()
            .zip(&want)
            .filter(|(a, b)| a.to_bits() != **b)
            .count();
        assert_eq!(
            differ,
            0,
            "{name}: {differ} of {} values differ",
            want.len()
        );
    }
}

/// Files the reader must refuse, each with its reason named.
#[test]
fn bad_files_are_refused_with_the_reason() {
    let refuse = |file: &str, grid: &str, words: &str| {
        let e = read(file, grid).expect_err(file).to_string();
        assert!(e.contains(words), "{file}: {e:?} does not say {words:?}");
    };
    refuse("two_grids.vdb", "smoke", "\"density\", \"temperature\"");
    refuse("vector.vdb", "density", "Tree_vec3s_5_4_3");
    refuse("level_set.vdb", "density", "level set");
    refuse("frustum.vdb", "density", "NonlinearFrustumMap");
    let text = b"not a vdb at all, just some text".to_vec();
    assert!(matches!(
        vdb::Archive::parse(&text),
        Err(vdb::VdbError::NotVdb)
    ));
    let whole = std::fs::read(cases().0.join("dense.vdb")).unwrap();
    for cut in [10, 100, whole.len() / 2, whole.len() - 1] {
        let e = vdb::Archive::parse(&whole[..cut]).and_then(|a| a.read("density", 1 << 28));
        let e = e.expect_err("a truncated file").to_string();
        assert!(
            e.contains("truncated") || e.contains("past the file's end"),
            "cut at {cut}: {e}"
        );
    }
    let e = read("dense.vdb", "density")
        .map(|_| ())
        .and_then(|()| vdb::Archive::parse(&whole)?.read("density", 100));
    assert!(
        e.unwrap_err()
            .to_string()
            .contains("19 × 11 × 15 = 3135 voxels")
    );
}
