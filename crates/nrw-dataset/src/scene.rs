//! The scene tables: `scene/cameras.parquet` and `scene/images.parquet`, one row per COLMAP
//! camera and per registered image. Later stages join on `camera_id` and `image_id`.

use crate::store::Store;
use std::collections::BTreeMap;
use std::sync::Arc;

use arrow_array::builder::{Float64Builder, ListBuilder, StringBuilder};
use arrow_array::{ArrayRef, BooleanArray, Float64Array, RecordBatch, StringArray, UInt32Array};
use arrow_schema::{DataType, Field, Schema, SchemaRef};
use nrw_colmap::{pose::QUAT_NORM_TOLERANCE, Reconstruction};

use crate::error::{DatasetError, Result};

/// Table path of the cameras table inside a dataset.
pub const CAMERAS_TABLE: &str = "scene/cameras.parquet";
/// Table path of the images table inside a dataset.
pub const IMAGES_TABLE: &str = "scene/images.parquet";

/// An image's `verdict` in `scene/images.parquet`, typed: counts and branches name a variant,
/// so none can misspell a verdict; the table holds [`ImageVerdict::name`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum ImageVerdict {
    /// The view entered the dataset (the renderer's `FilterVerdict::Kept`).
    Kept,
    /// The photo's shorter side is under the filter's minimum.
    TooSmall,
    /// The render is emptier than the filter allows.
    TooSparse,
    /// The photo or label map cannot be decoded whole (truncated, corrupt, not an image);
    /// `verdict_detail` holds the decoder's message.
    Unreadable,
    /// The photo's sharpness (variance of the Laplacian) is under `--min-sharpness`.
    TooBlurry,
}

impl ImageVerdict {
    /// Every verdict.
    pub const ALL: [ImageVerdict; 5] = [
        ImageVerdict::Kept,
        ImageVerdict::TooSmall,
        ImageVerdict::TooSparse,
        ImageVerdict::Unreadable,
        ImageVerdict::TooBlurry,
    ];

    /// The word the images table holds.
    pub const fn name(self) -> &'static str {
        match self {
            ImageVerdict::Kept => "kept",
            ImageVerdict::TooSmall => "too_small",
            ImageVerdict::TooSparse => "too_sparse",
            ImageVerdict::Unreadable => "unreadable",
            ImageVerdict::TooBlurry => "too_blurry",
        }
    }

    /// The verdict a table's word names, if any.
    pub fn of(name: &str) -> Option<ImageVerdict> {
        ImageVerdict::ALL.into_iter().find(|v| v.name() == name)
    }
}

/// The `verdict` of a view that entered the dataset; every other verdict names why a photo
/// was dropped.
pub const VERDICT_KEPT: &str = ImageVerdict::Kept.name();

/// The `verdict` of a view whose photo or label map cannot be decoded whole.
pub const VERDICT_UNREADABLE: &str = ImageVerdict::Unreadable.name();

fn list_of(item: DataType) -> DataType {
    DataType::List(Arc::new(Field::new("item", item, false)))
}

/// Arrow schema of `scene/cameras.parquet` (documented in schemas/scene_cameras.toml).
pub fn cameras_schema() -> SchemaRef {
    Arc::new(Schema::new(vec![
        Field::new("camera_id", DataType::UInt32, false),
        Field::new("model", DataType::Utf8, false),
        Field::new("width", DataType::UInt32, false),
        Field::new("height", DataType::UInt32, false),
        Field::new("params", list_of(DataType::Float64), false),
        Field::new("param_names", list_of(DataType::Utf8), false),
    ]))
}

