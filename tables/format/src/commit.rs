//! A bake directory that readers see as one generation or the previous one, never a mix.
//!
//! # The protocol
//! 1. **Lock** ([`BakeLock`]): a writer holds an exclusive advisory lock on `DIR/.lock` (which
//!    records its PID) for the whole bake; a second writer is refused, naming the holder.
//!    Under the lock, leftovers of dead writers are removed ([`BakeLock::clean_stale`]).
//! 2. **Stage** ([`Staging`]): every new file — each field's EXR and `manifest.json` — is written
//!    and fsynced inside `DIR/.stage-<pid>/`. Nothing a reader looks at changes; a failure or a
//!    kill here leaves the previous bake exactly as it was (the stage is removed on drop, or by
//!    the next writer).
//! 3. **Commit point**: the stage directory is renamed to `DIR/.commit` (one atomic rename). From
//!    here on the new generation is the bake.
//! 4. **Roll forward** ([`roll_forward`]): the staged files are renamed into `DIR`, the manifest
//!    last, then `.commit` is removed. A writer killed during this step leaves `.commit` behind;
//!    every reader refuses a directory with a pending commit ([`check_no_pending_commit`]) and
//!    the next writer finishes it before anything else.
//!
//! Readers also verify each EXR against the size and CRC-32 its manifest entry records, so a
//! reader that races a roll-forward in progress (old manifest, some new EXRs) refuses what it
//! read instead of accepting a mix.

use std::fs::{self, File, OpenOptions};
use std::io::{self, Read, Seek, Write};
use std::path::{Path, PathBuf};

use thiserror::Error;

/// The lock file inside a bake directory.
pub const LOCK_FILE: &str = ".lock";
/// The staged generation after the commit point.
pub const COMMIT_DIR: &str = ".commit";
/// Prefix of a writer's stage directory.
pub const STAGE_PREFIX: &str = ".stage-";

/// Why a bake directory cannot be written or read now.
#[derive(Debug, Error)]
pub enum CommitError {
    /// Another writer holds the lock.
    #[error(
        "{} is being baked by process {holder} (lock {}); wait for it to finish or bake into another directory",
        dir.display(),
        dir.join(LOCK_FILE).display()
    )]
    Locked {
        /// The bake directory.
        dir: PathBuf,
        /// The PID recorded by the holder (or "unknown").
        holder: String,
    },
    /// A previous writer stopped between its commit point and the end of its roll-forward.
    #[error(
        "{}: a bake was interrupted while publishing its files ({} is pending); run `photometeor bake` into this directory again to finish it",
        dir.display(),
        dir.join(COMMIT_DIR).display()
    )]
    PendingCommit {
        /// The bake directory.
        dir: PathBuf,
    },
    /// The operating system refused a step.
    #[error("{}: {op}: {source}", path.display())]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// The step.
        op: &'static str,
        /// The underlying error.
        source: io::Error,
    },
}

fn io_error<'p>(path: &'p Path, op: &'static str) -> impl FnOnce(io::Error) -> CommitError + 'p {
    move |source| CommitError::Io {
        path: path.to_path_buf(),
        op,
        source,
    }
}

/// Refuses a directory whose last bake stopped after its commit point (see the module docs).
pub fn check_no_pending_commit(dir: &Path) -> Result<(), CommitError> {
    if dir.join(COMMIT_DIR).exists() {
        return Err(CommitError::PendingCommit {
            dir: dir.to_path_buf(),
        });
    }
    Ok(())
}

/// The exclusive writer's lock on a bake directory, released on drop.
#[derive(Debug)]
pub struct BakeLock {
    dir: PathBuf,
    file: File,
}

impl BakeLock {
    /// Creates `dir` if needed and takes its lock without waiting; refuses if another process
    /// holds it, naming that process.
    pub fn acquire(dir: &Path) -> Result<Self, CommitError> {
        fs::create_dir_all(dir).map_err(io_error(dir, "creating the bake directory"))?;
        let path = dir.join(LOCK_FILE);
        let mut file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(io_error(&path, "opening the lock file"))?;
        match file.try_lock() {
            Ok(()) => {}
            Err(fs::TryLockError::WouldBlock) => {
                let mut holder = String::new();
                let _ = file.read_to_string(&mut holder);
                let holder = holder.trim();
                return Err(CommitError::Locked {
                    dir: dir.to_path_buf(),
                    holder: if holder.is_empty() {
                        "unknown".into()
                    } else {
                        holder.to_string()
                    },
                });
            }
            Err(fs::TryLockError::Error(e)) => {
                return Err(io_error(&path, "locking")(e));
            }
        }
        let record = |file: &mut File| -> io::Result<()> {
            file.set_len(0)?;
            file.rewind()?;
            writeln!(file, "{}", std::process::id())?;
            file.sync_all()
        };
        record(&mut file).map_err(io_error(&path, "recording the PID in the lock file"))?;
        Ok(Self {
            dir: dir.to_path_buf(),
            file,
        })
    }

    /// Waits while another process holds `dir`'s lock, calling `waiting` once with its PID (or
    /// "unknown") before the wait; returns at once when nobody holds it or `dir` has no lock
    /// file. Takes nothing: a writer still calls [`BakeLock::acquire`] after, and may find the
    /// lock taken again by a third process.
    pub fn wait_until_free(dir: &Path, waiting: impl FnOnce(&str)) -> Result<(), CommitError> {
        let path = dir.join(LOCK_FILE);
        let mut file = match OpenOptions::new().read(true).write(true).open(&path) {
            Ok(f) => f,
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(()),
            Err(e) => return Err(io_error(&path, "opening the lock file")(e)),
        };
        match file.try_lock() {
            Ok(()) => return Ok(()),
            Err(fs::TryLockError::WouldBlock) => {}
            Err(fs::TryLockError::Error(e)) => return Err(io_error(&path, "locking")(e)),
        }
        let mut holder = String::new();
        let _ = file.read_to_string(&mut holder);
        let holder = holder.trim();
        waiting(if holder.is_empty() { "unknown" } else { holder });
        // Blocks until the holder's lock goes (its bake ends or it dies); dropping the file
        // releases ours.
        file.lock().map_err(io_error(&path, "waiting for the lock"))
    }

