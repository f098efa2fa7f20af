//! The scene's COLMAP model as stages read it: found and read, its photo folder, the
//! undistorted model of `--undistort`, and the model re-read (and checked unchanged) from a
//! dataset's manifest.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use nrw_colmap::{Format, Reconstruction, Scene, UndistortOptions};
use nrw_dataset::{FileEntry, SceneSource};

use crate::error::{PipelineError, Result, Setting};

/// Find and read the model of a scene folder (or a model folder itself): the sub-model
/// `sparse/N` given by `pick`, else the one with the most registered images.
pub fn load_model(
    scene: &Path,
    format: Option<Format>,
    pick: Option<u32>,
) -> Result<(Scene, Reconstruction)> {
    let scene = Scene::find_sub_model(scene, pick)?;
    let rec = scene.read(format)?;
    Ok((scene, rec))
}

/// Refuse a model with a 360° camera (EQUIRECTANGULAR) before a stage that renders or
/// undistorts its views: nrw-etl reads and inspects panoramas but draws perspective and
/// fisheye views only, and COLMAP's undistorter refuses them too. Names the cameras file,
/// the camera and its model.
pub fn refuse_panoramas(scene: &Scene, rec: &Reconstruction) -> Result<()> {
    let Some(cam) = rec.cameras.values().find(|c| c.model.is_spherical()) else {
        return Ok(());
    };
    let file = ["cameras.bin", "cameras.txt"]
        .map(|n| scene.model_dir.join(n))
        .into_iter()
        .find(|p| p.exists())
        .unwrap_or_else(|| scene.model_dir.clone());
    Err(PipelineError::input(
        file,
        format!(
            "camera {}: model {} is a 360° panorama; nrw-etl reads and inspects it, but renders perspective and fisheye views only, and COLMAP's image_undistorter refuses it too — reconstruct from perspective crops of the panoramas",
            cam.id, cam.model
        ),
    ))
}

/// The model as COLMAP's `image_undistorter` writes it (PINHOLE cameras, keypoints carried
/// into the undistorted images), and the original cameras; ingest, densify and finalize all
/// derive it this way.
pub fn undistort_model(
    rec: &mut Reconstruction,
    options: &UndistortOptions,
    model_dir: &Path,
) -> Result<BTreeMap<u32, nrw_colmap::Camera>> {
    nrw_colmap::undistort_reconstruction(rec, options).map_err(|source| PipelineError::Undistort {
        path: model_dir.into(),
        source,
    })
}

/// The photo resampled from its own camera `from` to the undistorted PINHOLE camera `to`
/// (a photo stored at another size than its camera's, same aspect ratio, is brought to the
/// camera's size first).
pub fn undistorted_photo(
    photo: &image::RgbImage,
    from: &nrw_colmap::Camera,
    to: &nrw_colmap::Camera,
) -> image::RgbImage {
    let photo = nrw_dataset::codec::resize_photo(photo, from.width as u32, from.height as u32);
    let src = nrw_render::Rgb8 {
        width: photo.width(),
        height: photo.height(),
        data: photo.into_raw(),
    };
    let out = nrw_render::undistort_photo(&src, from, to);
    image::RgbImage::from_raw(out.width, out.height, out.data).expect("width × height × 3 bytes")
}

/// A label map of the photo resampled from its own camera `from` to the undistorted PINHOLE
/// camera `to`, nearest class (a map stored at another size than its camera's, same aspect
/// ratio, is brought to the camera's size first, nearest too).
pub fn undistorted_labels(
    labels: &image::GrayImage,
    from: &nrw_colmap::Camera,
    to: &nrw_colmap::Camera,
) -> image::GrayImage {
    let labels =
        nrw_dataset::semantics::resize_labels(labels, from.width as u32, from.height as u32);
    let out = nrw_render::undistort_labels(labels.as_raw(), from, to);
    image::GrayImage::from_raw(to.width as u32, to.height as u32, out)
        .expect("width × height bytes")
}

/// The undistorter's options as the unit record and manifest keep them.
pub fn undistort_record(o: &UndistortOptions) -> nrw_dataset::provenance::UndistortRecord {
    nrw_dataset::provenance::UndistortRecord {
        blank_pixels: o.blank_pixels,
        min_scale: o.min_scale,
        max_scale: o.max_scale,
        max_image_size: o.max_image_size,
    }
}

/// The options recorded by [`undistort_record`], read back (finalize).
pub fn undistort_options(r: &nrw_dataset::provenance::UndistortRecord) -> UndistortOptions {
    UndistortOptions {
        blank_pixels: r.blank_pixels,
        min_scale: r.min_scale,
        max_scale: r.max_scale,
        max_image_size: r.max_image_size,
    }
}

/// The model a dataset was ingested from (its manifest's or unit record's `scene`), read
/// again in the encoding ingest read, with the first of its files whose SHA-256 is not
/// among `inputs` (changed since ingest), if any.
pub fn reread_model(
    scene: &SceneSource,
    inputs: &[FileEntry],
) -> Result<(Reconstruction, Option<PathBuf>)> {
    let format = match scene.encoding.as_str() {
        "txt" => Some(Format::Text),
        "bin" => Some(Format::Binary),
        _ => None,
    };
    let rec = nrw_colmap::read_model(Path::new(&scene.model_dir), format)?;
    for f in &rec.files {
        if !unchanged(f, inputs)? {
            let changed = f.clone();
            return Ok((rec, Some(changed)));
        }
    }
    Ok((rec, None))
}

/// Whether `file` still has the SHA-256 a stage recorded for it among `inputs`.
pub fn unchanged(file: &Path, inputs: &[FileEntry]) -> Result<bool> {
    let (_, sha) = nrw_dataset::manifest::sha256_file(file)?;
    let path = file.display().to_string();
    Ok(inputs.iter().any(|i| i.path == path && i.sha256 == sha))
}

/// `bin`/`txt` and `colmap3`/`colmap4`, as reports and manifests spell them.
pub fn encoding_and_layout(rec: &Reconstruction) -> (&'static str, &'static str) {
    let enc = rec.format.map_or("?", |f| f.ext());
    let layout = if rec.is_colmap4() {
        "colmap4"
    } else {
        "colmap3"
    };
    (enc, layout)
}

/// The photo folder: given, or `images/` where COLMAP lays it out ([`Scene::images_dir`]).
pub fn images_dir(images: Option<&Path>, scene: &Scene) -> Result<PathBuf> {
    if let Some(d) = images {
        if !d.is_dir() {
            return Err(PipelineError::input(
                d,
                format!("{} is not a folder", Setting::Images),
            ));
        }
        return Ok(d.to_path_buf());
    }
    scene.images_dir().ok_or_else(|| {
        let tried: Vec<String> = scene
            .image_dir_candidates()
            .iter()
            .map(|d| d.display().to_string())
            .collect();
        PipelineError::input(
            &scene.dir,
            format!(
                "no photo folder found (tried {}); give {} a folder",
                tried.join(", "),
                Setting::Images
            ),
        )
    })
}
