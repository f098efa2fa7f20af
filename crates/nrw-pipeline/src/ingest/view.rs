//! One view: its photo, render, depth, labels and verdict, encoded into a shard row; and
//! one group of views, written as a shard and recorded.

use image::RgbImage;
use nrw_dataset::codec::{
    encode_color_render, encode_normals, encode_rgb, load_photo, resize_photo,
};
use nrw_dataset::scene::ImageVerdict;
use nrw_dataset::units::{self, GroupImage, GroupRecord};
use nrw_dataset::{FileEntry, ImageOutcome, PhotoSignals, Store, ViewRow};
use nrw_render::{render, render_size, FilterVerdict, View};
use rayon::prelude::*;

use crate::error::{PipelineError, Result};
use crate::Progress;

use super::config::{IngestConfig, Prepared};

/// A group's record if it is done with these inputs and parameters and its shard is intact.
pub(super) fn done_group(out: &Store, g: usize, fingerprint: &str) -> Option<GroupRecord> {
    let r: GroupRecord =
        units::read_record(out, &units::group_record_path(units::INGEST, g)).ok()??;
    let intact = r.fingerprint == fingerprint
        && r.shard
            .as_ref()
            .is_none_or(|e| FileEntry::of(out, &e.path).is_ok_and(|f| f.sha256 == e.sha256));
    intact.then_some(r)
}

pub(super) fn outcome(
    verdict: &FilterVerdict,
    empty: Option<f64>,
    size: Option<(u32, u32)>,
) -> ImageOutcome {
    ImageOutcome {
        verdict: verdict.name().into(),
        verdict_value: verdict.value(),
        empty_ratio: empty,
        render_size: size,
        shard: None,
        depth_range: None,
        detail: None,
        signals: None,
    }
}

/// The outcome of a view whose photo is less sharp than `--min-sharpness`: its render
/// stays measured (empty ratio, size), the verdict's value is the sharpness.
fn too_blurry(rendered: ImageOutcome, signals: PhotoSignals, min: f64) -> ImageOutcome {
    ImageOutcome {
        verdict: ImageVerdict::TooBlurry.name().into(),
        verdict_value: signals.sharpness,
        detail: Some(format!(
            "sharpness {:.1} is under --min-sharpness {min}",
            signals.sharpness
        )),
        signals: Some(signals),
        depth_range: None,
        ..rendered
    }
}

/// The outcome of a view whose photo or label map cannot be decoded: the verdict's value is
/// the file's size in bytes (0 for an empty file), the detail the decoder's message.
pub(super) fn unreadable(path: &nrw_dataset::Location, problem: String) -> ImageOutcome {
    ImageOutcome {
        verdict: nrw_dataset::VERDICT_UNREADABLE.into(),
        verdict_value: path
            .local()
            .and_then(|p| std::fs::metadata(p).ok())
            .map_or(0.0, |m| m.len() as f64),
        empty_ratio: None,
        render_size: None,
        shard: None,
        depth_range: None,
        detail: Some(problem),
        signals: None,
    }
}

/// Smallest and largest rendered depth (0 = empty).
pub(super) fn depth_range(depth: &[f32]) -> Option<(f64, f64)> {
    depth.iter().filter(|d| **d > 0.0).fold(None, |r, &d| {
        let d = d as f64;
        Some(r.map_or((d, d), |(lo, hi): (f64, f64)| (lo.min(d), hi.max(d))))
    })
}

pub(super) type LabelPngs = (Option<Vec<u8>>, Option<Vec<u8>>, Option<Vec<u8>>);

