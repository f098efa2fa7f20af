//! The one entry point for consumers (the trainer, export, QA): open a dataset, list splits,
//! stream one split's views without decoding the other's payloads, fetch a view by image id,
//! decode its payloads into typed buffers, and take aligned random crops.
//!
//! Memory stays bounded by a few row groups (8 rows each) whatever the dataset size: shards
//! are read row group by row group with a row selection, so rows of other splits are skipped
//! before any PNG or EXR is decoded.

use crate::location::Location;
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use crate::store::Store;

use arrow_array::{
    Array, BinaryArray, Float64Array, ListArray, RecordBatch, StringArray, UInt32Array,
};
use image::{GrayImage, RgbImage, RgbaImage};
use parquet::arrow::arrow_reader::{RowSelection, RowSelector};
use parquet::arrow::ProjectionMask;

use crate::depth::{decode_exr, DepthMap};
use crate::error::{DatasetError, Result};
use crate::manifest::Manifest;
use crate::views::ROW_GROUP_ROWS;

/// A kept view with its metadata and (still encoded) payloads: a shard row.
use crate::views::ViewRow;

/// The channels of a view decoded at one place: what a training step consumes.
#[derive(Debug, Clone, PartialEq)]
pub struct Crop {
    pub x: u32,
    pub y: u32,
    pub photo: RgbImage,
    /// Colour render; alpha is coverage (255 where a point was drawn).
    pub color: RgbaImage,
    /// Camera-space depth, 0 where empty, row-major size × size.
    pub depth: Vec<f32>,
    pub semantics: Option<RgbImage>,
    pub transient: Option<GrayImage>,
}

/// Largest view decoded, in pixels (an RGBA render of it is 256 MB): a row that claims more
/// is refused before any payload is decoded.
pub const MAX_VIEW_PIXELS: u64 = 1 << 26;

impl ViewRow {
    /// Decode one PNG payload after checking its header against the view's size, so damaged
    /// bytes can neither allocate more than the view needs nor give an image of another size.
    fn decode_image(&self, bytes: &[u8], what: &str) -> Result<image::DynamicImage> {
        let err = |problem: String| DatasetError::Value {
            path: Location::Local(PathBuf::from(&self.name)),
            record: format!("image {}", self.image_id),
            field: what.into(),
            problem,
        };
        let (w, h) = (self.width, self.height);
        if u64::from(w) * u64::from(h) > MAX_VIEW_PIXELS {
            return Err(err(format!(
                "the view claims {w}x{h} pixels, more than the {MAX_VIEW_PIXELS}-pixel limit"
            )));
        }
        let reader = || {
            image::ImageReader::with_format(std::io::Cursor::new(bytes), image::ImageFormat::Png)
        };
        let size = reader().into_dimensions().map_err(|e| err(e.to_string()))?;
        if size != (w, h) {
            return Err(err(format!(
                "the PNG is {}x{} but the view is {w}x{h}",
                size.0, size.1
            )));
        }
        reader().decode().map_err(|e| err(e.to_string()))
    }

    /// The resized photo.
    pub fn photo(&self) -> Result<RgbImage> {
        Ok(self
            .decode_image(&self.photo_png, crate::views::columns::PHOTO_PNG)?
            .into_rgb8())
    }
    /// The colour render with coverage as alpha.
    pub fn color(&self) -> Result<RgbaImage> {
        Ok(self
            .decode_image(&self.color_png, crate::views::columns::COLOR_PNG)?
            .into_rgba8())
    }
    /// The depth render (camera-space z, 0 = empty).
    pub fn depth(&self) -> Result<DepthMap> {
        let d = decode_exr(&self.depth_exr, Path::new(&self.name))?;
        if (d.width, d.height) != (self.width as usize, self.height as usize) {
            return Err(DatasetError::Value {
                path: Location::Local(PathBuf::from(&self.name)),
                record: format!("image {}", self.image_id),
                field: crate::views::columns::DEPTH_EXR.into(),
                problem: format!(
                    "the EXR is {}x{} but the view is {}x{}",
                    d.width, d.height, self.width, self.height
                ),
            });
        }
        Ok(d)
    }
    /// ADE20K colour-coded labels, when the dataset has semantics.
    pub fn semantics(&self) -> Result<Option<RgbImage>> {
        self.semantics_png
            .as_ref()
            .map(|b| {
                Ok(self
                    .decode_image(b, crate::views::columns::SEMANTICS_PNG)?
                    .into_rgb8())
            })
            .transpose()
    }
    /// Transient mask (255 = transient), when the dataset has semantics.
    pub fn transient(&self) -> Result<Option<GrayImage>> {
        self.transient_png
            .as_ref()
            .map(|b| {
                Ok(self
                    .decode_image(b, crate::views::columns::TRANSIENT_PNG)?
                    .into_luma8())
            })
            .transpose()
    }

