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
//! - `points3D.bin` holds the scene's 3D points, from which the loaders derive each image's
//!   near and far bounds (tracks are not written; images carry no 2D points).

use nrw_dataset::split::VAL;
use std::collections::BTreeMap;
use std::path::Path;

use nrw_colmap::{Camera, CameraModel, Image, Point3D, Reconstruction, Rigid3};

use nrw_dataset::ViewRow;

use crate::error::{ExportError, Result};
use crate::staging::Staged;
use crate::writer::{Job, ScenePoint, WithPoints};
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

/// The PINHOLE camera (id = image id) of a view at its stored size, or a refusal naming it.
pub(crate) fn pinhole(v: &ViewRow) -> Result<Camera> {
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
                    "camera model {} with parameters {:?}: NeRF-W loaders (nerf_pl, Ha-NeRF) read \
                     params[0..4] as fx, fy, cx, cy, so a distorted camera would be silently \
                     misread; ingest with --undistort to store PINHOLE cameras",
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

/// The model image of a view (no 2D points).
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

/// NeRF-W's Phototourism layout.
pub static NERFW: WithPoints = WithPoints(write);

/// Write the layout into `staged`: photos, model, tsv. Returns the splits written.
fn write(job: &Job, points: &[ScenePoint], staged: &Staged) -> Result<Vec<SplitExport>> {
    let (ds, cfg, tick) = (job.ds, job.cfg, job.tick);
    let mut rec = Reconstruction::default();
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
                    format!("images {other} and {id} would both be written as dense/images/{file}"),
                ));
            }
            rec.cameras.insert(id, pinhole(&v)?);
            rec.images.insert(id, model_image(&v, &file)?);
            let rel = format!("dense/images/{file}");
            staged.write(&rel, &v.photo_png)?;
            rows.push(format!("{file}\t{id}\t{}\t{}", tsv_split(split), cfg.name));
            s.image_ids.push(id);
            s.names.push(v.name.clone());
            s.files.push(rel);
            tick();
        }
        out.push(s);
    }
    for p in points {
        rec.points.insert(
            p.id,
            Point3D {
                id: p.id,
                xyz: p.xyz.into(),
                rgb: p.rgb,
                error: p.error,
                track: Vec::new(),
            },
        );
    }
    for file in ["cameras.bin", "images.bin", "points3D.bin"] {
        staged.claim(&format!("dense/sparse/{file}"))?;
    }
    let sparse = staged.dir().join("dense/sparse");
    nrw_colmap::write_model(&rec, &sparse, nrw_colmap::Format::Binary)
        .map_err(|e| ExportError::io(&sparse, e))?;
    let tsv = format!("filename\tid\tsplit\tdataset\n{}\n", rows.join("\n"));
    staged.write(&format!("{}.tsv", cfg.name), tsv.as_bytes())?;
    Ok(out)
}
