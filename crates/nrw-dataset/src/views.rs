//! View shards (`shards/views-NNNNN.parquet`): one row per kept photo with the resized
//! photo, the colour render with coverage as alpha, the depth as EXR, optional normals,
//! and everything needed to use them (ids, scaled intrinsics, pose, empty ratio).
//! Shards are small (default 64 rows) with row groups of 8 rows, so a reader streams them
//! and random access costs one small row group.

use crate::location::Location;
use crate::store::Store;
use std::sync::Arc;

use arrow_array::builder::{BinaryBuilder, Float64Builder, ListBuilder};
use arrow_array::{ArrayRef, Float64Array, RecordBatch, StringArray, UInt32Array};
use arrow_schema::{DataType, Field, Schema, SchemaRef};
use parquet::basic::Compression;
use parquet::schema::types::ColumnPath;

use crate::error::{DatasetError, Result};
use crate::manifest::FileEntry;
pub use crate::payload::{crc32, crc_column, payload_mismatches, PayloadMismatch};

/// Rows per row group inside a shard: the unit of random access.
pub const ROW_GROUP_ROWS: usize = 8;

/// Folder of the view shards inside a dataset.
pub const SHARDS_DIR: &str = "shards";

/// Path of view shard `g`, relative to the dataset (as the manifest lists it).
pub fn shard_path(g: usize) -> String {
    format!("{SHARDS_DIR}/views-{g:05}.parquet")
}

/// Whether a dataset-relative path (a manifest entry) is a view shard.
pub fn is_shard(rel: &str) -> bool {
    rel.strip_prefix(SHARDS_DIR)
        .is_some_and(|r| r.starts_with('/'))
}

/// Files in the dataset's shard folder that are none of `keep` (manifest entries): shards
/// of an earlier run with other parameters.
pub fn stale_shards(dir: &Store, keep: &[FileEntry]) -> Result<Vec<String>> {
    Ok(dir
        .list(SHARDS_DIR)?
        .into_iter()
        .filter(|rel| !keep.iter().any(|k| &k.path == rel))
        .collect())
}

/// Every column name of a view shard, spelled once: the schema, the writer and the reader
/// (and schemas/views.toml, which a test checks against the schema) use these.
pub mod columns {
    pub const IMAGE_ID: &str = "image_id";
    pub const NAME: &str = "name";
    pub const CAMERA_ID: &str = "camera_id";
    pub const MODEL: &str = "model";
    pub const WIDTH: &str = "width";
    pub const HEIGHT: &str = "height";
    pub const SCALE_X: &str = "scale_x";
    pub const SCALE_Y: &str = "scale_y";
    pub const PARAMS: &str = "params";
    pub const QW: &str = "qw";
    pub const QX: &str = "qx";
    pub const QY: &str = "qy";
    pub const QZ: &str = "qz";
    pub const TX: &str = "tx";
    pub const TY: &str = "ty";
    pub const TZ: &str = "tz";
    pub const EMPTY_RATIO: &str = "empty_ratio";
    pub const PHOTO_PNG: &str = "photo_png";
    pub const COLOR_PNG: &str = "color_png";
    pub const DEPTH_EXR: &str = "depth_exr";
    pub const NORMAL_PNG: &str = "normal_png";
    pub const SEMANTICS_PNG: &str = "semantics_png";
    pub const TRANSIENT_PNG: &str = "transient_png";
    pub const LABELS_PNG: &str = "labels_png";
}

/// The payload columns of a shard (encoded PNG or EXR bytes). Each has a `<name>_crc32`
/// column beside it ([`crc_column`]) that every reader checks before decoding, so a byte that
/// changed on disk or in transit is an error naming file, row and column, never a silently
/// different image.
pub const PAYLOAD_COLUMNS: [&str; 7] = [
    columns::PHOTO_PNG,
    columns::COLOR_PNG,
    columns::DEPTH_EXR,
    columns::NORMAL_PNG,
    columns::SEMANTICS_PNG,
    columns::TRANSIENT_PNG,
    columns::LABELS_PNG,
];

