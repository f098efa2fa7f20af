//! Style descriptors of a dataset's kept photos: `descriptors/part-NNNNN.parquet`, one row
//! per photo. Each row names its tier, weights hash and preprocessing, so descriptors of
//! different kinds can never be mixed silently; parts are written atomically and a rerun
//! with the same settings skips the parts already there.

use crate::location::Location;
use crate::store::Store;
use std::sync::Arc;

use arrow_array::builder::{Float32Builder, ListBuilder};
use arrow_array::{Array, Float32Array, ListArray, RecordBatch, StringArray, UInt32Array};
use arrow_schema::{DataType, Field, Schema, SchemaRef};

use crate::error::{DatasetError, Result};
use crate::manifest::FileEntry;
use crate::parquet_io::{column, read_batches};

/// Folder of descriptor parts inside a dataset.
pub const DESCRIPTORS_DIR: &str = "descriptors";

/// What kind of descriptor a table holds: rows of different kinds are never compared.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DescriptorKind {
    pub tier: String,
    /// SHA-256 of the weights file; empty for tiers without weights.
    pub weights_sha256: String,
    pub preprocess: String,
}

/// One photo's descriptor.
#[derive(Debug, Clone, PartialEq)]
pub struct DescriptorRow {
    pub image_id: u32,
    pub name: String,
    pub descriptor: Vec<f32>,
}

/// Arrow schema of a descriptors part (documented in schemas/descriptors.toml).
pub fn descriptors_schema() -> SchemaRef {
    Arc::new(Schema::new(vec![
        Field::new("image_id", DataType::UInt32, false),
        Field::new("name", DataType::Utf8, false),
        Field::new("tier", DataType::Utf8, false),
        Field::new("weights_sha256", DataType::Utf8, false),
        Field::new("preprocess", DataType::Utf8, false),
        Field::new(
            "descriptor",
            DataType::List(Arc::new(Field::new("item", DataType::Float32, false))),
            false,
        ),
        Field::new("descriptor_crc32", DataType::UInt32, false),
    ]))
}

/// Part file name of group `k`.
pub fn part_path(k: usize) -> String {
    format!("{DESCRIPTORS_DIR}/part-{k:05}.parquet")
}

/// The group index of a part's dataset-relative path ([`part_path`]'s inverse), or None for
/// any other file.
pub fn part_index(rel: &str) -> Option<usize> {
    rel.strip_prefix(DESCRIPTORS_DIR)?
        .strip_prefix("/part-")?
        .strip_suffix(".parquet")?
        .parse()
        .ok()
}

/// Every part present in the dataset, by group index, ascending.
pub fn existing_parts(store: &Store) -> Result<Vec<usize>> {
    let mut parts: Vec<usize> = store
        .list(DESCRIPTORS_DIR)?
        .iter()
        .filter_map(|rel| part_index(rel))
        .collect();
    parts.sort_unstable();
    Ok(parts)
}

/// Whether a dataset-relative path (a manifest entry) is a descriptor part.
pub fn is_part(rel: &str) -> bool {
    rel.strip_prefix(DESCRIPTORS_DIR)
        .is_some_and(|r| r.starts_with("/part-"))
}

/// A descriptor's checksum: CRC-32 of its values as little-endian float32 bytes (in NumPy,
/// `zlib.crc32(np.asarray(d, "<f4").tobytes())`). Readers check it before using a row.
pub fn descriptor_crc32(values: &[f32]) -> u32 {
    let mut h = crc32fast::Hasher::new();
    for v in values {
        h.update(&v.to_le_bytes());
    }
    h.finalize()
}

/// Every descriptor row of the parts the manifest lists, as Arrow batches (what a dataframe
/// library takes without a copy), each row checked against its CRC-32 first.
pub fn table(dir: &Store) -> Result<Vec<RecordBatch>> {
    let mut out = Vec::new();
    for t in crate::Manifest::read(dir)?.tables {
        if !is_part(&t.path) {
            continue;
        }
        let path = &dir.name(&t.path);
        let mut row = 0;
        for b in read_batches(dir, &t.path, None)? {
            if let Some(m) = descriptor_mismatches(&b, row, path)?.first() {
                return Err(m.error(path));
            }
            row += b.num_rows();
            out.push(b);
        }
    }
    Ok(out)
}

