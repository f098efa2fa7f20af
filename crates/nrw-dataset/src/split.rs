//! `splits.parquet`: which kept photo is for training and which for validation. Assignment
//! is a pure function of (seed, photo name), so it is the same on any machine and thread
//! count; re-running after new photos arrive assigns only the new ones, so a validation photo
//! never moves to training.

use crate::store::Store;
use std::collections::BTreeMap;
use std::sync::Arc;

use arrow_array::{RecordBatch, StringArray, UInt32Array, UInt64Array};
use arrow_schema::{DataType, Field, Schema, SchemaRef};
use sha2::{Digest, Sha256};

use crate::error::{DatasetError, Result};

/// Table path of the split inside a dataset.
pub const SPLITS_TABLE: &str = "splits.parquet";

/// One photo's assignment.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Assignment {
    pub image_id: u32,
    pub name: String,
    /// `train` or `val`.
    pub split: String,
    /// The seed in force when this photo was assigned.
    pub seed: u64,
}

/// Arrow schema of `splits.parquet` (documented in schemas/splits.toml).
pub fn splits_schema() -> SchemaRef {
    Arc::new(Schema::new(vec![
        Field::new("image_id", DataType::UInt32, false),
        Field::new("name", DataType::Utf8, false),
        Field::new("split", DataType::Utf8, false),
        Field::new("seed", DataType::UInt64, false),
    ]))
}

/// Rank of a photo for a seed: the first 8 bytes of SHA-256(seed ‖ name), platform-independent.
pub fn rank(seed: u64, name: &str) -> u64 {
    let mut h = Sha256::new();
    h.update(seed.to_le_bytes());
    h.update(name.as_bytes());
    u64::from_be_bytes(h.finalize()[..8].try_into().expect("8 bytes"))
}

/// What a split run changed.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct SplitChange {
    pub kept_train: usize,
    pub kept_val: usize,
    pub new_train: usize,
    pub new_val: usize,
    /// Assigned photos no longer kept by ingest (removed from the table).
    pub gone: Vec<String>,
}

/// Assign `eligible` (image id, name) photos given earlier assignments, so that `val`
/// photos are in validation. Earlier assignments are never changed.
pub fn assign(
    eligible: &[(u32, String)],
    previous: &[Assignment],
    val: usize,
    seed: u64,
) -> std::result::Result<(Vec<Assignment>, SplitChange), String> {
    let by_name: BTreeMap<&str, &Assignment> =
        previous.iter().map(|a| (a.name.as_str(), a)).collect();
    let mut out = Vec::with_capacity(eligible.len());
    let mut change = SplitChange::default();
    let mut fresh: Vec<(u64, &str, u32)> = Vec::new();
    for (id, name) in eligible {
        match by_name.get(name.as_str()) {
            Some(a) => {
                if a.split == "val" {
                    change.kept_val += 1;
                } else {
                    change.kept_train += 1;
                }
                out.push(Assignment {
                    image_id: *id,
                    ..(*a).clone()
                });
            }
            None => fresh.push((rank(seed, name), name.as_str(), *id)),
        }
    }
    let still: std::collections::BTreeSet<&str> =
        eligible.iter().map(|(_, n)| n.as_str()).collect();
    change.gone = previous
        .iter()
        .filter(|a| !still.contains(a.name.as_str()))
        .map(|a| a.name.clone())
        .collect();
    if val < change.kept_val {
        return Err(format!(
            "--val {val} is below the {} validation photos already assigned; assignments are never undone (remove {SPLITS_TABLE} to start over)",
            change.kept_val
        ));
    }
    let need = val - change.kept_val;
    if need > fresh.len() {
        return Err(format!(
            "--val {val} asks for {need} more validation photos but only {} unassigned kept photos exist ({} kept in all)",
            fresh.len(),
            eligible.len()
        ));
    }
    fresh.sort();
    for (k, (_, name, id)) in fresh.iter().enumerate() {
        let split = if k < need { "val" } else { "train" };
        if split == "val" {
            change.new_val += 1;
        } else {
            change.new_train += 1;
        }
        out.push(Assignment {
            image_id: *id,
            name: name.to_string(),
            split: split.into(),
            seed,
        });
    }
    out.sort_by_key(|a| a.image_id);
    Ok((out, change))
}

