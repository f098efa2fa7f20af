//! A workspace whose `--out` is on object storage, so machines that share nothing but a
//! bucket can densify. Every step builds in a local scratch folder of its own (each machine
//! reads the scene and undistorts the photos itself, as ingest reads the scene); the units
//! share the maps through a staging prefix beside the output (`.NAME.partial/`, the layout of
//! the local staging folder): a unit uploads each map it writes (the pass's last map last, so
//! its presence proves the view done) and fetches the maps it reads; finalize fetches every
//! map, fuses in its scratch folder with the bounded cache of a local run, and uploads the
//! workspace with `fused.ply` last, then removes the staging prefix.

use std::path::{Path, PathBuf};

use nrw_colmap::dense::Workspace;
use nrw_dataset::{Location, Store};

use crate::error::{PipelineError, Result, Setting};

/// The file a published workspace uploads last: a reader (ingest) looks for it.
pub(super) const MARKER: &str = "fused.ply";

/// The object-store side of a workspace: the staging prefix the units share, the output,
/// and the local scratch folder this process builds in (removed when dropped).
pub(super) struct Remote {
    pub(super) staging: Store,
    pub(super) out: Store,
    pub(super) scratch: PathBuf,
}

impl Drop for Remote {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.scratch);
    }
}

impl Remote {
    /// Open the output URL and its staging prefix, and make a fresh scratch folder.
    pub(super) fn open(out: &Location) -> Result<Remote> {
        let staging = Store::open(&staging_location(out)?)?;
        let out = Store::open(out)?;
        let scratch = nrw_dataset::publish::scratch_folder("densify")?;
        Ok(Remote {
            staging,
            out,
            scratch,
        })
    }

    /// Whether the staging prefix holds the workspace file at local `path`.
    pub(super) fn has(&self, ws: &Workspace, path: &Path) -> Result<bool> {
        Ok(self.staging.exists(&rel(ws, path))?)
    }

    /// Upload the workspace files at local `paths`, in order, to the staging prefix.
    pub(super) fn share(&self, ws: &Workspace, paths: &[PathBuf]) -> Result<()> {
        for p in paths {
            self.staging.upload(&rel(ws, p), p)?;
        }
        Ok(())
    }

    /// Make the workspace file at local `path` present, fetching it from the staging prefix
    /// when this machine does not have it; false when neither has it.
    pub(super) fn fetch(&self, ws: &Workspace, path: &Path) -> Result<bool> {
        if path.is_file() {
            return Ok(true);
        }
        match self.staging.read_opt(&rel(ws, path))? {
            Some(bytes) => {
                nrw_dataset::atomic::write_bytes_atomic(path, &bytes)?;
                Ok(true)
            }
            None => Ok(false),
        }
    }

    /// Fetch every map the units shared into the local workspace, one file at a time.
    pub(super) fn fetch_maps(&self, ws: &Workspace) -> Result<()> {
        let stereo = rel(ws, &ws.stereo());
        for r in self.staging.list(&stereo)? {
            self.fetch(ws, &ws.root.join(&r))?;
        }
        Ok(())
    }

    /// Upload the finished local workspace to the output (replacing what it held), then
    /// remove the staging prefix.
    pub(super) fn publish(&self, ws: &Workspace) -> Result<()> {
        let earlier = self.out.list("")?;
        nrw_dataset::publish::upload_folder(&ws.root, &self.out, &earlier, MARKER)?;
        self.staging.delete_dir("")?;
        Ok(())
    }
}

/// The prefix the units of a workspace at `out` build it under: `.NAME.partial` beside it.
fn staging_location(out: &Location) -> Result<Location> {
    let text = out.to_string();
    match text.rsplit_once('/') {
        Some((parent, name)) if !name.is_empty() && !parent.ends_with(':') && !parent.ends_with('/') => {
            Ok(Location::parse(&format!(
                "{parent}/{}",
                nrw_dataset::publish::staging_name(name)
            )))
        }
        _ => Err(PipelineError::config(
            Setting::DenseOut,
            format!("is {text}: give a folder inside the bucket (e.g. {text}/scene/dense), so the units have a place beside it to build the workspace in"),
        )),
    }
}

/// `path` relative to the workspace root, `/`-separated (an object key's tail).
pub(super) fn rel(ws: &Workspace, path: &Path) -> String {
    let tail = path.strip_prefix(&ws.root).unwrap_or(path);
    tail.components()
        .map(|c| c.as_os_str().to_string_lossy())
        .collect::<Vec<_>>()
        .join("/")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_staging_prefix_sits_beside_the_output_and_a_bucket_root_is_refused() {
        let s = staging_location(&Location::parse("s3://b/scene/dense/")).unwrap();
        assert_eq!(s.to_string(), "s3://b/scene/.dense.partial");
        let e = staging_location(&Location::parse("s3://b")).unwrap_err();
        assert!(e.to_string().contains("inside the bucket"), "{e}");
        let ws = Workspace::new(Path::new("/tmp/x"));
        assert_eq!(
            rel(&ws, &ws.fused_ply()),
            "fused.ply",
            "a workspace file's key"
        );
    }
}
