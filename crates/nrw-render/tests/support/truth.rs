//! Rendered depth against a synthetic scene's ground truth, shared by the clean-up test and
//! benchmark (`#[path]`).
#![allow(dead_code)]

use std::path::Path;

use glam::DVec3;
use nrw_render::{render, RenderCloud, View};

/// ADE20K ids of the landmark (building, windows, columns): the pixels depth is judged on.
pub const LANDMARK: [u8; 3] = [2, 9, 43];

/// (landmark pixels more than 1% off the true depth, covered landmark pixels) over the scene's
/// photos rendered at photo size with r = 1.
pub fn depth_errors(dir: &Path, positions: &[DVec3], colors: Option<&[[u8; 3]]>) -> (usize, usize) {
    let rec = nrw_colmap::read_scene(dir).unwrap();
    let origin = rec.scene_origin();
    let rc = RenderCloud::new(origin, positions, colors, None);
    let (mut off, mut covered) = (0, 0);
    for img in rec.images.values() {
        let cam = &rec.cameras[&img.camera_id];
        let view = View::new(img, cam, origin, cam.width as u32, cam.height as u32, 1.0);
        let buf = render(&view, &rc);
        let stem = Path::new(&img.name).with_extension("");
        let truth = nrw_dataset::depth::read_exr(
            &dir.join("ground_truth/depth")
                .join(format!("{}.exr", stem.display())),
        )
        .unwrap();
        let labels = image::open(
            dir.join("ground_truth/semantics")
                .join(format!("{}.png", stem.display())),
        )
        .unwrap()
        .to_luma8();
        for ((d, t), l) in buf.depth.iter().zip(&truth.data).zip(labels.as_raw()) {
            if *d > 0.0 && *t > 0.0 && LANDMARK.contains(l) {
                covered += 1;
                off += (((d - t) / t).abs() > 0.01) as usize;
            }
        }
    }
    (off, covered)
}