    /// Camera-space normals mapped from [-1, 1] to 0..=255 (0 where empty), when the cloud
    /// has normals.
    pub fn normals(&self) -> Result<Option<RgbImage>> {
        self.normal_png
            .as_ref()
            .map(|b| {
                Ok(self
                    .decode_image(b, crate::views::columns::NORMAL_PNG)?
                    .into_rgb8())
            })
            .transpose()
    }

    /// ADE20K class ids (0 = unlabelled), when the dataset has semantics.
    pub fn labels(&self) -> Result<Option<GrayImage>> {
        self.labels_png
            .as_ref()
            .map(|b| {
                Ok(self
                    .decode_image(b, crate::views::columns::LABELS_PNG)?
                    .into_luma8())
            })
            .transpose()
    }

    /// A `size`×`size` crop at (x, y) of every channel (the paper trains on 256×256).
    pub fn crop_at(&self, x: u32, y: u32, size: u32) -> Result<Crop> {
        if x + size > self.width || y + size > self.height {
            return Err(DatasetError::Value {
                path: Location::Local(PathBuf::from(&self.name)),
                record: format!("image {}", self.image_id),
                field: "crop".into(),
                problem: format!(
                    "a {size}×{size} crop at ({x}, {y}) does not fit in {}×{}",
                    self.width, self.height
                ),
            });
        }
        let sub = |img: &RgbImage| image::imageops::crop_imm(img, x, y, size, size).to_image();
        let depth = self.depth()?;
        let mut d = Vec::with_capacity((size * size) as usize);
        for row in y..y + size {
            let start = row as usize * depth.width + x as usize;
            d.extend_from_slice(&depth.data[start..start + size as usize]);
        }
        Ok(Crop {
            x,
            y,
            photo: sub(&self.photo()?),
            color: image::imageops::crop_imm(&self.color()?, x, y, size, size).to_image(),
            depth: d,
            semantics: self.semantics()?.map(|s| sub(&s)),
            transient: self
                .transient()?
                .map(|t| image::imageops::crop_imm(&t, x, y, size, size).to_image()),
        })
    }

    /// A crop at a place drawn uniformly by `pick(max_x, max_y)` (inclusive bounds).
    pub fn random_crop(
        &self,
        size: u32,
        pick: &mut dyn FnMut(u32, u32) -> (u32, u32),
    ) -> Result<Crop> {
        if size > self.width || size > self.height {
            return self.crop_at(0, 0, size); // names the size problem
        }
        let (x, y) = pick(self.width - size, self.height - size);
        self.crop_at(x, y, size)
    }
}

/// Where a view lives: shard file and row inside it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct RowAt {
    shard: usize,
    row: usize,
}

/// An opened dataset.
#[derive(Debug, Clone)]
pub struct Dataset {
    /// Where the dataset is (a folder or a URL).
    pub dir: Location,
    /// Its files.
    pub store: Store,
    pub manifest: Manifest,
    shards: Vec<String>,
    sizes: Vec<u64>,
    index: HashMap<u32, RowAt>,
    /// split name → image ids (sorted).
    splits: BTreeMap<String, Vec<u32>>,
}

fn parquet_err(path: &Location) -> impl Fn(parquet::errors::ParquetError) -> DatasetError + '_ {
    move |e| DatasetError::Parquet {
        path: path.into(),
        source: e,
    }
}

use crate::parquet_io::column;

