//! Shared by the command-line tests.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Runs the `photometeor` binary under test in `cwd`.
pub fn photometeor(args: &[&str], cwd: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_photometeor"))
        .args(args)
        .current_dir(cwd)
        .output()
        .expect("running photometeor")
}

/// A fresh, empty directory `name` under the tests' temporary directory.
pub fn workdir(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}
