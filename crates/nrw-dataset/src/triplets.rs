//! `triplets.parquet`: per anchor photo, its k nearest and k furthest photos under the style
//! distance, in order, with squared distances: what appearance pretraining samples from.

use crate::location::Location;

use crate::store::Store;
use std::sync::Arc;

use arrow_array::builder::{Float64Builder, ListBuilder, UInt32Builder};
use arrow_array::{RecordBatch, StringArray, UInt32Array};
use arrow_schema::{DataType, Field, Schema, SchemaRef};

use crate::error::{DatasetError, Result};
use crate::manifest::FileEntry;

/// Table path of the triplets inside a dataset.
pub const TRIPLETS_TABLE: &str = "triplets.parquet";

/// One anchor's row.
#[derive(Debug, Clone, PartialEq)]
pub struct TripletRow {
    pub anchor_id: u32,
    pub anchor_name: String,
    pub nearest_ids: Vec<u32>,
    pub nearest_d2: Vec<f64>,
    pub furthest_ids: Vec<u32>,
    pub furthest_d2: Vec<f64>,
}

/// How a table was made (same value on every row).
#[derive(Debug, Clone, PartialEq)]
pub struct TripletInfo {
    /// Descriptor tier the distances are in.
    pub tier: String,
    /// `exact`, or the approximate method.
    pub method: String,
    /// Splits anchors and neighbours were drawn from, e.g. `train`.
    pub scope: String,
    /// Recall@k of the nearest and furthest lists against the exact path, when measured.
    pub recall: Option<(f64, f64)>,
}

/// Arrow schema of `triplets.parquet` (documented in schemas/triplets.toml).
pub fn triplets_schema() -> SchemaRef {
    let list = |t: DataType| DataType::List(Arc::new(Field::new("item", t, false)));
    Arc::new(Schema::new(vec![
        Field::new("anchor_id", DataType::UInt32, false),
        Field::new("anchor_name", DataType::Utf8, false),
        Field::new("nearest_ids", list(DataType::UInt32), false),
        Field::new("nearest_d2", list(DataType::Float64), false),
        Field::new("furthest_ids", list(DataType::UInt32), false),
        Field::new("furthest_d2", list(DataType::Float64), false),
        Field::new("tier", DataType::Utf8, false),
        Field::new("method", DataType::Utf8, false),
        Field::new("scope", DataType::Utf8, false),
        Field::new("recall_nearest", DataType::Float64, true),
        Field::new("recall_furthest", DataType::Float64, true),
    ]))
}

/// Write the table atomically.
pub fn write_triplets(dir: &Store, info: &TripletInfo, rows: &[TripletRow]) -> Result<FileEntry> {
    let schema = triplets_schema();
    let field = |i: usize| match schema.field(i).data_type() {
        DataType::List(f) => f.clone(),
        _ => unreachable!("list column"),
    };
    let ids = |get: &dyn Fn(&TripletRow) -> &Vec<u32>, i: usize| {
        let mut b = ListBuilder::new(UInt32Builder::new()).with_field(field(i));
        for r in rows {
            b.values().append_slice(get(r));
            b.append(true);
        }
        Arc::new(b.finish()) as Arc<dyn arrow_array::Array>
    };
    let d2 = |get: &dyn Fn(&TripletRow) -> &Vec<f64>, i: usize| {
        let mut b = ListBuilder::new(Float64Builder::new()).with_field(field(i));
        for r in rows {
            b.values().append_slice(get(r));
            b.append(true);
        }
        Arc::new(b.finish()) as Arc<dyn arrow_array::Array>
    };
    let rep = |s: &str| {
        Arc::new(StringArray::from_iter_values(rows.iter().map(|_| s)))
            as Arc<dyn arrow_array::Array>
    };
    let batch = RecordBatch::try_new(
        schema.clone(),
        vec![
            Arc::new(UInt32Array::from_iter_values(
                rows.iter().map(|r| r.anchor_id),
            )),
            Arc::new(StringArray::from_iter_values(
                rows.iter().map(|r| r.anchor_name.as_str()),
            )),
            ids(&|r| &r.nearest_ids, 2),
            d2(&|r| &r.nearest_d2, 3),
            ids(&|r| &r.furthest_ids, 4),
            d2(&|r| &r.furthest_d2, 5),
            rep(&info.tier),
            rep(&info.method),
            rep(&info.scope),
            Arc::new(arrow_array::Float64Array::from_iter(
                rows.iter().map(|_| info.recall.map(|r| r.0)),
            )),
            Arc::new(arrow_array::Float64Array::from_iter(
                rows.iter().map(|_| info.recall.map(|r| r.1)),
            )),
        ],
    )
    .map_err(|e| DatasetError::Arrow {
        table: TRIPLETS_TABLE.into(),
        source: e,
    })?;
    crate::parquet_io::write_table(dir, TRIPLETS_TABLE, &batch)
}