impl Dataset {
    /// Open a dataset folder: manifest (schema version checked), shard index, splits.
    pub fn open(store: impl Into<Store>) -> Result<Dataset> {
        let store: Store = store.into();
        let dir = &store;
        let manifest = Manifest::read(dir)?;
        let listed: Vec<&crate::manifest::FileEntry> = manifest
            .tables
            .iter()
            .filter(|t| crate::views::is_shard(&t.path))
            .collect();
        let shards: Vec<String> = listed.iter().map(|t| t.path.clone()).collect();
        // Sizes from the manifest spare object stores a HEAD request per read.
        let sizes: Vec<u64> = listed.iter().map(|t| t.bytes).collect();
        let mut index = HashMap::new();
        for (s, rel) in shards.iter().enumerate() {
            let path = dir.name(rel);
            let f = dir.chunks_sized(rel, Some(sizes[s]))?;
            let b = crate::parquet_io::checked_builder(
                f,
                &path,
                None,
                Some(&[crate::views::columns::IMAGE_ID]),
            )?;
            let mask =
                ProjectionMask::columns(b.parquet_schema(), [crate::views::columns::IMAGE_ID]);
            let mut row = 0;
            let reader = b
                .with_projection(mask)
                .build()
                .map_err(parquet_err(&path))?;
            for batch in crate::parquet_io::guarded(reader, &path) {
                let batch = batch?;
                let ids = column::<UInt32Array>(&batch, crate::views::columns::IMAGE_ID, &path)?;
                for i in 0..ids.len() {
                    index.insert(ids.value(i), RowAt { shard: s, row });
                    row += 1;
                }
            }
        }
        let mut splits: BTreeMap<String, Vec<u32>> = BTreeMap::new();
        let assigned = crate::split::read_splits(dir)?;
        if assigned.is_empty() {
            let mut all: Vec<u32> = index.keys().copied().collect();
            all.sort_unstable();
            splits.insert("all".into(), all);
        } else {
            for a in assigned {
                if index.contains_key(&a.image_id) {
                    splits.entry(a.split).or_default().push(a.image_id);
                }
            }
        }
        for v in splits.values_mut() {
            v.sort_unstable();
        }
        Ok(Dataset {
            dir: store.root(),
            store: store.clone(),
            manifest,
            shards,
            sizes,
            index,
            splits,
        })
    }

    /// Number of view shards.
    pub fn shard_count(&self) -> usize {
        self.shards.len()
    }

    /// Split names with their sizes (`all` when the dataset has not been split yet).
    pub fn splits(&self) -> Vec<(String, usize)> {
        self.splits
            .iter()
            .map(|(k, v)| (k.clone(), v.len()))
            .collect()
    }

    /// Image ids of a split, sorted.
    pub fn ids(&self, split: &str) -> Result<&[u32]> {
        self.splits
            .get(split)
            .map(Vec::as_slice)
            .ok_or_else(|| DatasetError::NoSplit {
                path: self.dir.clone(),
                split: split.to_string(),
                have: self.splits.keys().cloned().collect(),
            })
    }

    /// Number of kept views.
    pub fn len(&self) -> usize {
        self.index.len()
    }

    /// The dataset without the views `left_out` names (an export of only what may be
    /// shared reads the rest as if they were all there is).
    pub fn without(&self, left_out: &std::collections::BTreeSet<u32>) -> Dataset {
        let mut ds = self.clone();
        ds.index.retain(|id, _| !left_out.contains(id));
        for ids in ds.splits.values_mut() {
            ids.retain(|id| !left_out.contains(id));
        }
        ds
    }

    /// Whether the dataset holds no view.
    pub fn is_empty(&self) -> bool {
        self.index.is_empty()
    }

    /// Whether `image_id` is a kept view of this dataset.
    pub fn contains(&self, image_id: u32) -> bool {
        self.index.contains_key(&image_id)
    }

    /// Every kept view's image id, in shard and row order (the order files hold them).
    pub fn all_ids(&self) -> Vec<u32> {
        let mut ids: Vec<(RowAt, u32)> = self.index.iter().map(|(id, l)| (*l, *id)).collect();
        ids.sort_unstable_by_key(|(l, _)| (l.shard, l.row));
        ids.into_iter().map(|(_, id)| id).collect()
    }