/// The view's label maps (colour-coded, transient mask, class ids), when ingest has them:
/// made from the (stored) photo by the model (`--segment-weights`), or read from the label
/// folder, where each map has its photo's size `original` and, with `--undistort`, is
/// resampled from the photo's camera to the pinhole one (`undistort`: from, to).
#[allow(clippy::too_many_arguments)]
pub(super) fn label_pngs(
    cfg: &IngestConfig,
    p: &Prepared,
    name: &str,
    photo_name: &str,
    photo: &RgbImage,
    original: (u32, u32),
    undistort: Option<(&nrw_colmap::Camera, &nrw_colmap::Camera)>,
    (w, h): (u32, u32),
) -> Result<LabelPngs> {
    let labels = if let Some((model, mode)) = &p.segmenter {
        let what = p.photos_dir.join(photo_name).display().to_string();
        nrw_segment::segment(model, photo, *mode, &what, nrw_segment::Parallelism::None)?
    } else if let Some(dir) = &cfg.settings.semantics {
        let path = nrw_dataset::semantics::label_path(dir, photo_name)?;
        let labels = nrw_dataset::semantics::load_labels(&path, original.0, original.1)?;
        match undistort {
            Some((from, to)) => crate::model::undistorted_labels(&labels, from, to),
            None => labels,
        }
    } else {
        return Ok((None, None, None));
    };
    let ids = nrw_dataset::semantics::resize_labels(&labels, w, h);
    let (rgb, mask) = nrw_dataset::semantics::colorize(&ids);
    Ok((
        Some(nrw_dataset::codec::encode_rgb_bytes(name, w, h, &rgb)?),
        Some(nrw_dataset::codec::encode_gray(name, w, h, &mask)?),
        Some(nrw_dataset::codec::encode_gray(name, w, h, ids.as_raw())?),
    ))
}

/// Render one image and, if kept, encode its row.
pub(super) fn process(
    cfg: &IngestConfig,
    p: &Prepared,
    image_id: u32,
) -> Result<(ImageOutcome, Option<ViewRow>)> {
    let img = &p.rec.images[&image_id];
    let cam = &p.rec.cameras[&img.camera_id];
    // Every image's path was checked (name, links) when its size was read in `photo_sizes`.
    let photo_path = p.photos_dir.join(&img.name);
    if let Some(problem) = p.unreadable.get(&image_id) {
        return Ok((
            unreadable(&photo_path.clone().into(), problem.clone()),
            None,
        ));
    }
    let size = p.photos[&image_id];
    if let Some(v) = cfg
        .settings
        .filters()
        .check_size(size.0 as u64, size.1 as u64)
    {
        return Ok((outcome(&v, None, None), None));
    }
    let (w, h) = render_size(cam.width, cam.height, cfg.settings.min_dim);
    let view = View::new(img, cam, p.cloud.origin, w, h, cfg.settings.radius);
    let buf = render(&view, &p.cloud);
    let empty = buf.empty_ratio();
    let verdict = cfg.settings.filters().check_render(empty);
    let o = outcome(&verdict, Some(empty), Some((w, h)));
    if !matches!(verdict, FilterVerdict::Kept { .. }) {
        return Ok((o, None));
    }
    // Kept: record its depth range (export's depth scale and QA's depth plots read it).
    let o = ImageOutcome {
        depth_range: depth_range(&buf.depth),
        ..o
    };
    let name = format!("image {}", img.id);
    let (photo, labels, signals) = match decode(cfg, p, (img, &name), &photo_path, &o, (w, h))? {
        Ok(d) => d,
        Err(dropped) => return Ok((dropped, None)),
    };
    let photo = resize_photo(&photo, w, h);
    let o = ImageOutcome {
        signals: Some(signals),
        ..o
    };
    let row = view_row((img, cam), &name, (&view, &buf, empty), &photo, labels)?;
    Ok((o, Some(row)))
}

