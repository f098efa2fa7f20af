//! Atomic file writes: a temporary file in the same folder, synced, then renamed over the
//! target, so an interrupted run leaves either the old file or the new one, never half.

use std::io::Write;
use std::path::{Path, PathBuf};

use crate::error::{DatasetError, Result};

/// The temporary name a file is written under before its rename.
pub fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!(".{name}.{}.tmp", std::process::id()))
}

/// Write through `fill` into a temporary file and rename it to `path` once complete.
pub fn write_atomic<F>(path: &Path, fill: F) -> Result<()>
where
    F: FnOnce(&mut std::fs::File) -> Result<()>,
{
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| DatasetError::io(dir, e))?;
    }
    let tmp = temp_path(path);
    let result = (|| {
        let mut f = std::fs::File::create(&tmp).map_err(|e| DatasetError::io(&tmp, e))?;
        fill(&mut f)?;
        f.flush().map_err(|e| DatasetError::io(&tmp, e))?;
        f.sync_all().map_err(|e| DatasetError::io(&tmp, e))?;
        std::fs::rename(&tmp, path).map_err(|e| DatasetError::io(path, e))
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// Write bytes atomically.
pub fn write_bytes_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic(path, |f| {
        f.write_all(bytes).map_err(|e| DatasetError::io(path, e))
    })
}
