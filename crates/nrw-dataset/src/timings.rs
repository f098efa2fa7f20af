//! `timings.json`: seconds per stage, shown by the QA report. Not part of the reproducible
//! dataset (times differ between runs), so it stays out of manifest.json.

use crate::error::Result;
use crate::store::Store;
use std::collections::BTreeMap;

/// Name of the per-stage timing log inside a dataset.
pub const TIMINGS_FILE: &str = "timings.json";

/// Seconds per stage recorded so far (empty when none or unreadable: timings are advisory).
pub fn read(dir: &Store) -> BTreeMap<String, f64> {
    dir.read_opt(TIMINGS_FILE)
        .ok()
        .flatten()
        .and_then(|s| serde_json::from_slice(&s).ok())
        .unwrap_or_default()
}

/// Record how long a stage took (atomic read-modify-write).
pub fn record(dir: &Store, stage: &str, seconds: f64) -> Result<()> {
    let mut t = read(dir);
    t.insert(stage.to_string(), seconds);
    let text = serde_json::to_string_pretty(&t).expect("map of numbers");
    dir.write(TIMINGS_FILE, text.into_bytes())
}