/// Read the table back (the trainer's triplet sampler reads it), or None before `triplets`.
pub fn read_triplets(dir: &Store) -> Result<Option<Vec<TripletRow>>> {
    if !dir.exists(TRIPLETS_TABLE)? {
        return Ok(None);
    }
    // A small table read whole, so its manifest hash is checked on every read.
    let data = crate::Manifest::read(dir)?.read_checked(dir, TRIPLETS_TABLE)?;
    triplets_in(data, &dir.name(TRIPLETS_TABLE)).map(Some)
}

/// The table as Arrow batches (what a dataframe library takes without a copy), its manifest
/// hash checked; None before `triplets`.
pub fn table(dir: &Store) -> Result<Option<Vec<arrow_array::RecordBatch>>> {
    if !dir.exists(TRIPLETS_TABLE)? {
        return Ok(None);
    }
    let data = crate::Manifest::read(dir)?.read_checked(dir, TRIPLETS_TABLE)?;
    let path = dir.name(TRIPLETS_TABLE);
    crate::parquet_io::batches_from(data, path, None, 65_536)?
        .collect::<Result<Vec<_>>>()
        .map(Some)
}

/// The rows of a triplets table's bytes (`path` names them in errors).
pub fn triplets_in<R: parquet::file::reader::ChunkReader + 'static>(
    data: R,
    path: &Location,
) -> Result<Vec<TripletRow>> {
    use crate::parquet_io::column;
    use arrow_array::types::{Float64Type, UInt32Type};
    use arrow_array::ListArray;
    let mut out = Vec::new();
    for b in crate::parquet_io::batches_from(data, path.clone(), None, 1024)? {
        let b = b?;
        let path = path.clone();
        let anchors = column::<UInt32Array>(&b, "anchor_id", &path)?;
        let names = column::<StringArray>(&b, "anchor_name", &path)?;
        let lists = |name: &str| column::<ListArray>(&b, name, &path);
        let (ni, nd, fi, fd) = (
            lists("nearest_ids")?,
            lists("nearest_d2")?,
            lists("furthest_ids")?,
            lists("furthest_d2")?,
        );
        for i in 0..b.num_rows() {
            out.push(TripletRow {
                anchor_id: anchors.value(i),
                anchor_name: names.value(i).to_string(),
                nearest_ids: list_values::<UInt32Type>(ni, i, "nearest_ids", &path)?,
                nearest_d2: list_values::<Float64Type>(nd, i, "nearest_d2", &path)?,
                furthest_ids: list_values::<UInt32Type>(fi, i, "furthest_ids", &path)?,
                furthest_d2: list_values::<Float64Type>(fd, i, "furthest_d2", &path)?,
            });
        }
    }
    Ok(out)
}

/// Row `i` of a list column as a vector of its primitive values.
fn list_values<T: arrow_array::ArrowPrimitiveType>(
    l: &arrow_array::ListArray,
    i: usize,
    name: &str,
    path: &Location,
) -> Result<Vec<T::Native>> {
    let v = l.value(i);
    let a = v
        .as_any()
        .downcast_ref::<arrow_array::PrimitiveArray<T>>()
        .ok_or_else(|| DatasetError::Schema {
            path: path.into(),
            problem: format!("column `{name}` does not hold {} lists", T::DATA_TYPE),
        })?;
    Ok(a.values().to_vec())
}
