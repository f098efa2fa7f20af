//! One written view of the layout: what its COLMAP model, `scene_info` and the pair files
//! need of it.

use nrw_colmap::{Camera, Point2D};

/// One written view: what the model and `scene_info` need of it.
pub(super) struct View {
    pub(super) file: String,
    /// The file's stem: DUSt3R's and IMC's image id.
    pub(super) stem: String,
    /// The export-relative path of DUSt3R's JPEG of the view.
    pub(super) jpg: String,
    pub(super) image_path: String,
    pub(super) depth_path: String,
    pub(super) depth_bytes: usize,
    pub(super) camera: Camera,
    /// The pose as written in images.txt: normalised (qw, qx, qy, qz) and t.
    pub(super) qvec: [f64; 4],
    pub(super) tvec: [f64; 3],
    /// Observations in the stored view's pixels, in the scene model's keypoint order.
    pub(super) points2d: Vec<Point2D>,
}