    /// The locked directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Under the lock: finishes an interrupted roll-forward, then removes what dead writers left
    /// (stage directories and `.*.tmp-*` files of [`crate::write_file_atomically`]). Returns the
    /// names removed or finished.
    pub fn clean_stale(&self) -> Result<Vec<String>, CommitError> {
        let mut cleaned = Vec::new();
        if roll_forward(&self.dir)? {
            cleaned.push(COMMIT_DIR.to_string());
        }
        let entries = fs::read_dir(&self.dir).map_err(io_error(&self.dir, "listing"))?;
        for entry in entries.flatten() {
            let name = entry.file_name().to_string_lossy().into_owned();
            let path = entry.path();
            if name.starts_with(STAGE_PREFIX) {
                fs::remove_dir_all(&path).map_err(io_error(&path, "removing a stale stage"))?;
                cleaned.push(name);
            } else if name.starts_with('.') && name.contains(".tmp-") && path.is_file() {
                fs::remove_file(&path).map_err(io_error(&path, "removing a stale temporary"))?;
                cleaned.push(name);
            }
        }
        Ok(cleaned)
    }
}

impl Drop for BakeLock {
    fn drop(&mut self) {
        let _ = self.file.unlock();
    }
}

/// A generation being written: files go into the stage directory until [`Staging::commit`].
#[derive(Debug)]
pub struct Staging<'a> {
    lock: &'a BakeLock,
    stage: PathBuf,
    done: bool,
}

impl<'a> Staging<'a> {
    /// A fresh stage directory in the locked bake directory.
    pub fn begin(lock: &'a BakeLock) -> Result<Self, CommitError> {
        let stage = lock
            .dir
            .join(format!("{STAGE_PREFIX}{}", std::process::id()));
        if stage.exists() {
            fs::remove_dir_all(&stage).map_err(io_error(&stage, "clearing the stage"))?;
        }
        fs::create_dir(&stage).map_err(io_error(&stage, "creating the stage"))?;
        Ok(Self {
            lock,
            stage,
            done: false,
        })
    }

    /// Writes one file of the new generation (a plain name) into the stage and syncs it.
    pub fn write(&mut self, name: &str, bytes: &[u8]) -> Result<(), CommitError> {
        let path = self.stage.join(name);
        let mut file = File::create(&path).map_err(io_error(&path, "creating a staged file"))?;
        file.write_all(bytes)
            .map_err(io_error(&path, "writing a staged file"))?;
        file.sync_all()
            .map_err(io_error(&path, "syncing a staged file"))?;
        Ok(())
    }

    /// The commit point (stage → `.commit`, one rename), then the roll-forward (the manifest is
    /// published last).
    pub fn commit(self) -> Result<(), CommitError> {
        let dir = self.lock.dir.clone();
        self.commit_point_only()?;
        roll_forward(&dir)?;
        Ok(())
    }

    /// The commit point only, without the roll-forward: what a writer killed right after it
    /// leaves. [`Self::commit`] is this plus [`roll_forward`]; alone, it serves fault-injection
    /// tests.
    #[doc(hidden)]
    pub fn commit_point_only(mut self) -> Result<(), CommitError> {
        sync_dir(&self.stage);
        let commit = self.lock.dir.join(COMMIT_DIR);
        fs::rename(&self.stage, &commit).map_err(io_error(&commit, "publishing the stage"))?;
        self.done = true;
        sync_dir(&self.lock.dir);
        Ok(())
    }
}

impl Drop for Staging<'_> {
    fn drop(&mut self) {
        if !self.done {
            let _ = fs::remove_dir_all(&self.stage);
        }
    }
}

/// Finishes a pending commit in `dir`, if any: every staged file renamed into `dir`,
/// `manifest.json` last, then `.commit` removed. Returns whether there was one. Safe to repeat
/// after a crash at any point (each rename either happened or did not).
pub fn roll_forward(dir: &Path) -> Result<bool, CommitError> {
    let commit = dir.join(COMMIT_DIR);
    if !commit.exists() {
        return Ok(false);
    }
    let mut names: Vec<String> = fs::read_dir(&commit)
        .map_err(io_error(&commit, "listing the pending commit"))?
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    // The manifest names the generation: it goes last.
    names.sort_by_key(|n| n == crate::MANIFEST_FILE);
    for name in &names {
        let from = commit.join(name);
        let to = dir.join(name);
        fs::rename(&from, &to).map_err(io_error(&to, "publishing a file"))?;
    }
    sync_dir(dir);
    fs::remove_dir(&commit).map_err(io_error(&commit, "removing the finished commit"))?;
    sync_dir(dir);
    Ok(true)
}

/// Makes renames in `dir` durable (Unix); best effort.
fn sync_dir(dir: &Path) {
    #[cfg(unix)]
    if let Ok(d) = File::open(dir) {
        let _ = d.sync_all();
    }
}

/// CRC-32 (IEEE) of `bytes` as 8 lowercase hex digits, the checksum a manifest records.
pub fn crc32_hex(bytes: &[u8]) -> String {
    format!("{:08x}", crc32fast::hash(bytes))
}
