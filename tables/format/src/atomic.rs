//! Files as a reader should see them: written whole or not at all, and read only when they are
//! regular files of a sane size.

use std::fs::{self, File};
use std::io::{self, Read, Write};
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};

/// Writes `bytes` to `path` atomically: a temporary file `.<name>.tmp-<pid>-<n>` in the same
/// directory, fsync, rename over `path`, fsync of the directory (Unix).
///
/// On any error before the rename the temporary file is removed and `path` is untouched. The
/// error carries the step that failed.
pub fn write_file_atomically(path: &Path, bytes: &[u8]) -> Result<(), (&'static str, io::Error)> {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let file_name = path.file_name().ok_or_else(|| {
        (
            "choosing a temporary name",
            io::Error::new(io::ErrorKind::InvalidInput, "the path has no file name"),
        )
    })?;
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let mut tmp_name = std::ffi::OsString::from(".");
    tmp_name.push(file_name);
    tmp_name.push(format!(
        ".tmp-{}-{}",
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    let tmp_path = dir.join(tmp_name);

    /// Removes the temporary file unless it was renamed.
    struct Guard<'a>(&'a Path, bool);
    impl Drop for Guard<'_> {
        fn drop(&mut self) {
            if !self.1 {
                let _ = fs::remove_file(self.0);
            }
        }
    }

    let mut file = File::options()
        .write(true)
        .create_new(true)
        .open(&tmp_path)
        .map_err(|e| ("creating the temporary file", e))?;
    let mut guard = Guard(&tmp_path, false);
    file.write_all(bytes)
        .map_err(|e| ("writing the temporary file", e))?;
    file.sync_all()
        .map_err(|e| ("syncing the temporary file", e))?;
    drop(file);
    fs::rename(&tmp_path, path).map_err(|e| ("renaming the temporary file into place", e))?;
    guard.1 = true;
    #[cfg(unix)]
    {
        // Make the rename itself durable. Best effort: the file is complete either way.
        if let Ok(d) = File::open(dir) {
            let _ = d.sync_all();
        }
    }
    Ok(())
}

/// Reads `path` whole if it is a regular file (after following links) of at most `max_bytes`:
/// a FIFO, a device such as `/dev/zero` or a directory is refused before anything is read.
pub fn read_regular_file(
    path: &Path,
    max_bytes: u64,
) -> Result<Vec<u8>, (&'static str, io::Error)> {
    let meta = fs::metadata(path).map_err(|e| ("reading", e))?;
    if !meta.is_file() {
        return Err((
            "reading",
            io::Error::new(
                io::ErrorKind::InvalidInput,
                "not a regular file (a directory, FIFO or device?)",
            ),
        ));
    }
    if meta.len() > max_bytes {
        return Err((
            "reading",
            io::Error::new(
                io::ErrorKind::InvalidData,
                format!(
                    "{} bytes, more than the {max_bytes} bytes allowed for this file",
                    meta.len()
                ),
            ),
        ));
    }
    let file = File::open(path).map_err(|e| ("reading", e))?;
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    // The bound holds even if the file grows while it is read.
    file.take(max_bytes + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| ("reading", e))?;
    if bytes.len() as u64 > max_bytes {
        return Err((
            "reading",
            io::Error::new(
                io::ErrorKind::InvalidData,
                "the file grew past its size bound",
            ),
        ));
    }
    Ok(bytes)
}