/// Rows of a part's bytes whose descriptor does not match its checksum (`path` names the
/// file).
pub fn check_part(
    path: &Location,
    data: bytes::Bytes,
) -> Result<Vec<crate::payload::PayloadMismatch>> {
    let mut out = Vec::new();
    let mut row = 0;
    let cols = ["image_id", "descriptor", "descriptor_crc32"];
    for b in crate::parquet_io::batches_from(data, path.clone(), Some(&cols), 1024)? {
        let b = b?;
        out.extend(descriptor_mismatches(&b, row, path)?);
        row += b.num_rows();
    }
    Ok(out)
}

fn descriptor_mismatches(
    b: &RecordBatch,
    first_row: usize,
    path: &Location,
) -> Result<Vec<crate::payload::PayloadMismatch>> {
    let ids = column::<UInt32Array>(b, "image_id", path)?;
    let desc = column::<ListArray>(b, "descriptor", path)?;
    let crcs = column::<UInt32Array>(b, "descriptor_crc32", path)?;
    let mut out = Vec::new();
    for i in 0..b.num_rows() {
        let v = row_values(desc, i, path)?;
        out.extend(row_mismatch(ids.value(i), crcs.value(i), &v, first_row + i));
    }
    Ok(out)
}

/// Row `i`'s descriptor values.
fn row_values(desc: &ListArray, i: usize, path: &Location) -> Result<Float32Array> {
    desc.value(i)
        .as_any()
        .downcast_ref::<Float32Array>()
        .cloned()
        .ok_or_else(|| DatasetError::Schema {
            path: path.into(),
            problem: "descriptor is not float32".into(),
        })
}

/// The mismatch of one row's values against its stored CRC-32, if they differ.
fn row_mismatch(
    image_id: u32,
    stored: u32,
    values: &Float32Array,
    row: usize,
) -> Option<crate::payload::PayloadMismatch> {
    let computed = descriptor_crc32(values.values());
    (computed != stored).then(|| crate::payload::PayloadMismatch {
        row,
        image_id,
        column: "descriptor".into(),
        stored: Some(stored),
        computed: Some(computed),
    })
}

/// Write one part atomically.
pub fn write_part(
    dir: &Store,
    k: usize,
    kind: &DescriptorKind,
    rows: &[DescriptorRow],
) -> Result<FileEntry> {
    let schema = descriptors_schema();
    let item = match schema.field(5).data_type() {
        DataType::List(f) => f.clone(),
        _ => unreachable!("descriptor is a list"),
    };
    let mut lists = ListBuilder::new(Float32Builder::new()).with_field(item);
    for r in rows {
        lists.values().append_slice(&r.descriptor);
        lists.append(true);
    }
    let rep =
        |s: &str| Arc::new(StringArray::from_iter_values(rows.iter().map(|_| s))) as Arc<dyn Array>;
    let batch = RecordBatch::try_new(
        schema,
        vec![
            Arc::new(UInt32Array::from_iter_values(
                rows.iter().map(|r| r.image_id),
            )),
            Arc::new(StringArray::from_iter_values(
                rows.iter().map(|r| r.name.as_str()),
            )),
            rep(&kind.tier),
            rep(&kind.weights_sha256),
            rep(&kind.preprocess),
            Arc::new(lists.finish()),
            Arc::new(UInt32Array::from_iter_values(
                rows.iter().map(|r| descriptor_crc32(&r.descriptor)),
            )),
        ],
    )
    .map_err(|e| DatasetError::Arrow {
        table: part_path(k),
        source: e,
    })?;
    // The values stored as they are (no dictionary, no compression: float32 Grams barely
    // compress), so a part reads at memory speed and its bytes are the values themselves.
    let raw = parquet::schema::types::ColumnPath::new(vec![
        "descriptor".into(),
        "list".into(),
        "item".into(),
    ]);
    let props = crate::parquet_io::writer_properties_builder(65_536)
        .set_column_compression(raw.clone(), parquet::basic::Compression::UNCOMPRESSED)
        .set_column_dictionary_enabled(raw.clone(), false)
        .set_column_statistics_enabled(raw, parquet::file::properties::EnabledStatistics::None)
        .build();
    crate::parquet_io::write_batch(dir, &part_path(k), &batch, props)
}