/// One kept view.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewRow {
    pub image_id: u32,
    pub name: String,
    pub camera_id: u32,
    pub model: String,
    /// Render (and resized photo) size.
    pub width: u32,
    pub height: u32,
    /// Render size / photo size per axis.
    pub scale_x: f64,
    pub scale_y: f64,
    /// The camera's parameters scaled to the render size (COLMAP order).
    pub params: Vec<f64>,
    /// World→camera pose in the model's world frame.
    pub qvec: [f64; 4],
    pub tvec: [f64; 3],
    pub empty_ratio: f64,
    pub photo_png: Vec<u8>,
    pub color_png: Vec<u8>,
    pub depth_exr: Vec<u8>,
    pub normal_png: Option<Vec<u8>>,
    /// ADE20K colour-coded labels, PNG RGB8, when --semantics was given.
    pub semantics_png: Option<Vec<u8>>,
    /// Transient mask, PNG L8 (255 = transient class), when --semantics was given.
    pub transient_png: Option<Vec<u8>>,
    /// ADE20K class ids (0 = unlabelled), PNG L8, when --semantics was given: the colour
    /// coding is not invertible (road and skyscraper share a colour), so exports that recode
    /// classes (the paper's official colours) read the ids from here.
    pub labels_png: Option<Vec<u8>>,
}

/// Arrow schema of a view shard (documented in schemas/views.toml).
pub fn views_schema() -> SchemaRef {
    let f = |n: &str, t: DataType| Field::new(n, t, false);
    let mut fields = vec![
        f(columns::IMAGE_ID, DataType::UInt32),
        f(columns::NAME, DataType::Utf8),
        f(columns::CAMERA_ID, DataType::UInt32),
        f(columns::MODEL, DataType::Utf8),
        f(columns::WIDTH, DataType::UInt32),
        f(columns::HEIGHT, DataType::UInt32),
        f(columns::SCALE_X, DataType::Float64),
        f(columns::SCALE_Y, DataType::Float64),
        f(
            columns::PARAMS,
            DataType::List(Arc::new(Field::new("item", DataType::Float64, false))),
        ),
        f(columns::QW, DataType::Float64),
        f(columns::QX, DataType::Float64),
        f(columns::QY, DataType::Float64),
        f(columns::QZ, DataType::Float64),
        f(columns::TX, DataType::Float64),
        f(columns::TY, DataType::Float64),
        f(columns::TZ, DataType::Float64),
        f(columns::EMPTY_RATIO, DataType::Float64),
        f(columns::PHOTO_PNG, DataType::Binary),
        f(columns::COLOR_PNG, DataType::Binary),
        f(columns::DEPTH_EXR, DataType::Binary),
        Field::new(columns::NORMAL_PNG, DataType::Binary, true),
        Field::new(columns::SEMANTICS_PNG, DataType::Binary, true),
        Field::new(columns::TRANSIENT_PNG, DataType::Binary, true),
        Field::new(columns::LABELS_PNG, DataType::Binary, true),
    ];
    // Each payload's CRC-32 beside it, nullable as the payload is.
    let crcs: Vec<Field> = PAYLOAD_COLUMNS
        .iter()
        .map(|c| {
            let nullable = fields.iter().any(|f| f.name() == c && f.is_nullable());
            Field::new(crc_column(c), DataType::UInt32, nullable)
        })
        .collect();
    fields.extend(crcs);
    Arc::new(Schema::new(fields))
}

