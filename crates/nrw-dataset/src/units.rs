//! Work-unit records: what each independent unit of a stage (`--unit I/N`) has done, so
//! `finalize` can merge the units into the scene tables and manifest without the units ever
//! talking to each other.
//!
//! Layout, inside the dataset (hidden: it is bookkeeping, removed by `finalize`):
//! - `.units/<stage>/group-NNNNN.json` — one record per group of work (an ingest group is one
//!   shard), written atomically after the group's data files, so a record proves its files;
//! - `.units/<stage>/unit-I-of-N.json` — written when unit I of N has done all its groups.
//!
//! Every file has exactly one writer (groups belong to one unit), so units running at once,
//! on one machine or many sharing a folder, never overwrite each other.

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::error::{DatasetError, Result};
use crate::manifest::{FileEntry, SceneSource};
use crate::scene::ImageOutcome;
use crate::store::Store;

/// Folder of the unit records inside a dataset.
pub const UNITS_DIR: &str = ".units";

/// Stage name of ingest's records.
pub const INGEST: &str = "ingest";
/// Stage name of style's records.
pub const STYLE: &str = "style";

/// Folder of one stage's records, relative to the dataset.
pub fn stage_dir(stage: &str) -> String {
    format!("{UNITS_DIR}/{stage}")
}

/// Record of group `g` of a stage, relative to the dataset.
pub fn group_record_path(stage: &str, g: usize) -> String {
    format!("{}/group-{g:05}.json", stage_dir(stage))
}

/// Record of unit `index` of `count`, relative to the dataset.
pub fn unit_record_path(stage: &str, index: usize, count: usize) -> String {
    format!("{}/unit-{index}-of-{count}.json", stage_dir(stage))
}

/// What a unit records when it has done every group it owns.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct UnitRecord {
    pub stage: String,
    pub index: usize,
    pub count: usize,
    /// Hash of the inputs and parameters: units with different fingerprints cannot be merged.
    pub fingerprint: String,
    /// The stage's parameters, so a disagreement can be named parameter by parameter.
    pub parameters: serde_json::Map<String, serde_json::Value>,
    /// Input files with their hashes (ingest: the model files and the point cloud).
    pub inputs: Vec<FileEntry>,
    /// Where the scene came from (ingest only).
    pub scene: Option<SceneSource>,
    /// Warnings about the inputs (every unit sees the same).
    pub warnings: Vec<String>,
    /// Groups of the whole stage (every unit computes the same).
    pub groups: usize,
    /// Wall time of the unit's run.
    pub seconds: f64,
    /// The vector instructions whose GEMM kernels computed the unit's values, where those
    /// depend on them (VGG descriptors: AVX-512 and AVX2 kernels sum in other orders); absent
    /// where no value does, so such records are the same bytes on every machine.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub instruction_set: Option<String>,
}

/// One image's result inside an ingest group record.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GroupImage {
    pub image_id: u32,
    /// The photo's pixel size as read from its header.
    pub photo_size: Option<(u32, u32)>,
    pub outcome: ImageOutcome,
}

/// What one ingest group produced: its shard (when a view was kept) and every image's outcome.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GroupRecord {
    pub fingerprint: String,
    pub shard: Option<FileEntry>,
    pub images: Vec<GroupImage>,
}

/// Write a record atomically (compact JSON: records are read by programs).
pub fn write_record<T: Serialize>(dir: &Store, rel: &str, record: &T) -> Result<()> {
    let text = serde_json::to_vec(record).map_err(|e| DatasetError::Json {
        path: dir.name(rel),
        source: e,
    })?;
    dir.write(rel, text)
}

/// Read a record; `None` when it does not exist.
pub fn read_record<T: DeserializeOwned>(dir: &Store, rel: &str) -> Result<Option<T>> {
    match dir.read_opt(rel)? {
        Some(bytes) => serde_json::from_slice(&bytes)
            .map(Some)
            .map_err(|e| DatasetError::Json {
                path: dir.name(rel),
                source: e,
            }),
        None => Ok(None),
    }
}

/// Every unit record of a stage, ordered by count then index.
pub fn unit_records(dir: &Store, stage: &str) -> Result<Vec<UnitRecord>> {
    let mut out = Vec::new();
    for rel in dir.list(&stage_dir(stage))? {
        let name = rel.rsplit('/').next().unwrap_or_default();
        if name.starts_with("unit-") && name.ends_with(".json") {
            if let Some(r) = read_record::<UnitRecord>(dir, &rel)? {
                out.push(r);
            }
        }
    }
    out.sort_by_key(|r| (r.count, r.index));
    Ok(out)
}

/// Remove every unit record of a stage except `keep` (a whole-stage run owns the dataset and
/// clears what interrupted unit runs left).
pub fn remove_unit_records(dir: &Store, stage: &str, keep: Option<(usize, usize)>) -> Result<()> {
    for r in unit_records(dir, stage)? {
        if Some((r.index, r.count)) != keep {
            dir.delete(&unit_record_path(stage, r.index, r.count))?;
        }
    }
    Ok(())
}

/// Remove a stage's records once merged.
pub fn clear_stage(dir: &Store, stage: &str) -> Result<()> {
    dir.delete_dir(&stage_dir(stage))?;
    if let Some(local) = dir.local_dir() {
        // Only when empty: another stage's records may still wait for their finalize.
        let _ = std::fs::remove_dir(local.join(UNITS_DIR));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_round_trip_and_unit_listing_is_ordered() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = &Store::local(tmp.path());
        let rec = |index, count| UnitRecord {
            stage: STYLE.into(),
            index,
            count,
            fingerprint: "f".into(),
            parameters: Default::default(),
            inputs: vec![],
            scene: None,
            warnings: vec![],
            groups: 3,
            seconds: 1.0,
            instruction_set: None,
        };
        for (i, n) in [(2, 3), (0, 3), (1, 2)] {
            write_record(dir, &unit_record_path(STYLE, i, n), &rec(i, n)).unwrap();
        }
        let got: Vec<_> = unit_records(dir, STYLE)
            .unwrap()
            .iter()
            .map(|r| (r.index, r.count))
            .collect();
        assert_eq!(got, vec![(1, 2), (0, 3), (2, 3)]);
        remove_unit_records(dir, STYLE, Some((0, 3))).unwrap();
        assert_eq!(unit_records(dir, STYLE).unwrap(), vec![rec(0, 3)]);
        assert!(read_record::<UnitRecord>(dir, &group_record_path(STYLE, 0))
            .unwrap()
            .is_none());
        clear_stage(dir, STYLE).unwrap();
        assert!(!tmp.path().join(UNITS_DIR).exists());
    }
}