/// Arrow schema of `scene/images.parquet` (documented in schemas/scene_images.toml).
pub fn images_schema() -> SchemaRef {
    let f64f = |n: &str| Field::new(n, DataType::Float64, false);
    Arc::new(Schema::new(vec![
        Field::new("image_id", DataType::UInt32, false),
        Field::new("name", DataType::Utf8, false),
        Field::new("camera_id", DataType::UInt32, false),
        f64f("qw"),
        f64f("qx"),
        f64f("qy"),
        f64f("qz"),
        f64f("tx"),
        f64f("ty"),
        f64f("tz"),
        f64f("center_x"),
        f64f("center_y"),
        f64f("center_z"),
        Field::new("quat_renormalized", DataType::Boolean, false),
        Field::new("photo_width", DataType::UInt32, true),
        Field::new("photo_height", DataType::UInt32, true),
        Field::new("photo_matches_camera", DataType::Boolean, true),
        Field::new("num_points2d", DataType::UInt32, false),
        Field::new("num_observations", DataType::UInt32, false),
        Field::new("verdict", DataType::Utf8, false),
        Field::new("verdict_value", DataType::Float64, false),
        Field::new("verdict_detail", DataType::Utf8, true),
        Field::new("empty_ratio", DataType::Float64, true),
        Field::new("render_width", DataType::UInt32, true),
        Field::new("render_height", DataType::UInt32, true),
        Field::new("shard", DataType::Utf8, true),
        Field::new("depth_min", DataType::Float64, true),
        Field::new("depth_max", DataType::Float64, true),
        Field::new("sharpness", DataType::Float64, true),
        Field::new("luma_mean", DataType::Float64, true),
        Field::new("luma_std", DataType::Float64, true),
        Field::new("dark_fraction", DataType::Float64, true),
        Field::new("bright_fraction", DataType::Float64, true),
        Field::new("phash", DataType::Utf8, true),
    ]))
}

/// What a photo's pixels say about it before any model does: blur, exposure, and a
/// perceptual hash that finds copies of one picture (recorded for every photo ingest decodes).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PhotoSignals {
    /// Variance of the Laplacian of the photo's grey levels, as instant-ngp's colmap2nerf
    /// records it (OpenCV's 3×3 kernel on the full-size photo: it grows with resolution).
    pub sharpness: f64,
    /// Mean grey level, 0–255.
    pub luma_mean: f64,
    /// Standard deviation of the grey levels (a flat photo, all black or all white, has 0:
    /// its hash says nothing and it is in no near-duplicate group).
    pub luma_std: f64,
    /// Fraction of pixels at grey level ≤ [`DARK_LEVEL`] (crushed shadows).
    pub dark_fraction: f64,
    /// Fraction of pixels at grey level ≥ [`BRIGHT_LEVEL`] (clipped highlights).
    pub bright_fraction: f64,
    /// 64-bit DCT perceptual hash (imagehash's `phash` layout: bit 63 is the DCT's (0, 0)).
    pub phash: u64,
}

/// Grey level at or under which a pixel counts as crushed in [`PhotoSignals::dark_fraction`].
pub const DARK_LEVEL: u8 = 5;
/// Grey level at or over which a pixel counts as clipped in [`PhotoSignals::bright_fraction`].
pub const BRIGHT_LEVEL: u8 = 250;

/// A perceptual hash as the images table holds it: 16 lower-case hex digits, as imagehash
/// prints one.
pub fn phash_hex(h: u64) -> String {
    format!("{h:016x}")
}

/// What ingest decided about one image (the render stage's output for the images table).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ImageOutcome {
    /// `kept`, `too_small`, `too_sparse` or `unreadable`.
    pub verdict: String,
    /// The measured value the verdict rests on (empty ratio, or shorter side in pixels).
    pub verdict_value: f64,
    pub empty_ratio: Option<f64>,
    pub render_size: Option<(u32, u32)>,
    /// Shard holding the view's row, when kept.
    pub shard: Option<String>,
    /// Smallest and largest rendered depth (camera-space z) of the view, when kept.
    pub depth_range: Option<(f64, f64)>,
    /// Why, in words, when the verdict needs more than a number (`unreadable`: the decoder's
    /// message).
    #[serde(default)]
    pub detail: Option<String>,
    /// Sharpness, exposure and perceptual hash of the photo, when ingest decoded it (kept
    /// views and those dropped as too blurry).
    #[serde(default)]
    pub signals: Option<PhotoSignals>,
}

fn to_u32(v: u64, table: &str, record: String, field: &str) -> Result<u32> {
    u32::try_from(v).map_err(|_| DatasetError::Value {
        path: table.into(),
        record,
        field: field.into(),
        problem: format!("{v} does not fit in 32 bits"),
    })
}