/// Every row's kind in a batch holding the kind columns.
fn kinds_in(b: &RecordBatch, path: &Location) -> Result<Vec<DescriptorKind>> {
    let (tier, sha, pre) = (
        column::<StringArray>(b, "tier", path)?,
        column::<StringArray>(b, "weights_sha256", path)?,
        column::<StringArray>(b, "preprocess", path)?,
    );
    Ok((0..b.num_rows())
        .map(|i| DescriptorKind {
            tier: tier.value(i).into(),
            weights_sha256: sha.value(i).into(),
            preprocess: pre.value(i).into(),
        })
        .collect())
}

/// The kinds of a part's rows, read without the descriptors themselves (the kind columns only).
pub fn read_kinds(dir: &Store, rel: &str) -> Result<Vec<DescriptorKind>> {
    let path = &dir.name(rel);
    let mut out = Vec::new();
    for b in read_batches(dir, rel, Some(&["tier", "weights_sha256", "preprocess"]))? {
        out.extend(kinds_in(&b, path)?);
    }
    Ok(out)
}

/// Read a part: its kind (all rows must agree) and rows.
pub fn read_part(dir: &Store, rel: &str) -> Result<(Option<DescriptorKind>, Vec<DescriptorRow>)> {
    part_in(dir.chunks(rel)?, &dir.name(rel))
}

/// A part's kind and rows from its bytes (`path` names them in errors), every descriptor
/// checked against its CRC-32.
pub fn part_in<R: parquet::file::reader::ChunkReader + 'static>(
    data: R,
    path: &Location,
) -> Result<(Option<DescriptorKind>, Vec<DescriptorRow>)> {
    let mut kind: Option<DescriptorKind> = None;
    let mut rows = Vec::new();
    for b in crate::parquet_io::batches_from(data, path.clone(), None, 1024)? {
        let b = b?;
        let crcs = column::<UInt32Array>(&b, "descriptor_crc32", path)?;
        let ids = column::<UInt32Array>(&b, "image_id", path)?;
        let names = column::<StringArray>(&b, "name", path)?;
        let kinds = kinds_in(&b, path)?;
        let desc = column::<ListArray>(&b, "descriptor", path)?;
        for (i, k) in kinds.into_iter().enumerate() {
            match &kind {
                None => kind = Some(k),
                Some(prev) if *prev != k => {
                    return Err(DatasetError::Value {
                        path: path.into(),
                        record: format!("image {}", ids.value(i)),
                        field: "tier/weights_sha256/preprocess".into(),
                        problem: format!("descriptor kind {k:?} differs from the part's {prev:?}"),
                    })
                }
                _ => {}
            }
            let v = row_values(desc, i, path)?;
            // Checked before the row is used: one pass over the values.
            if let Some(m) = row_mismatch(ids.value(i), crcs.value(i), &v, rows.len()) {
                return Err(m.error(path));
            }
            rows.push(DescriptorRow {
                image_id: ids.value(i),
                name: names.value(i).into(),
                descriptor: v.values().to_vec(),
            });
        }
    }
    Ok((kind, rows))
}

/// Every descriptor of a dataset, refusing mixed kinds; `None` when there are none.
/// Only the parts the manifest lists count (parts of unfinished style units do not). Holds
/// N descriptors: the stages read them through [`Index::visit`] instead.
pub fn read_all(dir: &Store) -> Result<Option<(DescriptorKind, Vec<DescriptorRow>)>> {
    let Some(index) = Index::read(dir)? else {
        return Ok(None);
    };
    let mut values: Vec<Vec<f32>> = vec![Vec::new(); index.entries.len()];
    index.visit(dir, &mut |i, v| values[i] = v.to_vec())?;
    let rows = index
        .entries
        .into_iter()
        .zip(values)
        .map(|(e, descriptor)| DescriptorRow {
            image_id: e.image_id,
            name: e.name,
            descriptor,
        })
        .collect();
    Ok(Some((index.kind, rows)))
}

/// One described photo of an [`Index`].
#[derive(Debug, Clone, PartialEq)]
pub struct Entry {
    pub image_id: u32,
    pub name: String,
}

