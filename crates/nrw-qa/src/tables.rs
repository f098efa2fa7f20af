//! The dataset's small tables (scene, split, triplets) read with polars through the
//! dataset's store; shards are never read here (their row counts come from the manifest).

use nrw_dataset::Location;

use nrw_dataset::Store;

use polars::prelude::*;

use crate::error::{QaError, Result};

/// One registered photo as `scene/images.parquet` records it.
#[derive(Debug, Clone)]
pub struct ImageRow {
    pub image_id: u32,
    pub name: String,
    pub verdict: String,
    pub verdict_value: f64,
    /// The verdict in words (`unreadable`: the decoder's message).
    pub verdict_detail: Option<String>,
    pub empty_ratio: Option<f64>,
    pub photo_width: Option<u32>,
    pub photo_height: Option<u32>,
    pub photo_matches_camera: Option<bool>,
    pub quat_renormalized: bool,
    pub num_observations: u32,
    pub depth_min: Option<f64>,
    pub depth_max: Option<f64>,
    /// "train", "val", or None when not split (or dropped).
    pub split: Option<String>,
    /// Sharpness, exposure and hash, when ingest decoded the photo.
    pub signals: Option<nrw_dataset::PhotoSignals>,
}

/// A table of the dataset as a lazy frame (read whole: these tables are small).
fn scan(store: &Store, rel: &str) -> Result<LazyFrame> {
    // Checked against the manifest first: a damaged table is an error naming it, and polars
    // never sees bytes other than those written.
    let bytes = nrw_dataset::Manifest::read(store)?.read_checked(store, rel)?;
    ParquetReader::new(std::io::Cursor::new(bytes.to_vec()))
        .finish()
        .map(IntoLazy::lazy)
        .map_err(|source| QaError::Polars {
            path: store.name(rel),
            source,
        })
}

fn collect(path: &Location, lf: LazyFrame) -> Result<DataFrame> {
    lf.collect().map_err(|source| QaError::Polars {
        path: path.clone(),
        source,
    })
}

fn col_err(path: &Location, column: &str, e: impl std::fmt::Display) -> QaError {
    QaError::Column {
        path: path.clone(),
        column: column.into(),
        problem: e.to_string(),
    }
}

macro_rules! column {
    ($df:expr, $path:expr, $name:expr, $as:ident) => {
        $df.column($name)
            .map_err(|e| col_err($path, $name, e))?
            .$as()
            .map_err(|e| col_err($path, $name, e))?
    };
}

/// `scene/images.parquet` joined with `splits.parquet` (when the dataset has been split).
pub fn images(dir: &Store) -> Result<Vec<ImageRow>> {
    let path = dir.name(nrw_dataset::IMAGES_TABLE);
    let df = collect(
        &path,
        scan(dir, nrw_dataset::IMAGES_TABLE)?.select([
            col("image_id"),
            col("name"),
            col("verdict"),
            col("verdict_value"),
            col("verdict_detail"),
            col("empty_ratio"),
            col("photo_width"),
            col("photo_height"),
            col("photo_matches_camera"),
            col("quat_renormalized"),
            col("num_observations"),
            col("depth_min"),
            col("depth_max"),
        ]),
    )?;
    let ids = column!(df, &path, "image_id", u32);
    let names = column!(df, &path, "name", str);
    let verdicts = column!(df, &path, "verdict", str);
    let values = column!(df, &path, "verdict_value", f64);
    let details = column!(df, &path, "verdict_detail", str);
    let empty = column!(df, &path, "empty_ratio", f64);
    let pw = column!(df, &path, "photo_width", u32);
    let ph = column!(df, &path, "photo_height", u32);
    let matches = column!(df, &path, "photo_matches_camera", bool);
    let renorm = column!(df, &path, "quat_renormalized", bool);
    let obs = column!(df, &path, "num_observations", u32);
    let dmin = column!(df, &path, "depth_min", f64);
    let dmax = column!(df, &path, "depth_max", f64);
    let splits: std::collections::HashMap<u32, String> = splits(dir)?.into_iter().collect();
    let signals = nrw_dataset::scene::read_signals(dir)?;
    let mut rows = Vec::with_capacity(df.height());
    for i in 0..df.height() {
        let image_id = ids
            .get(i)
            .ok_or_else(|| col_err(&path, "image_id", "null"))?;
        rows.push(ImageRow {
            image_id,
            name: names.get(i).unwrap_or_default().to_string(),
            verdict: verdicts.get(i).unwrap_or_default().to_string(),
            verdict_value: values.get(i).unwrap_or(f64::NAN),
            verdict_detail: details.get(i).map(str::to_string),
            empty_ratio: empty.get(i),
            photo_width: pw.get(i),
            photo_height: ph.get(i),
            photo_matches_camera: matches.get(i),
            quat_renormalized: renorm.get(i).unwrap_or(false),
            num_observations: obs.get(i).unwrap_or(0),
            depth_min: dmin.get(i),
            depth_max: dmax.get(i),
            split: splits.get(&image_id).cloned(),
            signals: signals.get(&image_id).copied(),
        });
    }
    rows.sort_by_key(|r| r.image_id);
    Ok(rows)
}

