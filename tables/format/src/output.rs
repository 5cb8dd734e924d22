//! Files a command writes where its user says (`--out`, `--png`, `--map`): one path for all of
//! them, so that none replaces what is not a file of its own.
//!
//! [`write_output`] writes only regular files, through [`crate::write_file_atomically`] (a
//! temporary file in the same directory, renamed into place: an error leaves nothing behind and
//! the target as it was), after [`check_output`]:
//! - an existing target that is not a regular file — a character or block device, a FIFO, a
//!   socket, a directory, a symbolic link to one of those or to nothing — is refused, naming
//!   it (a rename would otherwise turn `/dev/null` into a regular file);
//! - a symbolic link to a regular file is written through: the file it names is replaced;
//! - a target that is, or lies inside, one of the `protected` paths the caller names (the bake
//!   directory a command reads or writes, its input files) is refused, after resolving links
//!   and `..`, so `render --tables T --out T/manifest.json` cannot replace the bake it reads.
//!
//! A command checks its outputs before its work ([`check_output`], [`check_output_dir`]) and
//! writes them after; the write checks again.

use std::fs;
use std::io;
use std::path::{Component, Path, PathBuf};

use thiserror::Error;

/// Why an output was not written. Every variant names the path; none leaves a file behind.
#[derive(Debug, Error)]
pub enum OutputError {
    /// The target exists and is not a regular file (or directory, for a directory output).
    #[error("{}: exists and is {found}, not {expected}; refusing to replace it", path.display())]
    NotRegular {
        /// The target as given.
        path: PathBuf,
        /// What it is: "a character device", "a FIFO", "a directory", ….
        found: &'static str,
        /// What an output there must be: "a regular file" or "a directory".
        expected: &'static str,
    },
    /// The target is, holds or lies inside a path the command must not overwrite.
    #[error("{}: {relation} {} ({}); refusing to write there", path.display(), protected.display(), resolved.display())]
    Protected {
        /// The target as given.
        path: PathBuf,
        /// The target with links and `..` resolved.
        resolved: PathBuf,
        /// The protected path it meets.
        protected: PathBuf,
        /// "is", "lies inside" or "holds".
        relation: &'static str,
    },
    /// The operating system refused a step (a full disk, an I/O error); nothing was written and
    /// the target is as it was.
    #[error("{}: {op}: {source}; nothing was written", path.display())]
    Io {
        /// The target.
        path: PathBuf,
        /// The step that failed.
        op: &'static str,
        /// The underlying error.
        source: io::Error,
    },
}

/// What an existing path that is not a regular file is, for errors.
fn kind_of(meta: &fs::Metadata) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    let t = meta.file_type();
    if t.is_dir() {
        "a directory"
    } else if t.is_char_device() {
        "a character device"
    } else if t.is_block_device() {
        "a block device"
    } else if t.is_fifo() {
        "a FIFO"
    } else if t.is_socket() {
        "a socket"
    } else if t.is_file() {
        "a regular file"
    } else {
        "not a file"
    }
}

/// `path` absolute, with links resolved where the path exists and `.`/`..` folded after.
fn resolve(path: &Path) -> Result<PathBuf, OutputError> {
    let io = |op, source| OutputError::Io {
        path: path.to_path_buf(),
        op,
        source,
    };
    let absolute = std::path::absolute(path).map_err(|e| io("resolving the path", e))?;
    // Component by component: canonicalized while the path exists (links resolved), then
    // the rest appended with `..` folded.
    let mut resolved = PathBuf::new();
    let mut exists = true;
    for component in absolute.components() {
        match component {
            Component::CurDir => {}
            Component::ParentDir => {
                resolved.pop();
            }
            other => {
                resolved.push(other);
                if exists {
                    match fs::canonicalize(&resolved) {
                        Ok(canonical) => resolved = canonical,
                        Err(_) => exists = false,
                    }
                }
            }
        }
    }
    Ok(resolved)
}

/// Refuses `resolved` (from `path`) if it is, lies inside, or (for a directory output) holds a
/// protected path.
fn check_protected(
    path: &Path,
    resolved: &Path,
    protected: &[&Path],
    directory: bool,
) -> Result<(), OutputError> {
    for p in protected {
        let p_resolved = resolve(p)?;
        let relation = if resolved == p_resolved {
            Some("is")
        } else if resolved.starts_with(&p_resolved) {
            Some("lies inside")
        } else if directory && p_resolved.starts_with(resolved) {
            Some("holds")
        } else {
            None
        };
        if let Some(relation) = relation {
            return Err(OutputError::Protected {
                path: path.to_path_buf(),
                resolved: resolved.to_path_buf(),
                protected: p.to_path_buf(),
                relation,
            });
        }
    }
    Ok(())
}

