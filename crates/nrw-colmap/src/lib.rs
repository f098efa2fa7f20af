//! COLMAP reconstructions read into f64 geometry: sparse models in both encodings and both
//! layouts (COLMAP 3, COLMAP 4 with rigs and frames), dense `fused.ply` clouds, and COLMAP's
//! exact camera models. Every count read from a file is checked against the bytes left
//! before anything is allocated, and every error names the file, the record and the field.

mod bin;
pub mod camera;
pub mod dense;
pub mod error;
pub mod fused;
mod load;
mod map_file;
pub mod model;
pub mod names;
pub mod overlap;
mod parse;
pub mod ply;
pub mod pose;
pub mod scene;
pub mod stats;
mod txt;
pub mod undistort;
mod write;

pub use camera::{Camera, CameraModel, Projection, ProjectionVisitor};
pub use error::{ColmapError, Record, Result};
pub use load::{
    detect_format, find_model_dir, model_from_bytes, read_model, read_scene, ModelFiles,
    MODEL_FILES,
};
pub use model::{
    Format, Frame, Image, Point2D, Point3D, Reconstruction, Rig, SensorId, TrackElement, Warning,
    NO_POINT3D,
};
pub use ply::{read_ply, read_ply_file_into, read_ply_from, write_ply, PointCloud, VertexSink};
pub use pose::{LocalRigid3, Rigid3};
pub use scene::{sub_models, ModelChoice, Scene, SubModel};
pub use stats::{observation_errors, reprojection_stats, ImageReprojection, ReprojectionStats};
pub use undistort::{
    undistort_camera, undistort_reconstruction, undistorted_keypoint, UndistortError,
    UndistortOptions,
};
pub use write::write_model;
