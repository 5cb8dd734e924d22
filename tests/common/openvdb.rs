//! The OpenVDB library's own files for the tests of `shape = "vdb"`.

use std::path::Path;

/// Writes the files `runtime/vdb/tests/write_cases.py` makes with the OpenVDB library (Debian's
/// python3-openvdb and vdb_tool, which scripts/test installs) into `dir`, and returns the
/// library's answers about them (its cases.json).
pub fn write_cases(dir: &Path) -> serde_json::Value {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("runtime/vdb/tests/write_cases.py");
    let out = std::process::Command::new("/usr/bin/python3")
        .arg(&script)
        .arg(dir)
        .output()
        .expect("running /usr/bin/python3 (scripts/test installs python3-openvdb)");
    assert!(
        out.status.success(),
        "write_cases.py failed (scripts/test installs python3-openvdb and libopenvdb-tools):\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&std::fs::read(dir.join("cases.json")).unwrap()).unwrap()
}