fn batch(table: &str, schema: SchemaRef, cols: Vec<ArrayRef>) -> Result<RecordBatch> {
    RecordBatch::try_new(schema, cols).map_err(|e| DatasetError::Arrow {
        table: table.into(),
        source: e,
    })
}

/// One row per camera, in id order.
pub fn cameras_batch(rec: &Reconstruction) -> Result<RecordBatch> {
    let cams: Vec<_> = rec.cameras.values().collect();
    let mut widths = Vec::with_capacity(cams.len());
    let mut heights = Vec::with_capacity(cams.len());
    for c in &cams {
        widths.push(to_u32(
            c.width,
            CAMERAS_TABLE,
            format!("camera {}", c.id),
            "width",
        )?);
        heights.push(to_u32(
            c.height,
            CAMERAS_TABLE,
            format!("camera {}", c.id),
            "height",
        )?);
    }
    let schema = cameras_schema();
    let item = |i: usize| match schema.field(i).data_type() {
        DataType::List(f) => f.clone(),
        _ => unreachable!("list column"),
    };
    let mut params = ListBuilder::new(Float64Builder::new()).with_field(item(4));
    let mut names = ListBuilder::new(StringBuilder::new()).with_field(item(5));
    for c in &cams {
        params.values().append_slice(&c.params);
        params.append(true);
        for n in c.model.param_names() {
            names.values().append_value(n);
        }
        names.append(true);
    }
    batch(
        CAMERAS_TABLE,
        schema.clone(),
        vec![
            Arc::new(UInt32Array::from_iter_values(cams.iter().map(|c| c.id))),
            Arc::new(StringArray::from_iter_values(
                cams.iter().map(|c| c.model.name()),
            )),
            Arc::new(UInt32Array::from(widths)),
            Arc::new(UInt32Array::from(heights)),
            Arc::new(params.finish()),
            Arc::new(names.finish()),
        ],
    )
}

/// One row per registered image, in id order; `photos` gives each photo's pixel size if found.
pub fn images_batch(
    rec: &Reconstruction,
    photos: &BTreeMap<u32, Option<(u32, u32)>>,
    outcomes: &BTreeMap<u32, ImageOutcome>,
) -> Result<RecordBatch> {
    let outcome = |i: &nrw_colmap::Image| {
        outcomes.get(&i.id).ok_or_else(|| DatasetError::Value {
            path: IMAGES_TABLE.into(),
            record: format!("image {}", i.id),
            field: "verdict".into(),
            problem: "no outcome recorded for this image".into(),
        })
    };
    let outs: Vec<&ImageOutcome> = rec.images.values().map(outcome).collect::<Result<_>>()?;
    let imgs: Vec<_> = rec.images.values().collect();
    let mut columns = pose_columns(&imgs);
    columns.extend(photo_columns(rec, &imgs, photos)?);
    columns.extend(outcome_columns(&outs));
    batch(IMAGES_TABLE, images_schema(), columns)
}

/// The images table's columns from the model's images: ids, names, cameras and poses.
fn pose_columns(imgs: &[&nrw_colmap::Image]) -> Vec<ArrayRef> {
    let col = |f: &dyn Fn(&nrw_colmap::Image) -> f64| -> ArrayRef {
        Arc::new(Float64Array::from_iter_values(imgs.iter().map(|i| f(i))))
    };
    vec![
        Arc::new(UInt32Array::from_iter_values(imgs.iter().map(|i| i.id))),
        Arc::new(StringArray::from_iter_values(
            imgs.iter().map(|i| i.name.as_str()),
        )),
        Arc::new(UInt32Array::from_iter_values(
            imgs.iter().map(|i| i.camera_id),
        )),
        col(&|i| i.cam_from_world.qvec()[0]),
        col(&|i| i.cam_from_world.qvec()[1]),
        col(&|i| i.cam_from_world.qvec()[2]),
        col(&|i| i.cam_from_world.qvec()[3]),
        col(&|i| i.cam_from_world.translation.x),
        col(&|i| i.cam_from_world.translation.y),
        col(&|i| i.cam_from_world.translation.z),
        col(&|i| i.cam_from_world.centre().x),
        col(&|i| i.cam_from_world.centre().y),
        col(&|i| i.cam_from_world.centre().z),
        Arc::new(BooleanArray::from_iter(imgs.iter().map(|i| {
            Some((i.stored_quat_norm - 1.0).abs() > QUAT_NORM_TOLERANCE)
        }))),
    ]
}

