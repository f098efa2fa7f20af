//! The undistorted photos: written into the workspace once, read back as colour and grey views.

use std::collections::BTreeMap;
use std::path::Path;

use nrw_colmap::dense::Workspace;
use nrw_colmap::{CameraModel, Format, Reconstruction};
use nrw_stereo::{GrayImage, Pinhole, StereoView};
use rayon::prelude::*;

use super::config::DensifyConfig;
use crate::error::{PipelineError, Result};
use crate::Progress;

/// Undistort every photo into `images/` and write the undistorted model into `sparse/`;
/// the photos that could not be read, with why.
pub(super) fn undistort_views(
    ws: &Workspace,
    cfg: &DensifyConfig,
    photos: &Path,
    rec: &Reconstruction,
    distorted: &BTreeMap<u32, nrw_colmap::Camera>,
    entries: &[Entry],
    progress: &dyn Progress,
) -> Result<BTreeMap<String, String>> {
    std::fs::create_dir_all(ws.sparse()).map_err(|e| PipelineError::io(ws.sparse(), e))?;
    nrw_colmap::write_model(rec, &ws.sparse(), Format::Binary)
        .map_err(|e| PipelineError::io(ws.sparse(), e))?;
    progress.start("undistorting", entries.len() as u64, "photos");
    let written: Vec<std::result::Result<(), String>> = entries
        .par_iter()
        .map(|e| {
            let r = write_view(ws, photos, cfg.follow_outside_links, rec, distorted, e);
            progress.inc(1);
            r
        })
        .collect();
    progress.finish();
    Ok(entries
        .iter()
        .zip(written)
        .filter_map(|(e, w)| w.err().map(|why| (e.name.clone(), why)))
        .collect())
}

/// Read, undistort and write one photo into `images/`; the problem if it cannot be.
pub(super) fn write_view(
    ws: &Workspace,
    photos: &Path,
    follow_outside_links: bool,
    rec: &Reconstruction,
    distorted: &BTreeMap<u32, nrw_colmap::Camera>,
    e: &Entry,
) -> std::result::Result<(), String> {
    let im = &rec.images[&e.image_id];
    let path = nrw_colmap::names::photo_path(photos, &im.name, follow_outside_links)?;
    let photo = nrw_dataset::codec::load_photo(&path).map_err(|err| err.to_string())?;
    let out = crate::model::undistorted_photo(
        &photo,
        &distorted[&im.camera_id],
        &rec.cameras[&im.camera_id],
    );
    let target = ws.image(&im.name)?;
    let bytes = encode(&im.name, &out).map_err(|err| format!("{}: {err}", target.display()))?;
    nrw_dataset::atomic::write_bytes_atomic(&target, &bytes).map_err(|err| err.to_string())
}

/// The undistorted photo in the encoding its name says (JPEG at quality 95, else PNG).
pub(super) fn encode(name: &str, img: &image::RgbImage) -> std::result::Result<Vec<u8>, String> {
    let lower = name.to_ascii_lowercase();
    if lower.ends_with(".jpg") || lower.ends_with(".jpeg") {
        let mut out = Vec::new();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 95)
            .encode_image(img)
            .map_err(|e| e.to_string())?;
        Ok(out)
    } else {
        nrw_dataset::codec::encode_rgb(name, img).map_err(|e| e.to_string())
    }
}

/// A workspace view as stereo reads it (its undistorted photo, decoded again).
pub(super) fn load_view(ws: &Workspace, e: &Entry) -> Result<StereoView> {
    let rgb = load_rgb(ws, e)?;
    Ok(StereoView {
        id: e.image_id as u64,
        image: GrayImage::from_rgb8(e.width, e.height, rgb.as_raw()),
        lens: e.lens,
        rotation: e.rotation,
        translation: e.translation,
    })
}

pub(super) fn load_rgb(ws: &Workspace, e: &Entry) -> Result<image::RgbImage> {
    let path = ws
        .image(&e.name)
        .map_err(|p| PipelineError::input(ws.images(), p))?;
    let rgb = nrw_dataset::codec::load_photo(&path)?;
    if rgb.width() as usize != e.width || rgb.height() as usize != e.height {
        return Err(PipelineError::input(
            &path,
            format!(
                "is {}x{}, its undistorted camera {}x{}",
                rgb.width(),
                rgb.height(),
                e.width,
                e.height
            ),
        ));
    }
    Ok(rgb)
}

/// A view of the undistorted model as densify handles it.
pub(super) struct Entry {
    pub(super) image_id: u32,
    pub(super) name: String,
    pub(super) lens: Pinhole,
    pub(super) rotation: glam::DMat3,
    pub(super) translation: glam::DVec3,
    pub(super) width: usize,
    pub(super) height: usize,
}

/// The views of the undistorted model, by image id.
pub(super) fn entries(rec: &Reconstruction) -> Vec<Entry> {
    let origin = rec.scene_origin();
    rec.images
        .values()
        .map(|im| {
            let cam = &rec.cameras[&im.camera_id];
            debug_assert_eq!(cam.model, CameraModel::Pinhole);
            let p = &cam.params;
            let local = im.cam_from_world.recentred(origin);
            Entry {
                image_id: im.id,
                name: im.name.clone(),
                lens: Pinhole {
                    fx: p[0],
                    fy: p[1],
                    cx: p[2],
                    cy: p[3],
                },
                rotation: local.matrix,
                translation: local.translation,
                width: cam.width as usize,
                height: cam.height as usize,
            }
        })
        .collect()
}

/// A view to match: its index in the entries, its sources' indices, its depth range.
pub(super) type Plan = (usize, Vec<usize>, (f64, f64));
