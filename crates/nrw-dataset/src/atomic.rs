//! Atomic file writes: a temporary file in the same folder, synced, then renamed over the
//! target, so an interrupted run leaves either the old file or the new one, never half; the
//! next write into that folder removes what a killed process left.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, OnceLock};

use crate::error::{DatasetError, Result};

/// This machine's name as temporary file names carry it (so a sweep on a shared file system
/// never touches another machine's files).
fn host() -> &'static str {
    static HOST: OnceLock<String> = OnceLock::new();
    HOST.get_or_init(|| {
        std::fs::read_to_string("/proc/sys/kernel/hostname")
            .ok()
            .or_else(|| std::env::var("HOSTNAME").ok())
            .unwrap_or_default()
            .trim()
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || c == '-' {
                    c
                } else {
                    '_'
                }
            })
            .collect()
    })
}

/// The temporary name a file is written under before its rename:
/// `.NAME.HOST.PID.tmp` beside it.
pub fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!(".{name}.{}.{}.tmp", host(), std::process::id()))
}

/// The process id in a temporary name of this machine (`None` for other machines' files).
fn temp_pid(file_name: &str) -> Option<u32> {
    let rest = file_name.strip_prefix('.')?.strip_suffix(".tmp")?;
    let (rest, pid) = rest.rsplit_once('.')?;
    let (_, h) = rest.rsplit_once('.')?;
    (h == host()).then(|| pid.parse().ok())?
}

/// Remove the temporary files a killed process of this machine left in `dir` (its pid no
/// longer runs), once per folder per process: a SIGKILL between write and rename leaves one,
/// and a rerun must end with the same files as an uninterrupted run.
fn sweep_stale_temps(dir: &Path) {
    static SWEPT: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());
    {
        let mut swept = SWEPT.lock().unwrap_or_else(|e| e.into_inner());
        if swept.iter().any(|d| d == dir) {
            return;
        }
        swept.push(dir.to_path_buf());
    }
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        let stale = temp_pid(&name).is_some_and(|pid| {
            pid != std::process::id() && !Path::new(&format!("/proc/{pid}")).exists()
        });
        if stale {
            let _ = std::fs::remove_file(e.path());
        }
    }
}

/// A function run before each commit with its target.
pub type CommitHook = Box<dyn Fn(&crate::Location) + Send + Sync>;

/// What runs before each commit; see [`set_commit_hook`].
static COMMIT_HOOK: std::sync::OnceLock<CommitHook> = std::sync::OnceLock::new();

/// Fault injection for the kill tests: `hook` runs before every commit (the rename that
/// makes a file or an export visible) with its target, so the binary can announce the
/// commit and wait, and a test SIGKILL a stage at a known point with its temporary output on
/// disk and its target not yet replaced. Set once per process; the library never prints.
pub fn set_commit_hook(hook: CommitHook) {
    let _ = COMMIT_HOOK.set(hook);
}

/// Run the hook of [`set_commit_hook`] before committing `target` (nothing when unset).
pub fn before_commit(target: &crate::Location) {
    if let Some(hook) = COMMIT_HOOK.get() {
        hook(target);
    }
}

/// Write through `fill` into a temporary file and rename it to `path` once complete.
pub fn write_atomic<F>(path: &Path, fill: F) -> Result<()>
where
    F: FnOnce(&mut std::fs::File) -> Result<()>,
{
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| DatasetError::io(dir, e))?;
        sweep_stale_temps(dir);
    }
    let tmp = temp_path(path);
    let result = (|| {
        let mut f = std::fs::File::create(&tmp).map_err(|e| DatasetError::io(&tmp, e))?;
        fill(&mut f)?;
        f.flush().map_err(|e| DatasetError::io(&tmp, e))?;
        f.sync_all().map_err(|e| DatasetError::io(&tmp, e))?;
        before_commit(&path.into());
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

/// Copy the file `from` to `path` atomically, streaming (any size, bounded memory).
pub fn copy_atomic(from: &Path, path: &Path) -> Result<()> {
    let mut src = std::fs::File::open(from).map_err(|e| DatasetError::io(from, e))?;
    write_atomic(path, |f| {
        std::io::copy(&mut src, f)
            .map(|_| ())
            .map_err(|e| DatasetError::io(from, e))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_write_sweeps_temporaries_of_dead_local_processes_only() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let dead = d.join(format!(".a.parquet.{}.4000000000.tmp", host()));
        let other_host = d.join(".a.parquet.elsewhere.1.tmp");
        let live = d.join(format!(".b.parquet.{}.1.tmp", host())); // pid 1 runs
        for p in [&dead, &other_host, &live] {
            std::fs::write(p, b"half").unwrap();
        }
        write_bytes_atomic(&d.join("c.parquet"), b"whole").unwrap();
        assert!(!dead.exists(), "a dead process's temporary is removed");
        assert!(other_host.exists() && live.exists());
        assert_eq!(std::fs::read(d.join("c.parquet")).unwrap(), b"whole");
        assert_eq!(temp_pid(&format!(".x.{}.42.tmp", host())), Some(42));
        assert_eq!(temp_pid("x.parquet"), None);
    }
}