/// The images table's columns of each photo's size (and whether its camera's agrees) and
/// keypoint counts.
fn photo_columns(
    rec: &Reconstruction,
    imgs: &[&nrw_colmap::Image],
    photos: &BTreeMap<u32, Option<(u32, u32)>>,
) -> Result<Vec<ArrayRef>> {
    let size = |i: &nrw_colmap::Image| photos.get(&i.id).copied().flatten();
    let matches = |i: &nrw_colmap::Image| {
        size(i).map(|(w, h)| {
            let c = &rec.cameras[&i.camera_id];
            w as u64 == c.width && h as u64 == c.height
        })
    };
    let mut np = Vec::with_capacity(imgs.len());
    let mut no = Vec::with_capacity(imgs.len());
    for i in imgs {
        np.push(to_u32(
            i.points2d.len() as u64,
            IMAGES_TABLE,
            format!("image {}", i.id),
            "num_points2d",
        )?);
        no.push(i.num_observations() as u32);
    }
    Ok(vec![
        Arc::new(UInt32Array::from_iter(
            imgs.iter().map(|i| size(i).map(|s| s.0)),
        )),
        Arc::new(UInt32Array::from_iter(
            imgs.iter().map(|i| size(i).map(|s| s.1)),
        )),
        Arc::new(BooleanArray::from_iter(imgs.iter().map(|i| matches(i)))),
        Arc::new(UInt32Array::from(np)),
        Arc::new(UInt32Array::from(no)),
    ])
}

/// The images table's columns of what ingest decided for each image and the photo signals
/// it measured.
fn outcome_columns(outs: &[&ImageOutcome]) -> Vec<ArrayRef> {
    let signal = |f: &dyn Fn(&PhotoSignals) -> f64| -> ArrayRef {
        Arc::new(Float64Array::from_iter(
            outs.iter().map(|o| o.signals.as_ref().map(f)),
        ))
    };
    vec![
        Arc::new(StringArray::from_iter_values(
            outs.iter().map(|o| o.verdict.as_str()),
        )),
        Arc::new(Float64Array::from_iter_values(
            outs.iter().map(|o| o.verdict_value),
        )),
        Arc::new(StringArray::from_iter(
            outs.iter().map(|o| o.detail.as_deref()),
        )),
        Arc::new(Float64Array::from_iter(outs.iter().map(|o| o.empty_ratio))),
        Arc::new(UInt32Array::from_iter(
            outs.iter().map(|o| o.render_size.map(|s| s.0)),
        )),
        Arc::new(UInt32Array::from_iter(
            outs.iter().map(|o| o.render_size.map(|s| s.1)),
        )),
        Arc::new(StringArray::from_iter(
            outs.iter().map(|o| o.shard.as_deref()),
        )),
        Arc::new(Float64Array::from_iter(
            outs.iter().map(|o| o.depth_range.map(|r| r.0)),
        )),
        Arc::new(Float64Array::from_iter(
            outs.iter().map(|o| o.depth_range.map(|r| r.1)),
        )),
        signal(&|s| s.sharpness),
        signal(&|s| s.luma_mean),
        signal(&|s| s.luma_std),
        signal(&|s| s.dark_fraction),
        signal(&|s| s.bright_fraction),
        Arc::new(StringArray::from_iter(
            outs.iter().map(|o| o.signals.map(|s| phash_hex(s.phash))),
        )),
    ]
}

/// Write both scene tables into `dir`; returns their manifest entries.
pub fn write_scene_tables(
    dir: &Store,
    rec: &Reconstruction,
    photos: &BTreeMap<u32, Option<(u32, u32)>>,
    outcomes: &BTreeMap<u32, ImageOutcome>,
) -> Result<Vec<crate::manifest::FileEntry>> {
    Ok(vec![
        crate::parquet_io::write_table(dir, CAMERAS_TABLE, &cameras_batch(rec)?)?,
        crate::parquet_io::write_table(dir, IMAGES_TABLE, &images_batch(rec, photos, outcomes)?)?,
    ])
}