/// Checks that `path` may be written as an output file (module docs) and returns the file to
/// write: `path` with links and `..` resolved.
pub fn check_output(path: &Path, protected: &[&Path]) -> Result<PathBuf, OutputError> {
    if let Ok(link) = fs::symlink_metadata(path) {
        match fs::metadata(path) {
            Ok(meta) if meta.is_file() => {}
            Ok(meta) => {
                return Err(OutputError::NotRegular {
                    path: path.to_path_buf(),
                    found: kind_of(&meta),
                    expected: "a regular file",
                });
            }
            Err(_) if link.file_type().is_symlink() => {
                return Err(OutputError::NotRegular {
                    path: path.to_path_buf(),
                    found: "a symbolic link to nothing",
                    expected: "a regular file",
                });
            }
            Err(source) => {
                return Err(OutputError::Io {
                    path: path.to_path_buf(),
                    op: "inspecting the target",
                    source,
                });
            }
        }
    }
    let resolved = resolve(path)?;
    check_protected(path, &resolved, protected, false)?;
    Ok(resolved)
}

/// Checks that `dir` may be an output directory: absent or a directory (through links), not
/// one of the `protected` paths, not inside one, and holding none of them (a command that
/// replaces its output directory would remove them).
pub fn check_output_dir(dir: &Path, protected: &[&Path]) -> Result<PathBuf, OutputError> {
    if let Ok(meta) = fs::metadata(dir)
        && !meta.is_dir()
    {
        return Err(OutputError::NotRegular {
            path: dir.to_path_buf(),
            found: kind_of(&meta),
            expected: "a directory",
        });
    }
    let resolved = resolve(dir)?;
    check_protected(dir, &resolved, protected, true)?;
    Ok(resolved)
}

/// Writes `bytes` to the output file `path` (module docs): [`check_output`], then an atomic
/// write of the file it resolves to. On any error nothing is left behind and an existing
/// target is as it was.
pub fn write_output(path: &Path, bytes: &[u8], protected: &[&Path]) -> Result<(), OutputError> {
    let resolved = check_output(path, protected)?;
    crate::write_file_atomically(&resolved, bytes).map_err(|(op, source)| OutputError::Io {
        path: path.to_path_buf(),
        op,
        source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn non_regular_targets_and_protected_paths_are_refused_and_left_as_they_were() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let bake = d.join("bake");
        fs::create_dir(&bake).unwrap();
        fs::write(bake.join("manifest.json"), "{}").unwrap();
        std::os::unix::fs::symlink("/dev/null", d.join("null")).unwrap();
        std::os::unix::fs::symlink(d.join("absent"), d.join("dangling")).unwrap();
        let protected = [bake.as_path()];
        for (target, needle) in [
            (d.join("null"), "is a character device, not a regular file"),
            (d.join("dangling"), "a symbolic link to nothing"),
            (bake.clone(), "is a directory, not a regular file"),
            (bake.join("manifest.json"), "lies inside"),
            (d.join("x/../bake/cloud.exr"), "lies inside"),
        ] {
            let e = write_output(&target, b"new", &protected)
                .unwrap_err()
                .to_string();
            assert!(e.contains(needle), "{}: {e}", target.display());
        }
        assert_eq!(fs::read(bake.join("manifest.json")).unwrap(), b"{}");
        assert!(!d.join("absent").exists());
        // A directory output may not hold the bake either.
        let e = check_output_dir(d, &protected).unwrap_err().to_string();
        assert!(e.contains("holds"), "{e}");
        // A link to a regular file is written through.
        fs::write(d.join("real.png"), "old").unwrap();
        std::os::unix::fs::symlink(d.join("real.png"), d.join("link.png")).unwrap();
        write_output(&d.join("link.png"), b"new", &protected).unwrap();
        assert_eq!(fs::read(d.join("real.png")).unwrap(), b"new");
        assert!(
            fs::symlink_metadata(d.join("link.png"))
                .unwrap()
                .file_type()
                .is_symlink()
        );
    }
}