/// (image_id, split) of every split photo; empty before `nrw-etl split`.
pub fn splits(dir: &Store) -> Result<Vec<(u32, String)>> {
    let rel = nrw_dataset::split::SPLITS_TABLE;
    let path = dir.name(rel);
    if !dir.exists(rel)? {
        return Ok(Vec::new());
    }
    let df = collect(
        &path,
        scan(dir, rel)?.select([col("image_id"), col("split")]),
    )?;
    let ids = column!(df, &path, "image_id", u32);
    let split = column!(df, &path, "split", str);
    Ok((0..df.height())
        .filter_map(|i| Some((ids.get(i)?, split.get(i)?.to_string())))
        .collect())
}

/// Rows in the view shards (every kept view has one), as the manifest records them.
pub fn shard_rows(manifest: &nrw_dataset::Manifest) -> u64 {
    manifest
        .tables
        .iter()
        .filter(|t| nrw_dataset::views::is_shard(&t.path))
        .filter_map(|t| t.rows)
        .sum()
}

/// The first anchors of the triplet table with their neighbour ids, and its settings.
#[derive(Debug, Clone)]
pub struct Triplets {
    pub settings: crate::TripletFigures,
    pub sample: Vec<(u32, Vec<u32>, Vec<u32>)>,
}

/// The triplet table, or None before `nrw-etl triplets`.
pub fn triplets(dir: &Store, sample: usize) -> Result<Option<Triplets>> {
    let rel = nrw_dataset::triplets::TRIPLETS_TABLE;
    let path = dir.name(rel);
    if !dir.exists(rel)? {
        return Ok(None);
    }
    let df = collect(
        &path,
        scan(dir, rel)?.select([
            col("anchor_id"),
            col("nearest_ids"),
            col("furthest_ids"),
            col("tier"),
            col("method"),
            col("scope"),
            col("recall_nearest"),
        ]),
    )?;
    let anchors = column!(df, &path, "anchor_id", u32);
    let near = column!(df, &path, "nearest_ids", list);
    let far = column!(df, &path, "furthest_ids", list);
    let ids_of = |s: Option<Series>, name: &str| -> Result<Vec<u32>> {
        let Some(s) = s else { return Ok(Vec::new()) };
        let ca = s.u32().map_err(|e| col_err(&path, name, e))?;
        Ok((0..ca.len()).filter_map(|i| ca.get(i)).collect())
    };
    let n = df.height();
    let step = (n / sample.max(1)).max(1);
    let mut picked = Vec::new();
    for i in (0..n).step_by(step).take(sample) {
        picked.push((
            anchors.get(i).unwrap_or(0),
            ids_of(near.get_as_series(i), "nearest_ids")?,
            ids_of(far.get_as_series(i), "furthest_ids")?,
        ));
    }
    let first_str = |name: &str| -> Result<String> {
        Ok(column!(df, &path, name, str)
            .get(0)
            .unwrap_or_default()
            .to_string())
    };
    Ok(Some(Triplets {
        settings: crate::TripletFigures {
            anchors: n,
            k: picked.first().map_or(0, |p| p.1.len()),
            tier: first_str("tier")?,
            method: first_str("method")?,
            scope: first_str("scope")?,
            recall_nearest: column!(df, &path, "recall_nearest", f64).get(0),
        },
        sample: picked,
    }))
}
