//! Shared by the command-line tests.

use std::path::Path;
use std::process::{Command, Output};

/// Runs the `photometeor` binary under test in `cwd`.
pub fn photometeor(args: &[&str], cwd: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_photometeor"))
        .args(args)
        .current_dir(cwd)
        .output()
        .expect("running photometeor")
}