/// The photo as its row needs it: decoded, its signals measured, undistorted, with its label
/// maps; or the outcome that drops it (too blurry, or unreadable unless `--strict`).
fn decode(
    cfg: &IngestConfig,
    p: &Prepared,
    (img, name): (&nrw_colmap::Image, &str),
    photo_path: &std::path::Path,
    o: &ImageOutcome,
    (w, h): (u32, u32),
) -> Result<std::result::Result<(RgbImage, LabelPngs, PhotoSignals), ImageOutcome>> {
    let cam = &p.rec.cameras[&img.camera_id];
    let undistort = p
        .distorted
        .as_ref()
        .map(|originals| (&originals[&img.camera_id], cam));
    let decoded = load_photo(photo_path)
        .map_err(PipelineError::from)
        .and_then(|photo| {
            let signals = super::signals::signals(&photo);
            if let Some(min) = cfg
                .settings
                .min_sharpness
                .filter(|min| signals.sharpness < *min)
            {
                return Ok(Err(too_blurry(o.clone(), signals, min)));
            }
            let original = (photo.width(), photo.height());
            let photo = match undistort {
                Some((from, to)) => crate::model::undistorted_photo(&photo, from, to),
                None => photo,
            };
            let labels = label_pngs(cfg, p, name, &img.name, &photo, original, undistort, (w, h))?;
            Ok(Ok((photo, labels, signals)))
        });
    match decoded {
        Err(PipelineError::Dataset(nrw_dataset::DatasetError::Unreadable { path, problem }))
            if !cfg.settings.strict =>
        {
            Ok(Err(unreadable(&path, problem)))
        }
        other => other,
    }
}

/// A kept view's shard row: its pose and camera, its photo (at the render's size), the
/// render's colour, depth and normals, and its label maps.
fn view_row(
    (img, cam): (&nrw_colmap::Image, &nrw_colmap::Camera),
    name: &str,
    (view, buf, empty): (&View, &nrw_render::DeepBuffer, f64),
    photo: &RgbImage,
    (semantics_png, transient_png, labels_png): LabelPngs,
) -> Result<ViewRow> {
    let (w, h) = (view.width, view.height);
    Ok(ViewRow {
        image_id: img.id,
        name: img.name.clone(),
        camera_id: cam.id,
        model: cam.model.name().into(),
        width: w,
        height: h,
        scale_x: view.scale.x,
        scale_y: view.scale.y,
        params: view.camera.params.clone(),
        qvec: img.cam_from_world.qvec(),
        tvec: img.cam_from_world.translation.to_array(),
        empty_ratio: empty,
        photo_png: encode_rgb(name, photo)?,
        color_png: encode_color_render(name, w, h, buf.color.as_deref(), &buf.depth)?,
        depth_exr: nrw_dataset::depth::encode_exr(&nrw_dataset::depth::DepthMap {
            width: w as usize,
            height: h as usize,
            data: buf.depth.clone(),
        })?,
        normal_png: match &buf.normal {
            Some(n) => Some(encode_normals(name, w, h, n, &buf.depth)?),
            None => None,
        },
        semantics_png,
        transient_png,
        labels_png,
    })
}

/// Render one group, write its shard, then its record.
pub(super) fn run_group(
    cfg: &IngestConfig,
    store: &Store,
    p: &Prepared,
    g: usize,
    ids: &[u32],
    progress: &dyn Progress,
) -> Result<usize> {
    let results: Vec<(ImageOutcome, Option<ViewRow>)> = ids
        .par_iter()
        .map(|id| {
            let r = process(cfg, p, *id);
            progress.inc(1);
            r
        })
        .collect::<Result<_>>()?;
    // Rows move into the shard writer (no copy: a group's encoded rows are its largest
    // state after the cloud).
    let (outcomes, rows): (Vec<ImageOutcome>, Vec<Option<ViewRow>>) = results.into_iter().unzip();
    let kept: Vec<bool> = rows.iter().map(Option::is_some).collect();
    let rows: Vec<ViewRow> = rows.into_iter().flatten().collect();
    let rel = nrw_dataset::views::shard_path(g);
    let (written, shard) = match rows.len() {
        0 => (0, None),
        n => (
            n,
            Some(nrw_dataset::views::write_shard_owned(store, &rel, rows)?),
        ),
    };
    let images = ids
        .iter()
        .zip(outcomes.into_iter().zip(kept))
        .map(|(id, (mut o, row))| {
            if row {
                o.shard = Some(rel.clone());
            }
            GroupImage {
                image_id: *id,
                photo_size: p.photos.get(id).copied(),
                outcome: o,
            }
        })
        .collect();
    let record = GroupRecord {
        fingerprint: p.record.fingerprint.clone(),
        shard,
        images,
    };
    units::write_record(store, &units::group_record_path(units::INGEST, g), &record)?;
    Ok(written)
}