/// Write `splits.parquet` atomically.
pub fn write_splits(dir: &Store, rows: &[Assignment]) -> Result<crate::manifest::FileEntry> {
    let batch = RecordBatch::try_new(
        splits_schema(),
        vec![
            Arc::new(UInt32Array::from_iter_values(
                rows.iter().map(|a| a.image_id),
            )),
            Arc::new(StringArray::from_iter_values(
                rows.iter().map(|a| a.name.as_str()),
            )),
            Arc::new(StringArray::from_iter_values(
                rows.iter().map(|a| a.split.as_str()),
            )),
            Arc::new(UInt64Array::from_iter_values(rows.iter().map(|a| a.seed))),
        ],
    )
    .map_err(|e| DatasetError::Arrow {
        table: SPLITS_TABLE.into(),
        source: e,
    })?;
    crate::parquet_io::write_table(dir, SPLITS_TABLE, &batch)
}

/// Read `splits.parquet`, or nothing if the dataset has no split yet.
pub fn read_splits(dir: &Store) -> Result<Vec<Assignment>> {
    let path = dir.name(SPLITS_TABLE);
    if !dir.exists(SPLITS_TABLE)? {
        return Ok(Vec::new());
    }
    use crate::parquet_io::column;
    let mut out = Vec::new();
    for b in crate::parquet_io::read_batches(dir, SPLITS_TABLE, None)? {
        let ids = column::<UInt32Array>(&b, "image_id", &path)?;
        let names = column::<StringArray>(&b, "name", &path)?;
        let splits = column::<StringArray>(&b, "split", &path)?;
        let seeds = column::<UInt64Array>(&b, "seed", &path)?;
        for i in 0..ids.len() {
            out.push(Assignment {
                image_id: ids.value(i),
                name: names.value(i).into(),
                split: splits.value(i).into(),
                seed: seeds.value(i),
            });
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn photos(n: usize) -> Vec<(u32, String)> {
        (0..n)
            .map(|i| (i as u32 + 1, format!("p{i:05}.jpg")))
            .collect()
    }

    #[test]
    fn exact_counts_disjoint_and_deterministic() {
        let (a, c) = assign(&photos(1000), &[], 100, 7).unwrap();
        assert_eq!(a.iter().filter(|x| x.split == "val").count(), 100);
        assert_eq!((c.new_val, c.new_train), (100, 900));
        let mut names: Vec<&str> = a.iter().map(|x| x.name.as_str()).collect();
        names.dedup();
        assert_eq!(
            names.len(),
            1000,
            "each photo once: train and val are disjoint"
        );
        assert_eq!(
            assign(&photos(1000), &[], 100, 7).unwrap().0,
            a,
            "same seed, same split"
        );
        assert_ne!(
            assign(&photos(1000), &[], 100, 8).unwrap().0,
            a,
            "another seed, another split"
        );
        // Order of the input does not matter.
        let mut rev = photos(1000);
        rev.reverse();
        assert_eq!(assign(&rev, &[], 100, 7).unwrap().0, a);
    }

    #[test]
    fn new_photos_never_move_old_assignments() {
        let (first, _) = assign(&photos(500), &[], 50, 1).unwrap();
        let (second, c) = assign(&photos(800), &first, 80, 99).unwrap();
        for a in &first {
            assert!(second.contains(a), "{a:?} changed");
        }
        assert_eq!((c.kept_val, c.new_val, c.new_train), (50, 30, 270));
        assert_eq!(second.iter().filter(|x| x.split == "val").count(), 80);
    }

    #[test]
    fn impossible_requests_name_both_numbers() {
        let e = assign(&photos(19), &[], 100, 1).unwrap_err();
        assert!(e.contains("--val 100") && e.contains("only 19"), "{e}");
        let (first, _) = assign(&photos(50), &[], 10, 1).unwrap();
        let e = assign(&photos(50), &first, 5, 1).unwrap_err();
        assert!(
            e.contains("--val 5") && e.contains("10 validation photos already"),
            "{e}"
        );
        let (none, c) = assign(&photos(5), &[], 0, 1).unwrap();
        assert_eq!((none.len(), c.new_val), (5, 0));
        let (tiny, _) = assign(&photos(1), &[], 1, 1).unwrap();
        assert_eq!(tiny[0].split, "val");
    }
}
