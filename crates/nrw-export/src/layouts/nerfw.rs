//! The Phototourism layout NeRF-W loaders read (kwea123/nerf_pl's `PhototourismDataset`,
//! Ha-NeRF's, which follow NeRF-W's data release):
//!
//! ```text
//! OUT/NAME.tsv                 filename  id  split  dataset   (tab-separated, header row)
//! OUT/dense/images/FILE.png    each view's photo, as stored in the dataset
//! OUT/dense/sparse/{cameras,images,points3D}.bin
//! ```
//!
//! What those loaders assume, and this layout therefore guarantees:
//! - every image has its own camera whose id is the image's id (`camdata[image_id]`);
//! - that camera's `params[0..4]` are fx, fy, cx, cy, so only PINHOLE cameras are written —
//!   SIMPLE_PINHOLE is converted exactly, and a distorted camera is refused by name (its
//!   parameters would be silently misread: ingest with `--undistort`);
//! - `filename` equals the model's image name and the file under `dense/images/`;
//! - `split` is `train` or `test` (our `val`);
//! - `points3D.bin` holds the SfM points the exported images observe, with their tracks, and
//!   each image its observations where the stored photo shows them (`crate::colmap_model`):
//!   the loaders derive each image's near and far bounds from these points, as they do on
//!   NeRF-W's own release, whose `dense/sparse` is COLMAP's undistorted SfM model. nerf_pl and
//!   Ha-NeRF read no initialisation cloud, so a dense cloud the dataset was rendered from is
//!   not written here.

use nrw_dataset::split::VAL;
use std::collections::BTreeMap;
use std::path::Path;

use nrw_colmap::{Camera, CameraModel, Image, Reconstruction, Rigid3};

use nrw_dataset::ViewRow;

use crate::error::{ExportError, Result};
use crate::staging::Staged;
use crate::writer::{About, Job, WithModel};
use crate::SplitExport;

/// The tsv `split` value of one of our splits: NeRF-W's loaders call the held-out set `test`.
pub fn tsv_split(split: &str) -> &str {
    match split {
        VAL => "test",
        s => s,
    }
}

/// The file name a view gets under `dense/images/`: its name (subfolders kept) with `.png`,
/// since the stored photo is a PNG.
pub fn file_name(view_name: &str) -> String {
    let p = Path::new(view_name);
    p.with_extension("png").to_string_lossy().replace('\\', "/")
}

/// What NeRF-W's loaders do with a camera that is not a pinhole: [`pinhole`]'s `reader`.
pub(crate) const NERFW_READERS: &str = "NeRF-W loaders (nerf_pl, Ha-NeRF) read params[0..4] as \
     fx, fy, cx, cy, so a distorted camera would be silently misread";

/// The PINHOLE camera (id = image id) of a view at its stored size, or a refusal naming the
/// camera, what the layout's `reader` (its consumers) does with it, and the command that
/// stores PINHOLE cameras.
pub(crate) fn pinhole(v: &ViewRow, reader: &str) -> Result<Camera> {
    let p = &v.params;
    let params = match CameraModel::from_name(&v.model) {
        Some(CameraModel::Pinhole) if p.len() == 4 => p.clone(),
        Some(CameraModel::SimplePinhole) if p.len() == 3 => vec![p[0], p[0], p[1], p[2]],
        _ => {
            return Err(ExportError::Value {
                path: v.name.clone().into(),
                record: format!("image {}", v.image_id),
                field: "model".into(),
                problem: format!(
                    "camera model {} with parameters {:?}: {reader}; re-ingest the scene with \
                     `nrw-etl ingest SCENE --out DATASET --undistort` to store PINHOLE cameras \
                     (photos resampled as COLMAP's image_undistorter does)",
                    v.model, v.params
                ),
            })
        }
    };
    Ok(Camera {
        id: v.image_id,
        model: CameraModel::Pinhole,
        width: v.width as u64,
        height: v.height as u64,
        params,
    })
}

/// The model image of a view (its 2D points are the caller's to fill in).
pub(crate) fn model_image(v: &ViewRow, file: &str) -> Result<Image> {
    let (cam_from_world, norm) =
        Rigid3::from_colmap(v.qvec, v.tvec).ok_or_else(|| ExportError::Value {
            path: v.name.clone().into(),
            record: format!("image {}", v.image_id),
            field: "qvec".into(),
            problem: format!("{:?} is not a rotation", v.qvec),
        })?;
    Ok(Image {
        id: v.image_id,
        name: file.to_string(),
        camera_id: v.image_id,
        cam_from_world,
        stored_quat_norm: norm,
        points2d: Vec::new(),
    })
}

/// The `nerfw` layout, as the CLI, pipeline files and `export.json` name it.
pub const ABOUT: About = About {
    name: "nerfw",
    summary: "NeRF-W's Phototourism layout for nerf_pl / Ha-NeRF loaders: NAME.tsv (filename, id, split, dataset), dense/images/, dense/sparse/ (one PINHOLE camera per image, the scene's points); needs a dataset ingested with `ingest.undistort` (or pinhole cameras)",
    needs_points: true,
    writes_depth_priors: false,
    default_crop: None,
};

