//! Resuming and publishing a workspace: `densify.json` (the settings and the photos that could
//! not be read), the claim on the output folder, the staging folder, and its move into place.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use nrw_dataset::{Location, Store};

use super::config::Settings;
use crate::error::{PipelineError, Result, Setting};

/// The record's name in a workspace ([`nrw_colmap::dense::Workspace::settings`]).
pub(super) const RECORD: &str = "densify.json";

/// `densify.json`: the settings, and the photos undistortion could not read (name → why).
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub(super) struct Record {
    pub(super) settings: Settings,
    pub(super) unreadable: BTreeMap<String, String>,
}

/// The settings a record holds (what every unit and resumed run must share).
pub(super) fn settings_of(r: &Record) -> &Settings {
    &r.settings
}

/// The error for a unit whose settings are not the workspace's: names each that differs.
pub(super) fn settings_differ(record: Location, differ: &[String]) -> PipelineError {
    PipelineError::input(
        record,
        format!(
            "the workspace is being built with {}: run every unit and finalize with the same settings, or delete the folder to start over",
            differ.join(", ")
        ),
    )
}

/// Refuse to replace an output that holds files (locally) or objects (on a bucket) unless
/// asked to: one claim wherever the workspace goes. `store` is the store at `out`.
pub(super) fn claim(out: &Location, store: &Store, overwrite: bool) -> Result<()> {
    if let Location::Local(dir) = out {
        if dir.exists() && !dir.is_dir() {
            return Err(PipelineError::input(
                dir,
                "is a file, not a folder: the dense workspace is a folder",
            ));
        }
    }
    if overwrite || !nrw_dataset::publish::occupied(store)? {
        return Ok(());
    }
    Err(PipelineError::config(
        Setting::Overwrite,
        format!(
            "{out} already holds a dense workspace (perhaps your own COLMAP run); it is kept unless {} is set — or write elsewhere with {}",
            Setting::Overwrite,
            Setting::DenseOut
        ),
    ))
}

/// The folder a workspace is built in before it replaces `out` whole.
pub(super) fn staging_dir(out: &Path) -> PathBuf {
    let name = out
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "dense".into());
    out.with_file_name(nrw_dataset::publish::staging_name(&name))
}

/// Move the finished workspace into place (replacing an older one the caller may replace).
pub(super) fn publish(staging: &Path, out: &Path) -> Result<()> {
    Ok(nrw_dataset::publish::rename_into_place(staging, out)?)
}