/// A dataset's descriptors without their values: their kind and the photos they describe,
/// in image-id order. Whole-collection stages read the values through [`Index::visit`], a
/// few rows at a time, so memory holds N names, never N descriptors.
#[derive(Debug, Clone)]
pub struct Index {
    pub kind: DescriptorKind,
    pub entries: Vec<Entry>,
    parts: Vec<String>,
}

/// Rows decoded at a time while visiting (a reference-tier descriptor is 1.2 MB).
const VISIT_ROWS: usize = 16;

impl Index {
    /// The index of the parts the manifest lists (as [`read_all`] reads them: mixed kinds
    /// refused); `None` when there are no descriptors. A photo described twice is refused.
    pub fn read(dir: &Store) -> Result<Option<Index>> {
        let parts: Vec<String> = crate::Manifest::read(dir)?
            .tables
            .into_iter()
            .map(|t| t.path)
            .filter(|p| is_part(p))
            .collect();
        let mut kind: Option<DescriptorKind> = None;
        let mut entries = Vec::new();
        for p in &parts {
            let path = &dir.name(p);
            let cols = ["image_id", "name", "tier", "weights_sha256", "preprocess"];
            for b in read_batches(dir, p, Some(&cols))? {
                let ids = column::<UInt32Array>(&b, "image_id", path)?;
                let names = column::<StringArray>(&b, "name", path)?;
                for (i, k) in kinds_in(&b, path)?.into_iter().enumerate() {
                    if let Some(prev) = kind.as_ref().filter(|prev| **prev != k) {
                        return Err(DatasetError::Value {
                            path: path.clone(),
                            record: format!("image {}", ids.value(i)),
                            field: "tier/weights_sha256/preprocess".into(),
                            problem: format!(
                                "descriptors of another kind ({k:?}) than earlier ones ({prev:?})"
                            ),
                        });
                    }
                    kind = Some(k);
                    entries.push(Entry {
                        image_id: ids.value(i),
                        name: names.value(i).into(),
                    });
                }
            }
        }
        entries.sort_by_key(|e| e.image_id);
        if let Some(w) = entries.windows(2).find(|w| w[0].image_id == w[1].image_id) {
            return Err(DatasetError::Value {
                path: dir.name(DESCRIPTORS_DIR),
                record: format!("image {}", w[0].image_id),
                field: "image_id".into(),
                problem: "described twice".into(),
            });
        }
        Ok(kind.map(|kind| Index {
            kind,
            entries,
            parts,
        }))
    }

    /// Keep only the photos `keep` accepts (their order stays).
    pub fn retain(&mut self, keep: impl Fn(&Entry) -> bool) {
        self.entries.retain(keep);
    }

    /// Visit every kept descriptor once, with its position in `entries`, part by part in
    /// file order (image-id order, as style writes them); every row of the parts read is
    /// checked against its CRC-32 before `f` sees any later one.
    pub fn visit(&self, dir: &Store, f: &mut dyn FnMut(usize, &[f32])) -> Result<()> {
        let pos: std::collections::HashMap<u32, usize> = self
            .entries
            .iter()
            .enumerate()
            .map(|(i, e)| (e.image_id, i))
            .collect();
        for p in &self.parts {
            let path = &dir.name(p);
            let cols = ["image_id", "descriptor", "descriptor_crc32"];
            let mut row = 0;
            for b in crate::parquet_io::batches(dir, p, Some(&cols), VISIT_ROWS)? {
                let b = b?;
                let ids = column::<UInt32Array>(&b, "image_id", path)?;
                let crcs = column::<UInt32Array>(&b, "descriptor_crc32", path)?;
                let desc = column::<ListArray>(&b, "descriptor", path)?;
                for i in 0..b.num_rows() {
                    // Every row is checked, kept or not: a damaged part is refused whole,
                    // whichever photos a stage reads from it.
                    let v = row_values(desc, i, path)?;
                    if let Some(m) = row_mismatch(ids.value(i), crcs.value(i), &v, row + i) {
                        return Err(m.error(path));
                    }
                    if let Some(&at) = pos.get(&ids.value(i)) {
                        f(at, v.values());
                    }
                }
                row += b.num_rows();
            }
        }
        Ok(())
    }
}