fn batch(rows: &[ViewRow]) -> Result<RecordBatch> {
    let schema = views_schema();
    let u32s = |f: &dyn Fn(&ViewRow) -> u32| -> ArrayRef {
        Arc::new(UInt32Array::from_iter_values(rows.iter().map(f)))
    };
    let f64s = |f: &dyn Fn(&ViewRow) -> f64| -> ArrayRef {
        Arc::new(Float64Array::from_iter_values(rows.iter().map(f)))
    };
    let bins = |f: &dyn Fn(&ViewRow) -> Option<&[u8]>| -> ArrayRef {
        let mut b = BinaryBuilder::new();
        for r in rows {
            b.append_option(f(r));
        }
        Arc::new(b.finish())
    };
    let crcs = |f: &dyn Fn(&ViewRow) -> Option<&[u8]>| -> ArrayRef {
        Arc::new(UInt32Array::from_iter(rows.iter().map(|r| f(r).map(crc32))))
    };
    let item = match schema.field(8).data_type() {
        DataType::List(f) => f.clone(),
        _ => unreachable!("params is a list"),
    };
    let mut params = ListBuilder::new(Float64Builder::new()).with_field(item);
    for r in rows {
        params.values().append_slice(&r.params);
        params.append(true);
    }
    RecordBatch::try_new(
        schema,
        vec![
            u32s(&|r| r.image_id),
            Arc::new(StringArray::from_iter_values(
                rows.iter().map(|r| r.name.as_str()),
            )),
            u32s(&|r| r.camera_id),
            Arc::new(StringArray::from_iter_values(
                rows.iter().map(|r| r.model.as_str()),
            )),
            u32s(&|r| r.width),
            u32s(&|r| r.height),
            f64s(&|r| r.scale_x),
            f64s(&|r| r.scale_y),
            Arc::new(params.finish()),
            f64s(&|r| r.qvec[0]),
            f64s(&|r| r.qvec[1]),
            f64s(&|r| r.qvec[2]),
            f64s(&|r| r.qvec[3]),
            f64s(&|r| r.tvec[0]),
            f64s(&|r| r.tvec[1]),
            f64s(&|r| r.tvec[2]),
            f64s(&|r| r.empty_ratio),
            bins(&|r| Some(&r.photo_png)),
            bins(&|r| Some(&r.color_png)),
            bins(&|r| Some(&r.depth_exr)),
            bins(&|r| r.normal_png.as_deref()),
            bins(&|r| r.semantics_png.as_deref()),
            bins(&|r| r.transient_png.as_deref()),
            bins(&|r| r.labels_png.as_deref()),
            crcs(&|r| Some(&r.photo_png)),
            crcs(&|r| Some(&r.color_png)),
            crcs(&|r| Some(&r.depth_exr)),
            crcs(&|r| r.normal_png.as_deref()),
            crcs(&|r| r.semantics_png.as_deref()),
            crcs(&|r| r.transient_png.as_deref()),
            crcs(&|r| r.labels_png.as_deref()),
        ],
    )
    .map_err(|e| DatasetError::Arrow {
        table: "views".into(),
        source: e,
    })
}

/// Write a shard atomically at `dir/rel`; payload columns are stored uncompressed (PNG and
/// EXR are compressed already), metadata columns with zstd.
pub fn write_shard(dir: &Store, rel: &str, rows: &[ViewRow]) -> Result<FileEntry> {
    write_shard_batch(dir, rel, batch(rows)?)
}

/// [`write_shard`] of rows given up to it: they are dropped once in Arrow form, so a group's
/// payloads are held twice at most (Arrow and the encoded file), not three times.
pub fn write_shard_owned(dir: &Store, rel: &str, rows: Vec<ViewRow>) -> Result<FileEntry> {
    let b = batch(&rows)?;
    drop(rows);
    write_shard_batch(dir, rel, b)
}

fn write_shard_batch(dir: &Store, rel: &str, b: RecordBatch) -> Result<FileEntry> {
    let mut props = crate::parquet_io::writer_properties_builder(ROW_GROUP_ROWS);
    for c in PAYLOAD_COLUMNS {
        props = props
            .set_column_compression(ColumnPath::from(c), Compression::UNCOMPRESSED)
            .set_column_statistics_enabled(
                ColumnPath::from(c),
                parquet::file::properties::EnabledStatistics::None,
            );
    }
    crate::parquet_io::write_batch(dir, rel, &b, props.build())
}

/// Every payload of a shard's bytes checked against its checksum (what `verify` runs), a
/// row group at a time; `path` names the file.
pub fn check_shard(path: &Location, data: bytes::Bytes) -> Result<Vec<PayloadMismatch>> {
    let mut out = Vec::new();
    let mut row = 0;
    for b in crate::parquet_io::batches_from(data, path.clone(), None, ROW_GROUP_ROWS)? {
        let b = b?;
        let rows: Vec<usize> = (row..row + b.num_rows()).collect();
        for c in PAYLOAD_COLUMNS {
            out.extend(payload_mismatches(&b, &rows, c, path)?);
        }
        row += b.num_rows();
    }
    Ok(out)
}
