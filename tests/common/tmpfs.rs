//! A small tmpfs for the tests that fill a disk; included with
//! `#[path = "common/tmpfs.rs"] mod tmpfs;`.

use std::path::{Path, PathBuf};
use std::process::Command;

/// A tmpfs of `size` (mount's notation, e.g. "16k") mounted on `dir` until the guard drops,
/// or `None` (said on stderr) where this machine does not let the tests mount one.
pub fn mount_tmpfs(dir: &Path, size: &str) -> Option<Unmount> {
    let mounted = Command::new("mount")
        .args(["-t", "tmpfs", "-o", &format!("size={size}"), "tmpfs"])
        .arg(dir)
        .output();
    match mounted {
        Ok(out) if out.status.success() => Some(Unmount(dir.to_path_buf())),
        Ok(out) => {
            eprintln!(
                "skipped: cannot mount a tmpfs here ({})",
                String::from_utf8_lossy(&out.stderr).trim()
            );
            None
        }
        Err(e) => {
            eprintln!("skipped: cannot run mount ({e})");
            None
        }
    }
}

/// Unmounts its directory when dropped.
pub struct Unmount(PathBuf);

impl Drop for Unmount {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg(&self.0).status();
    }
}
