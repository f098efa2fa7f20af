//! `timings.json`: seconds per stage, shown by the QA report. Not part of the reproducible
//! dataset (times differ between runs), so it stays out of manifest.json.

use std::collections::BTreeMap;
use std::path::Path;

use crate::error::Result;

/// Name of the per-stage timing log inside a dataset.
pub const TIMINGS_FILE: &str = "timings.json";

/// Seconds per stage recorded so far (empty when none or unreadable: timings are advisory).
pub fn read(dir: &Path) -> BTreeMap<String, f64> {
    std::fs::read_to_string(dir.join(TIMINGS_FILE))
        .ok()
        .and_then(|s| serde_json::from_str(&s).ok())
        .unwrap_or_default()
}

/// Record how long a stage took (atomic read-modify-write).
pub fn record(dir: &Path, stage: &str, seconds: f64) -> Result<()> {
    let mut t = read(dir);
    t.insert(stage.to_string(), seconds);
    let text = serde_json::to_string_pretty(&t).expect("map of numbers");
    crate::atomic::write_bytes_atomic(&dir.join(TIMINGS_FILE), text.as_bytes())
}
