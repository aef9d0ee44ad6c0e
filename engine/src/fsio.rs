//! Files written so that a reader, or a run killed at any moment, sees the old file or the
//! complete new one, never a part of it.

use std::io::Write;
use std::path::{Path, PathBuf};

/// The folder `path` is in (`.` for a bare file name).
fn folder_of(path: &Path) -> &Path {
    match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    }
}

/// The temporary file a writer of `path` fills before renaming it into place: beside it,
/// hidden, named by the process (`.NAME.PID.partial` then `suffix`, e.g. `.mp4` so a tool that
/// picks its format from the extension still does).
pub fn partial_path(path: &Path, suffix: &str) -> PathBuf {
    let name = path
        .file_name()
        .map_or("file".into(), |n| n.to_string_lossy());
    folder_of(path).join(format!(".{name}.{}.partial{suffix}", std::process::id()))
}

/// Writes `bytes` to `path` through a temporary file in the same folder that is synced and
/// renamed over `path`; on any error (a full disk, a read-only folder) the temporary file is
/// removed and `path` is left as it was. The error says which step failed.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), String> {
    let err = |what: &str, e: std::io::Error| format!("{what}: {e}");
    let dir = folder_of(path);
    let tmp = partial_path(path, "");
    let written = std::fs::File::create(&tmp)
        .map_err(|e| err("cannot create a file in its folder", e))
        .and_then(|mut f| {
            f.write_all(bytes)
                .and_then(|()| f.sync_all())
                .map_err(|e| err("cannot write", e))
        })
        .and_then(|()| std::fs::rename(&tmp, path).map_err(|e| err("cannot rename into place", e)));
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
        return written;
    }
    if let Ok(d) = std::fs::File::open(dir) {
        // Persists the rename; not every platform can sync a folder.
        let _ = d.sync_all();
    }
    Ok(())
}