/// (image id, name, verdict) of every registered image, from `scene/images.parquet`.
pub fn read_verdicts(dir: &Store) -> Result<Vec<(u32, String, String)>> {
    use crate::parquet_io::column;
    let path = dir.name(IMAGES_TABLE);
    let mut out = Vec::new();
    for b in
        crate::parquet_io::read_batches(dir, IMAGES_TABLE, Some(&["image_id", "name", "verdict"]))?
    {
        let ids = column::<UInt32Array>(&b, "image_id", &path)?;
        let names = column::<StringArray>(&b, "name", &path)?;
        let verdicts = column::<StringArray>(&b, "verdict", &path)?;
        for i in 0..b.num_rows() {
            out.push((
                ids.value(i),
                names.value(i).to_string(),
                verdicts.value(i).to_string(),
            ));
        }
    }
    Ok(out)
}

/// The nearest and farthest rendered depth over the kept views (from `depth_min` and
/// `depth_max`), if any view was kept.
pub fn read_depth_range(dir: &Store) -> Result<Option<(f64, f64)>> {
    use crate::parquet_io::column;
    let path = dir.name(IMAGES_TABLE);
    let mut range: Option<(f64, f64)> = None;
    for b in crate::parquet_io::read_batches(dir, IMAGES_TABLE, Some(&["depth_min", "depth_max"]))?
    {
        let lo = column::<Float64Array>(&b, "depth_min", &path)?;
        let hi = column::<Float64Array>(&b, "depth_max", &path)?;
        for (l, h) in lo.iter().zip(hi.iter()) {
            if let (Some(l), Some(h)) = (l, h) {
                range = Some(range.map_or((l, h), |(a, b)| (a.min(l), b.max(h))));
            }
        }
    }
    Ok(range)
}

/// The largest rendered depth over the kept views (from `depth_max`), if any view was kept.
pub fn read_depth_max(dir: &Store) -> Result<Option<f64>> {
    // Ingest writes depth_min and depth_max together (both or neither per view).
    Ok(read_depth_range(dir)?.map(|(_, far)| far))
}

/// Each decoded photo's signals by image id, from `scene/images.parquet`; empty for a
/// dataset ingested before they were recorded (its table has no `sharpness` column).
pub fn read_signals(dir: &Store) -> Result<BTreeMap<u32, PhotoSignals>> {
    use crate::parquet_io::column;
    use arrow_array::Array;
    let path = dir.name(IMAGES_TABLE);
    let mut out = BTreeMap::new();
    for b in crate::parquet_io::read_batches(dir, IMAGES_TABLE, None)? {
        if b.column_by_name("sharpness").is_none() {
            return Ok(out);
        }
        let ids = column::<UInt32Array>(&b, "image_id", &path)?;
        let f = |n: &str| column::<Float64Array>(&b, n, &path);
        let (sharp, mean, std) = (f("sharpness")?, f("luma_mean")?, f("luma_std")?);
        let (dark, bright) = (f("dark_fraction")?, f("bright_fraction")?);
        let hash = column::<StringArray>(&b, "phash", &path)?;
        for i in (0..b.num_rows()).filter(|i| !sharp.is_null(*i)) {
            let phash =
                u64::from_str_radix(hash.value(i), 16).map_err(|e| DatasetError::Value {
                    path: path.clone(),
                    record: format!("image {}", ids.value(i)),
                    field: "phash".into(),
                    problem: format!("`{}` is not 16 hex digits: {e}", hash.value(i)),
                })?;
            out.insert(
                ids.value(i),
                PhotoSignals {
                    sharpness: sharp.value(i),
                    luma_mean: mean.value(i),
                    luma_std: std.value(i),
                    dark_fraction: dark.value(i),
                    bright_fraction: bright.value(i),
                    phash,
                },
            );
        }
    }
    Ok(out)
}