/// NeRF-W's Phototourism layout.
pub static NERFW: WithModel = WithModel(write);

/// Where a Phototourism-style layout puts its photos and model.
pub(crate) struct Places {
    pub images: &'static str,
    pub sparse: &'static str,
}

/// What [`write_phototourism`] wrote: the splits and the tsv rows (without header).
pub(crate) struct Written {
    pub splits: Vec<SplitExport>,
    pub rows: Vec<String>,
    pub max_id: Option<u32>,
}

/// Write the layout into `staged`: photos, model, tsv. Returns the splits written.
fn write(
    job: &Job,
    model: &Reconstruction,
    staged: &Staged,
) -> Result<(Vec<SplitExport>, Vec<String>)> {
    let places = Places {
        images: "dense/images",
        sparse: "dense/sparse",
    };
    let w = write_phototourism(job, model, staged, &places, &|_, _| Ok(()))?;
    staged.write(&format!("{}.tsv", job.cfg.name), tsv(&w.rows).as_bytes())?;
    let warnings = n_vocab_warning(w.max_id).into_iter().collect();
    Ok((w.splits, warnings))
}

/// The tsv NeRF-W's loaders read: a header and one row a view.
pub(crate) fn tsv(rows: &[String]) -> String {
    format!("filename\tid\tsplit\tdataset\n{}\n", rows.join("\n"))
}

/// The photos (and whatever `extra` writes per view, given the view and its file name) and
/// the PINHOLE model of a Phototourism-style layout.
pub(crate) fn write_phototourism(
    job: &Job,
    model: &Reconstruction,
    staged: &Staged,
    places: &Places,
    extra: &dyn Fn(&ViewRow, &str) -> Result<()>,
) -> Result<Written> {
    let (ds, cfg, tick) = (job.ds, job.cfg, job.tick);
    let mut views = Vec::new();
    let mut rows = Vec::new();
    let mut by_file: BTreeMap<String, u32> = BTreeMap::new();
    let mut out = Vec::new();
    for (split, n) in &job.splits {
        if *n == 0 {
            continue;
        }
        let mut s = SplitExport::new(split);
        for &id in ds.ids(split)? {
            let v = ds.get(id)?;
            let file = file_name(&v.name);
            if let Some(other) = by_file.insert(file.clone(), id) {
                return Err(ExportError::refused(
                    &cfg.out,
                    format!(
                        "images {other} and {id} would both be written as {}/{file}",
                        places.images
                    ),
                ));
            }
            let camera = pinhole(&v, NERFW_READERS)?;
            let mut image = model_image(&v, &file)?;
            image.points2d = crate::colmap_model::observations(&v, model, &camera)?;
            views.push((camera, image));
            let rel = format!("{}/{file}", places.images);
            staged.write(&rel, &v.photo_png)?;
            extra(&v, &file)?;
            rows.push(format!("{file}\t{id}\t{}\t{}", tsv_split(split), cfg.name));
            s.image_ids.push(id);
            s.names.push(v.name.clone());
            s.files.push(rel);
            tick();
        }
        out.push(s);
    }
    let max_id = views.iter().map(|(_, i)| i.id).max();
    let rec = crate::colmap_model::with_tracks(views, model);
    if rec.points.is_empty() {
        return Err(ExportError::refused(
            &cfg.out,
            "the exported images observe no SfM point: NeRF-W's loaders take each image's near \
             and far bounds from the model's points",
        ));
    }
    crate::colmap_model::write(&rec, staged, places.sparse, nrw_colmap::Format::Binary)?;
    Ok(Written {
        splits: out,
        rows,
        max_id,
    })
}

/// nerf_pl's default `--N_vocab` (opt.py).
pub const NERF_PL_N_VOCAB: u32 = 100;

/// nerf_pl indexes its appearance and transient embeddings by image id (the tsv's `id`), so
/// `--N_vocab` must exceed the largest id, not the count; at its default it fails with an
/// index error past id 99.
pub fn n_vocab_warning(max_id: Option<u32>) -> Option<String> {
    let max = max_id?;
    (max >= NERF_PL_N_VOCAB).then(|| {
        format!(
            "nerf_pl indexes its embeddings by image id: train with --N_vocab {} or more (the \
             largest id here is {max}; its default {NERF_PL_N_VOCAB} fails with an index error)",
            max + 1
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn n_vocab_is_named_past_nerf_pls_default() {
        assert_eq!(n_vocab_warning(None), None);
        assert_eq!(
            n_vocab_warning(Some(99)),
            None,
            "ids 0..=99 fit the default 100"
        );
        let w = n_vocab_warning(Some(100)).unwrap();
        assert!(w.contains("--N_vocab 101") && w.contains("nerf_pl"), "{w}");
    }
}