    /// Read the given rows of one shard (rows in increasing order).
    fn read_rows(&self, shard: usize, rows: &[usize]) -> Result<Vec<ViewRow>> {
        let rel = &self.shards[shard];
        let path = self.store.name(rel);
        let f = self.store.chunks_sized(rel, Some(self.sizes[shard]))?;
        // Read only the row groups that hold wanted rows, and within them only those rows.
        let groups: Vec<usize> = {
            let mut g: Vec<usize> = rows.iter().map(|r| r / ROW_GROUP_ROWS).collect();
            g.dedup();
            g
        };
        let b = crate::parquet_io::prefetched_builder(f, &path, &groups)?;
        let total = b.metadata().file_metadata().num_rows() as usize;
        let mut selectors = Vec::new();
        for &g in &groups {
            let (start, end) = (g * ROW_GROUP_ROWS, ((g + 1) * ROW_GROUP_ROWS).min(total));
            let mut at = start;
            for &r in rows.iter().filter(|r| (start..end).contains(*r)) {
                if r > at {
                    selectors.push(RowSelector::skip(r - at));
                }
                selectors.push(RowSelector::select(1));
                at = r + 1;
            }
            if end > at {
                selectors.push(RowSelector::skip(end - at));
            }
        }
        let reader = b
            .with_row_groups(groups)
            .with_row_selection(RowSelection::from(selectors))
            .with_batch_size(ROW_GROUP_ROWS)
            .build()
            .map_err(parquet_err(&path))?;
        let mut out: Vec<ViewRow> = Vec::with_capacity(rows.len());
        for batch in crate::parquet_io::guarded(reader, &path) {
            let b = batch?;
            let at = out.len().min(rows.len());
            out.extend(views_of(&b, &rows[at..], &path)?);
        }
        Ok(out)
    }

    /// One view by image id (reads one row of one row group).
    pub fn get(&self, image_id: u32) -> Result<ViewRow> {
        let loc = self
            .index
            .get(&image_id)
            .ok_or_else(|| DatasetError::NotKept {
                path: self.dir.clone(),
                image_id,
            })?;
        self.read_rows(loc.shard, &[loc.row])?
            .pop()
            .ok_or_else(|| DatasetError::Schema {
                path: self.store.name(&self.shards[loc.shard]),
                problem: format!("row {} for image {image_id} is missing", loc.row),
            })
    }

    /// Stream a split's views in image-id order within each shard, a row group at a time.
    pub fn iter_split<'a>(
        &'a self,
        split: &str,
    ) -> Result<impl Iterator<Item = Result<ViewRow>> + 'a> {
        let ids = self.ids(split)?;
        self.iter_ids(ids)
    }

    /// Stream the views of any kept image ids, a row group at a time (each row group read
    /// once however many of its rows are wanted), in shard and row order.
    pub fn iter_ids<'a>(
        &'a self,
        ids: &[u32],
    ) -> Result<impl Iterator<Item = Result<ViewRow>> + 'a> {
        Ok(self
            .reads(ids)?
            .into_iter()
            .flat_map(move |read| match self.read(&read) {
                Ok(v) => v.into_iter().map(Ok).collect::<Vec<_>>(),
                Err(e) => vec![Err(e)],
            }))
    }

    /// The reads that fetch the views of `ids`, one per row group, in shard and row order:
    /// a consumer that cannot borrow the dataset (another language's iterator) walks these.
    pub fn reads(&self, ids: &[u32]) -> Result<Vec<GroupRead>> {
        let mut per_shard: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
        for id in ids {
            let loc = self.index.get(id).ok_or_else(|| DatasetError::NotKept {
                path: self.dir.clone(),
                image_id: *id,
            })?;
            per_shard.entry(loc.shard).or_default().push(loc.row);
        }
        let mut plan: Vec<GroupRead> = Vec::new();
        for (shard, mut rows) in per_shard {
            rows.sort_unstable();
            // An id asked for twice is read once (a row selected twice is not a selection).
            rows.dedup();
            // One read per row group keeps memory at one row group's payloads.
            let mut group: Vec<usize> = Vec::new();
            for r in rows {
                if group
                    .last()
                    .is_some_and(|g| g / ROW_GROUP_ROWS != r / ROW_GROUP_ROWS)
                {
                    plan.push(GroupRead {
                        shard,
                        rows: std::mem::take(&mut group),
                    });
                }
                group.push(r);
            }
            if !group.is_empty() {
                plan.push(GroupRead { shard, rows: group });
            }
        }
        Ok(plan)
    }

    /// The views of one read, every payload checked against its CRC-32.
    pub fn read(&self, read: &GroupRead) -> Result<Vec<ViewRow>> {
        self.read_rows(read.shard, &read.rows)
    }
}

