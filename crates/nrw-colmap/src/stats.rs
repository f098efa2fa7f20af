//! Reprojection errors of every observation: the strongest check that cameras, poses and points agree.

use std::collections::BTreeMap;

use crate::model::Reconstruction;

/// Reprojection error figures of one image.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ImageReprojection {
    pub observations: usize,
    pub mean_px: Option<f64>,
    pub max_px: Option<f64>,
}

/// Reprojection error figures of a whole model.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ReprojectionStats {
    /// Track elements whose point projected into the image (the ones averaged).
    pub observations: usize,
    /// Track elements whose point is behind the camera or outside the model's valid angle.
    pub not_visible: usize,
    /// Mean over observations of |projection − keypoint| in pixels; `None` with no observation.
    pub mean_px: Option<f64>,
    pub max_px: Option<f64>,
    pub per_image: BTreeMap<u32, ImageReprojection>,
}

/// Every track element's reprojection error in pixels, points in id order and tracks in
/// file order; `None` where the point is not visible in that image.
pub fn observation_errors(rec: &Reconstruction) -> Vec<Option<f64>> {
    let origin = rec.scene_origin();
    let local: BTreeMap<u32, crate::pose::LocalRigid3> = rec
        .images
        .values()
        .map(|i| (i.id, i.cam_from_world.recentred(origin)))
        .collect();
    let mut out = Vec::with_capacity(rec.num_observations());
    for p in rec.points.values() {
        let xyz = p.xyz - origin;
        for el in &p.track {
            let img = &rec.images[&el.image_id];
            let cam = &rec.cameras[&img.camera_id];
            let px = cam.img_from_cam(local[&el.image_id].transform(xyz));
            out.push(px.map(|px| (px - img.points2d[el.point2d_idx as usize].xy).length()));
        }
    }
    out
}

/// For every track element, the pixel distance between the projected point and its keypoint.
///
/// Points are re-centred on [`Reconstruction::scene_origin`] in f64 first, so a model in
/// georeferenced coordinates gives the same errors as one near the origin.
pub fn reprojection_stats(rec: &Reconstruction) -> ReprojectionStats {
    let origin = rec.scene_origin();
    // Per image: local pose, camera, running (count, sum, max).
    let mut per: BTreeMap<u32, (crate::pose::LocalRigid3, &crate::Camera, usize, f64, f64)> = rec
        .images
        .values()
        .map(|img| {
            let cam = &rec.cameras[&img.camera_id];
            (
                img.id,
                (
                    img.cam_from_world.recentred(origin),
                    cam,
                    0usize,
                    0.0f64,
                    0.0f64,
                ),
            )
        })
        .collect();
    let mut out = ReprojectionStats::default();
    let (mut sum, mut max) = (0.0f64, 0.0f64);
    for p in rec.points.values() {
        let local = p.xyz - origin;
        for el in &p.track {
            let img = &rec.images[&el.image_id];
            let entry = per.get_mut(&el.image_id).expect("validated track");
            let cam_pt = entry.0.transform(local);
            match entry.1.img_from_cam(cam_pt) {
                Some(px) => {
                    let e = (px - img.points2d[el.point2d_idx as usize].xy).length();
                    out.observations += 1;
                    sum += e;
                    max = max.max(e);
                    entry.2 += 1;
                    entry.3 += e;
                    entry.4 = entry.4.max(e);
                }
                None => out.not_visible += 1,
            }
        }
    }
    if out.observations > 0 {
        out.mean_px = Some(sum / out.observations as f64);
        out.max_px = Some(max);
    }
    out.per_image = per
        .into_iter()
        .map(|(id, (_, _, n, s, m))| {
            let stats = if n > 0 {
                ImageReprojection {
                    observations: n,
                    mean_px: Some(s / n as f64),
                    max_px: Some(m),
                }
            } else {
                ImageReprojection::default()
            };
            (id, stats)
        })
        .collect();
    out
}
