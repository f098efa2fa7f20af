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

/// The record of the workspace being built (`densify.json` in the staging folder or prefix
/// `store`), if it has one.
pub(super) fn read_record(store: &Store) -> Result<Option<Record>> {
    let Some(bytes) = store.read_opt(RECORD)? else {
        return Ok(None);
    };
    serde_json::from_slice(&bytes).map(Some).map_err(|e| {
        PipelineError::input(
            store.name(RECORD),
            format!("is not densify's record ({e}); delete the folder to start over"),
        )
    })
}

/// The record's bytes (the same wherever it is written, so a published workspace is too).
pub(super) fn record_bytes(record: &Record) -> Vec<u8> {
    serde_json::to_string_pretty(record)
        .expect("densify's record serialises")
        .into_bytes()
}

/// The error for a unit whose settings are not the workspace's: names the first that differs.
pub(super) fn settings_differ(record: Location, have: &Settings, want: &Settings) -> PipelineError {
    let flat = |s: &Settings| {
        let mut out = BTreeMap::new();
        flatten(
            "",
            &serde_json::to_value(s).expect("settings serialise"),
            &mut out,
        );
        out
    };
    let (have, want) = (flat(have), flat(want));
    let null = serde_json::Value::Null;
    let differ: Vec<String> = want
        .iter()
        .filter(|(k, v)| have.get(*k) != Some(*v))
        .map(|(k, v)| format!("{k} = {} (this run: {v})", have.get(k).unwrap_or(&null)))
        .collect();
    PipelineError::input(
        record,
        format!(
            "the workspace is being built with {}: run every unit and finalize with the same settings, or delete the folder to start over",
            differ.join(", ")
        ),
    )
}

/// A JSON object's leaves by dotted key.
pub(super) fn flatten(
    prefix: &str,
    v: &serde_json::Value,
    out: &mut BTreeMap<String, serde_json::Value>,
) {
    match v {
        serde_json::Value::Object(m) => {
            for (k, v) in m {
                let key = if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}.{k}")
                };
                flatten(&key, v, out);
            }
        }
        _ => {
            out.insert(prefix.to_string(), v.clone());
        }
    }
}

/// Refuse to replace a non-empty folder at `out` unless asked to.
pub(super) fn claim(out: &Path, overwrite: bool) -> Result<()> {
    let occupied = std::fs::read_dir(out).is_ok_and(|mut d| d.next().is_some());
    if occupied && !overwrite {
        return Err(PipelineError::config(
            Setting::Overwrite,
            format!(
                "{} already holds a dense workspace (perhaps your own COLMAP run); it is kept unless {} is set — or write elsewhere with {}",
                out.display(),
                Setting::Overwrite,
                Setting::DenseOut
            ),
        ));
    }
    if out.exists() && !out.is_dir() {
        return Err(PipelineError::input(
            out,
            "is a file, not a folder: the dense workspace is a folder",
        ));
    }
    Ok(())
}

/// The folder a workspace is built in before it replaces `out` whole.
pub(super) fn staging_dir(out: &Path) -> PathBuf {
    let name = out
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "dense".into());
    out.with_file_name(format!(".{name}.partial"))
}

/// Move the finished workspace into place (replacing an older one the caller may replace).
pub(super) fn publish(staging: &Path, out: &Path) -> Result<()> {
    Ok(nrw_dataset::publish::rename_into_place(staging, out)?)
}
