//! The scene's photos before rendering: each one's path through the name check, and its
//! size read from the header (a photo that cannot be read is a verdict, not an error).

use std::collections::BTreeMap;
use std::path::Path;

use nrw_colmap::Reconstruction;

use crate::error::{PipelineError, Result};

use super::config::IngestConfig;

/// One photo's size from its header (no pixel decoded), or why it has none.
pub(super) fn header_size(path: &Path) -> std::result::Result<(u32, u32), String> {
    use std::io::Read;
    let mut head = Vec::with_capacity(16);
    std::fs::File::open(path)
        .and_then(|f| f.take(16).read_to_end(&mut head))
        .map_err(|e| e.to_string())?;
    nrw_dataset::codec::photo_format(&head)?;
    image::ImageReader::open(path)
        .and_then(|r| r.with_guessed_format())
        .map_err(|e| e.to_string())?
        .into_dimensions()
        .map_err(|e| format!("cannot read the photo's size: {}", e.to_string().trim()))
}

/// Registered photos' sizes from their headers, and those whose header cannot be read.
pub(super) struct PhotoSizes {
    pub(super) sizes: BTreeMap<u32, (u32, u32)>,
    pub(super) unreadable: BTreeMap<u32, String>,
}

/// Photo sizes from file headers, with warnings for size mismatches; an unreadable header
/// is an error only when `strict`.
pub(super) fn photo_sizes(
    rec: &Reconstruction,
    dir: &Path,
    cfg: &IngestConfig,
    warnings: &mut Vec<String>,
) -> Result<PhotoSizes> {
    let strict = cfg.settings.strict;
    let mut photos = BTreeMap::new();
    let mut unreadable = BTreeMap::new();
    let mut missing = Vec::new();
    let photos_dir = nrw_colmap::names::PhotoDir::new(dir, cfg.follow_outside_links);
    for img in rec.images.values() {
        // The one place a model's image name becomes a path (checked when the model was read;
        // links out of the folder refused unless --follow-outside-links).
        let path = photos_dir.photo(&img.name).map_err(|p| {
            PipelineError::input(dir, format!("image {}: field `name`: {p}", img.id))
        })?;
        if !path.is_file() {
            missing.push(img.name.clone());
            continue;
        }
        let (w, h) = match header_size(&path) {
            Ok(size) => size,
            Err(problem) if strict => return Err(unreadable_error(&path, problem)),
            Err(problem) => {
                unreadable.insert(img.id, problem);
                continue;
            }
        };
        let cam = &rec.cameras[&img.camera_id];
        if (w as u64, h as u64) != (cam.width, cam.height) {
            // Same aspect ratio (to a pixel): the photo is rescaled to the render size like
            // any other. Otherwise the camera does not describe this photo.
            let aspect_ok =
                ((w as f64 / h as f64) * cam.height as f64 - cam.width as f64).abs() <= 1.0;
            let sizes = format!(
                "photo is {w}x{h} but camera {} is {}x{}",
                cam.id, cam.width, cam.height
            );
            if !aspect_ok {
                return Err(PipelineError::input(
                    &path,
                    format!(
                        "{sizes} (another aspect ratio): the model does not describe this photo"
                    ),
                ));
            }
            warnings.push(format!(
                "{}: {sizes}; same aspect ratio, rescaled",
                path.display()
            ));
        }
        photos.insert(img.id, (w, h));
    }
    if !missing.is_empty() {
        let shown: Vec<_> = missing.iter().take(5).cloned().collect();
        return Err(PipelineError::input(
            dir,
            format!(
                "{} of {} registered photos are missing ({}{})",
                missing.len(),
                rec.images.len(),
                shown.join(", "),
                if missing.len() > 5 { ", …" } else { "" }
            ),
        ));
    }
    Ok(PhotoSizes {
        sizes: photos,
        unreadable,
    })
}

pub(super) fn unreadable_error(path: &Path, problem: String) -> PipelineError {
    nrw_dataset::DatasetError::Unreadable {
        path: path.into(),
        problem,
    }
    .into()
}
