//! The reconstruction as read: id-keyed maps of cameras, images and points, plus what we noticed.

use std::collections::BTreeMap;
use std::path::PathBuf;

use glam::{DVec2, DVec3};

use crate::camera::Camera;
use crate::pose::Rigid3;

/// COLMAP's "no 3D point" marker in points2D (u64::MAX in .bin, -1 in .txt).
pub const NO_POINT3D: u64 = u64::MAX;

/// A keypoint of an image, and the 3D point it observes if any.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Point2D {
    pub xy: DVec2,
    /// [`NO_POINT3D`] when the keypoint triangulated nothing.
    pub point3d_id: u64,
}

impl Point2D {
    /// Whether this keypoint observes a 3D point.
    pub fn has_point3d(&self) -> bool {
        self.point3d_id != NO_POINT3D
    }
}

/// A registered photo: its pose, camera and keypoints.
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    pub id: u32,
    pub name: String,
    pub camera_id: u32,
    /// World→camera transform; the quaternion is normalised on read.
    pub cam_from_world: Rigid3,
    /// Norm of the quaternion as stored, so tools can report a renormalisation.
    pub stored_quat_norm: f64,
    pub points2d: Vec<Point2D>,
}

impl Image {
    /// Keypoints that observe a 3D point.
    pub fn num_observations(&self) -> usize {
        self.points2d.iter().filter(|p| p.has_point3d()).count()
    }
}

/// One observation of a 3D point: which image and which of its keypoints.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TrackElement {
    pub image_id: u32,
    pub point2d_idx: u32,
}

/// A triangulated point with its colour, COLMAP's error and its track.
#[derive(Debug, Clone, PartialEq)]
pub struct Point3D {
    pub id: u64,
    pub xyz: DVec3,
    pub rgb: [u8; 3],
    /// COLMAP's stored mean reprojection error (px); −1 when COLMAP did not compute it.
    pub error: f64,
    pub track: Vec<TrackElement>,
}

/// A sensor of a COLMAP 4 rig.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub struct SensorId {
    /// COLMAP's sensor type: 0 camera, 1 IMU; other values are kept as read.
    pub kind: i32,
    pub id: u32,
}

impl SensorId {
    /// COLMAP's code for a camera sensor.
    pub const CAMERA: i32 = 0;
    /// COLMAP's code for an IMU sensor.
    pub const IMU: i32 = 1;
}

/// A COLMAP 4 rig: a reference sensor and others at fixed offsets.
#[derive(Debug, Clone, PartialEq)]
pub struct Rig {
    pub id: u32,
    pub ref_sensor: Option<SensorId>,
    /// Non-reference sensors with their sensor_from_rig transform, when known.
    pub sensors: Vec<(SensorId, Option<Rigid3>)>,
}

/// A COLMAP 4 frame: one rig pose and the images taken at it.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    pub id: u32,
    pub rig_id: u32,
    pub rig_from_world: Rigid3,
    /// (sensor, data id); for camera sensors the data id is an image id.
    pub data: Vec<(SensorId, u64)>,
}

/// Which encoding the model files use.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    Binary,
    Text,
}

impl Format {
    /// Every encoding, for parsers that list them.
    pub const ALL: [Format; 2] = [Format::Binary, Format::Text];

    /// The file extension of this encoding.
    pub fn ext(self) -> &'static str {
        match self {
            Format::Binary => "bin",
            Format::Text => "txt",
        }
    }

    /// The encoding's name on a command line: its files' extension.
    pub fn name(self) -> &'static str {
        self.ext()
    }

    /// One line on the files of this encoding.
    pub fn summary(self) -> &'static str {
        match self {
            Format::Binary => "cameras.bin, images.bin, points3D.bin (preferred when both exist)",
            Format::Text => "cameras.txt, images.txt, points3D.txt",
        }
    }
}

impl std::str::FromStr for Format {
    type Err = String;

    /// An encoding by its name (`bin`, `txt`); the error lists the names.
    fn from_str(s: &str) -> std::result::Result<Format, String> {
        Format::ALL
            .into_iter()
            .find(|f| f.name() == s)
            .ok_or_else(|| format!("{s:?} is not a model encoding: bin, txt"))
    }
}

/// Something worth a human's attention that did not stop the read.
#[derive(Debug, Clone, PartialEq)]
pub struct Warning {
    pub path: PathBuf,
    pub record: String,
    pub field: String,
    pub message: String,
}

impl std::fmt::Display for Warning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}: {}: field `{}`: {}",
            self.path.display(),
            self.record,
            self.field,
            self.message
        )
    }
}

/// A COLMAP sparse model with every cross-reference checked.
#[derive(Debug, Clone, Default)]
pub struct Reconstruction {
    pub cameras: BTreeMap<u32, Camera>,
    pub images: BTreeMap<u32, Image>,
    pub points: BTreeMap<u64, Point3D>,
    /// Present only in the COLMAP 4 layout.
    pub rigs: BTreeMap<u32, Rig>,
    /// Present only in the COLMAP 4 layout.
    pub frames: BTreeMap<u32, Frame>,
    /// The model files read, in the order read.
    pub files: Vec<PathBuf>,
    pub format: Option<Format>,
    pub warnings: Vec<Warning>,
}

impl Reconstruction {
    /// Total track length: how many (image, keypoint) pairs observe a 3D point.
    pub fn num_observations(&self) -> usize {
        self.points.values().map(|p| p.track.len()).sum()
    }

    /// Whether the model came in COLMAP 4's layout (rigs and frames).
    pub fn is_colmap4(&self) -> bool {
        !self.rigs.is_empty() || !self.frames.is_empty()
    }

    /// Sorted, de-duplicated names of the camera models in use.
    pub fn camera_model_names(&self) -> Vec<&'static str> {
        let mut names: Vec<_> = self.cameras.values().map(|c| c.model.name()).collect();
        names.sort_unstable();
        names.dedup();
        names
    }

    /// A representative point near the scene (mean camera centre), for re-centring in f64.
    pub fn scene_origin(&self) -> DVec3 {
        if self.images.is_empty() {
            return self
                .points
                .values()
                .next()
                .map(|p| p.xyz)
                .unwrap_or(DVec3::ZERO);
        }
        let sum: DVec3 = self
            .images
            .values()
            .map(|i| i.cam_from_world.centre())
            .sum();
        sum / self.images.len() as f64
    }
}