/// Rows of one row group of one shard: a unit of [`Dataset::reads`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GroupRead {
    shard: usize,
    rows: Vec<usize>,
}

impl GroupRead {
    /// How many views the read yields.
    pub fn len(&self) -> usize {
        self.rows.len()
    }
    /// Whether the read yields no view.
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }
}

/// Every view of a shard's bytes (`path` names them in errors), each payload checked against
/// its CRC-32: a shard read whole, without a dataset around it.
pub fn views_in<R: parquet::file::reader::ChunkReader + 'static>(
    data: R,
    path: &Location,
) -> Result<Vec<ViewRow>> {
    let mut out: Vec<ViewRow> = Vec::new();
    for b in crate::parquet_io::batches_from(data, path.clone(), None, ROW_GROUP_ROWS)? {
        let b = b?;
        let rows: Vec<usize> = (out.len()..out.len() + b.num_rows()).collect();
        out.extend(views_of(&b, &rows, path)?);
    }
    Ok(out)
}

/// The views of a batch whose row i is row `rows[i]` of the shard at `path`, every payload
/// checked against its checksum first.
fn views_of(b: &RecordBatch, rows: &[usize], path: &Location) -> Result<Vec<ViewRow>> {
    use crate::views::columns as col;
    for c in crate::views::PAYLOAD_COLUMNS {
        if let Some(m) = crate::views::payload_mismatches(b, rows, c, path)?.first() {
            return Err(m.error(path));
        }
    }
    let u = |n: &str| column::<UInt32Array>(b, n, path);
    let f = |n: &str| column::<Float64Array>(b, n, path);
    let s = |n: &str| column::<StringArray>(b, n, path);
    let bin = |n: &str| column::<BinaryArray>(b, n, path);
    let (ids, names, cams, models, ws, hs) = (
        u(col::IMAGE_ID)?,
        s(col::NAME)?,
        u(col::CAMERA_ID)?,
        s(col::MODEL)?,
        u(col::WIDTH)?,
        u(col::HEIGHT)?,
    );
    let params = column::<ListArray>(b, col::PARAMS, path)?;
    let q = [f(col::QW)?, f(col::QX)?, f(col::QY)?, f(col::QZ)?];
    let t = [f(col::TX)?, f(col::TY)?, f(col::TZ)?];
    let empty = f(col::EMPTY_RATIO)?;
    let labels = bin(col::LABELS_PNG)?;
    let (photo, color, depth, normal, sem, tr) = (
        bin(col::PHOTO_PNG)?,
        bin(col::COLOR_PNG)?,
        bin(col::DEPTH_EXR)?,
        bin(col::NORMAL_PNG)?,
        bin(col::SEMANTICS_PNG)?,
        bin(col::TRANSIENT_PNG)?,
    );
    let opt = |a: &BinaryArray, i: usize| (!a.is_null(i)).then(|| a.value(i).to_vec());
    let mut out = Vec::with_capacity(b.num_rows());
    for i in 0..b.num_rows() {
        let p = params.value(i);
        let p = p
            .as_any()
            .downcast_ref::<Float64Array>()
            .ok_or_else(|| DatasetError::Schema {
                path: path.into(),
                problem: "params are not float64".into(),
            })?;
        out.push(ViewRow {
            image_id: ids.value(i),
            name: names.value(i).into(),
            camera_id: cams.value(i),
            model: models.value(i).into(),
            width: ws.value(i),
            height: hs.value(i),
            scale_x: f(col::SCALE_X)?.value(i),
            scale_y: f(col::SCALE_Y)?.value(i),
            params: p.values().to_vec(),
            qvec: q.map(|c| c.value(i)),
            tvec: t.map(|c| c.value(i)),
            empty_ratio: empty.value(i),
            photo_png: photo.value(i).to_vec(),
            color_png: color.value(i).to_vec(),
            depth_exr: depth.value(i).to_vec(),
            normal_png: opt(normal, i),
            semantics_png: opt(sem, i),
            transient_png: opt(tr, i),
            labels_png: opt(labels, i),
        });
    }
    Ok(out)
}
