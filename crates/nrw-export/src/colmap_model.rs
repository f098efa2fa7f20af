//! The COLMAP models the layouts write (nerfw's `dense/sparse`, gsplat's `sparse/0`,
//! nerfbaselines' `sparse`, MegaDepth's `sparse-txt`), built in one place: one PINHOLE camera
//! per exported image, the image's pose, and its SfM observations — the scene model's
//! keypoints carried into the stored view through its camera (scaled, and undistorted when the
//! dataset was), so they lie where the stored photo shows their points — and the SfM points
//! those observations see, with tracks rebuilt from them. This is what COLMAP's
//! `image_undistorter` writes for the same views, and what consumers that read tracks
//! (gsplat's `Parser` and its `point_indices`, graphdeco's `make_depth_scale.py`,
//! nerfbaselines' `images_points3D_indices`) expect.

use nrw_colmap::{
    Camera, Format, Image, Point2D, Point3D, Reconstruction, TrackElement, NO_POINT3D,
};
use nrw_dataset::ViewRow;

use crate::error::{ExportError, Result};
use crate::staging::Staged;

/// The scene model's observations of view `v`, carried into the stored view's pixels: each
/// keypoint's ray through the photo's camera, projected by the stored camera. Keypoints
/// without a ray (past a fisheye's fold) are dropped.
pub(crate) fn observations(
    v: &ViewRow,
    rec: &Reconstruction,
    stored: &Camera,
) -> Result<Vec<Point2D>> {
    let missing = |what: &str| ExportError::Value {
        path: v.name.clone().into(),
        record: format!("image {}", v.image_id),
        field: "image_id".into(),
        problem: format!("the scene model has no {what} for this view"),
    };
    let img = rec
        .images
        .get(&v.image_id)
        .ok_or_else(|| missing("image"))?;
    let photo = rec
        .cameras
        .get(&img.camera_id)
        .ok_or_else(|| missing("camera"))?;
    Ok(img
        .points2d
        .iter()
        .filter(|p| p.point3d_id != NO_POINT3D)
        .filter_map(|p| {
            Some(Point2D {
                xy: nrw_colmap::undistorted_keypoint(photo, stored, p.xy)?,
                point3d_id: p.point3d_id,
            })
        })
        .collect())
}

/// The exported model: each view's camera and image (whose `points2d` are its
/// [`observations`]), and the scene points they observe with tracks rebuilt from them.
pub(crate) fn with_tracks(
    views: impl IntoIterator<Item = (Camera, Image)>,
    rec: &Reconstruction,
) -> Reconstruction {
    let mut out = Reconstruction::default();
    for (camera, image) in views {
        for (idx, p) in image.points2d.iter().enumerate() {
            let point = out.points.entry(p.point3d_id).or_insert_with(|| Point3D {
                track: Vec::new(),
                ..rec.points[&p.point3d_id].clone()
            });
            point.track.push(TrackElement {
                image_id: image.id,
                point2d_idx: idx as u32,
            });
        }
        out.cameras.insert(camera.id, camera);
        out.images.insert(image.id, image);
    }
    out
}

/// Write `rec` under the export-relative folder `dir` in `format`, claiming each file.
pub(crate) fn write(
    rec: &Reconstruction,
    staged: &Staged,
    dir: &str,
    format: Format,
) -> Result<()> {
    for file in ["cameras", "images", "points3D"] {
        staged.claim(&format!("{dir}/{file}.{}", format.ext()))?;
    }
    let path = staged.dir().join(dir);
    nrw_colmap::write_model(rec, &path, format).map_err(|e| ExportError::io(&path, e))
}
