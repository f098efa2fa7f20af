//! `scene/duplicates.parquet`: groups of kept photos that are one picture (the same upload
//! twice, resized, re-encoded, cropped or recoloured copies), found by ingest. Split keeps a
//! group on one side, so no copy of a validation photo is trained on; QA shows the groups.
//! One row per member of a group of two or more; an empty table says ingest looked and found
//! none (a dataset without the file was ingested before ingest looked).

use std::collections::BTreeMap;
use std::sync::Arc;

use arrow_array::{Array, ArrayRef, Float64Array, RecordBatch, StringArray, UInt32Array};
use arrow_schema::{DataType, Field, Schema, SchemaRef};

use crate::error::{DatasetError, Result};
use crate::store::Store;

/// Table path of the near-duplicate groups inside a dataset.
pub const DUPLICATES_TABLE: &str = "scene/duplicates.parquet";

/// One photo of a group, with the evidence that put it there.
#[derive(Debug, Clone, PartialEq)]
pub struct Member {
    pub image_id: u32,
    pub name: String,
    /// The group: the smallest image id among its members.
    pub group: u32,
    /// A member it was matched to (the first pair, by image id, that put it in the group).
    pub matched_with: Option<u32>,
    /// Bits in which the two perceptual hashes differ (of 64).
    pub phash_distance: Option<u32>,
    /// Normalised cross-correlation of the two photos' grey levels where one covers the
    /// other, aligned through their cameras; none when the hashes alone decided.
    pub ncc: Option<f64>,
}

/// Arrow schema of `scene/duplicates.parquet` (documented in schemas/scene_duplicates.toml).
pub fn duplicates_schema() -> SchemaRef {
    Arc::new(Schema::new(vec![
        Field::new("image_id", DataType::UInt32, false),
        Field::new("name", DataType::Utf8, false),
        Field::new("group", DataType::UInt32, false),
        Field::new("matched_with", DataType::UInt32, true),
        Field::new("phash_distance", DataType::UInt32, true),
        Field::new("ncc", DataType::Float64, true),
    ]))
}

/// Write the groups (members in image-id order); an empty list writes an empty table.
pub fn write_duplicates(store: &Store, members: &[Member]) -> Result<crate::FileEntry> {
    let mut rows: Vec<&Member> = members.iter().collect();
    rows.sort_by_key(|m| m.image_id);
    let columns: Vec<ArrayRef> = vec![
        Arc::new(UInt32Array::from_iter_values(
            rows.iter().map(|m| m.image_id),
        )),
        Arc::new(StringArray::from_iter_values(
            rows.iter().map(|m| m.name.as_str()),
        )),
        Arc::new(UInt32Array::from_iter_values(rows.iter().map(|m| m.group))),
        Arc::new(UInt32Array::from_iter(rows.iter().map(|m| m.matched_with))),
        Arc::new(UInt32Array::from_iter(
            rows.iter().map(|m| m.phash_distance),
        )),
        Arc::new(Float64Array::from_iter(rows.iter().map(|m| m.ncc))),
    ];
    let batch = RecordBatch::try_new(duplicates_schema(), columns).map_err(|source| {
        DatasetError::Arrow {
            table: DUPLICATES_TABLE.into(),
            source,
        }
    })?;
    crate::parquet_io::write_table(store, DUPLICATES_TABLE, &batch)
}

/// Every member of every group, in image-id order; none when the dataset has no table.
pub fn read_duplicates(store: &Store) -> Result<Vec<Member>> {
    use crate::parquet_io::column;
    let mut out = Vec::new();
    if !store.exists(DUPLICATES_TABLE)? {
        return Ok(out);
    }
    let path = store.name(DUPLICATES_TABLE);
    for b in crate::parquet_io::read_batches(store, DUPLICATES_TABLE, None)? {
        let ids = column::<UInt32Array>(&b, "image_id", &path)?;
        let names = column::<StringArray>(&b, "name", &path)?;
        let groups = column::<UInt32Array>(&b, "group", &path)?;
        let with = column::<UInt32Array>(&b, "matched_with", &path)?;
        let dist = column::<UInt32Array>(&b, "phash_distance", &path)?;
        let ncc = column::<Float64Array>(&b, "ncc", &path)?;
        for i in 0..b.num_rows() {
            out.push(Member {
                image_id: ids.value(i),
                name: names.value(i).to_string(),
                group: groups.value(i),
                matched_with: (!with.is_null(i)).then(|| with.value(i)),
                phash_distance: (!dist.is_null(i)).then(|| dist.value(i)),
                ncc: (!ncc.is_null(i)).then(|| ncc.value(i)),
            });
        }
    }
    Ok(out)
}

/// The groups as lists of their members' names, in group order (what inspect and QA show).
pub fn names_by_group(members: &[Member]) -> Vec<Vec<String>> {
    let mut groups: BTreeMap<u32, Vec<String>> = BTreeMap::new();
    for m in members {
        groups.entry(m.group).or_default().push(m.name.clone());
    }
    groups.into_values().collect()
}

/// Each photo's group, by name (what split joins on): photos in no group are absent.
pub fn group_of(members: &[Member]) -> BTreeMap<String, u32> {
    members.iter().map(|m| (m.name.clone(), m.group)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn groups_round_trip_through_the_table() {
        let dir = tempfile::tempdir().unwrap();
        let store = Store::local(dir.path());
        assert!(read_duplicates(&store).unwrap().is_empty());
        let members = vec![
            Member {
                image_id: 7,
                name: "b.jpg".into(),
                group: 3,
                matched_with: Some(3),
                phash_distance: Some(2),
                ncc: Some(0.97),
            },
            Member {
                image_id: 3,
                name: "a.jpg".into(),
                group: 3,
                matched_with: None,
                phash_distance: None,
                ncc: None,
            },
        ];
        write_duplicates(&store, &members).unwrap();
        let back = read_duplicates(&store).unwrap();
        assert_eq!(back, vec![members[1].clone(), members[0].clone()]);
        assert_eq!(group_of(&back)["b.jpg"], 3);
    }
}
