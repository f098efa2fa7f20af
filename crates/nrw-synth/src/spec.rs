//! The scene spec: a small TOML file. Every effect is opt-in; an effect the spec does not
//! name is never computed (see [`crate::Counters`], which tests use to prove it).

use serde::{Deserialize, Serialize};

use crate::error::{Result, SynthError};

/// A whole synthetic scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneSpec {
    pub name: String,
    /// Same seed, same bytes.
    pub seed: u64,
    #[serde(default)]
    pub geometry: GeometrySpec,
    #[serde(default)]
    pub cameras: CameraSpec,
    #[serde(default)]
    pub observations: ObservationSpec,
    /// Absent table or absent keys: no effect simulated.
    #[serde(default)]
    pub effects: EffectsSpec,
}

/// The landmark and its dense cloud.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GeometrySpec {
    /// Points in dense/fused.ply (10⁴ … 10⁷).
    pub points: usize,
    /// Façade width and height in metres.
    pub facade_width: f64,
    pub facade_height: f64,
    /// Window columns and rows.
    pub bays: usize,
    pub floors: usize,
    /// A portico of columns in front of the façade.
    pub columns: bool,
    /// Offset added to every world coordinate written (e.g. UTM-like [5e6, 5e6, 0]).
    pub origin: [f64; 3],
}

impl Default for GeometrySpec {
    fn default() -> Self {
        GeometrySpec {
            points: 200_000,
            facade_width: 24.0,
            facade_height: 14.0,
            bays: 6,
            floors: 3,
            columns: true,
            origin: [0.0; 3],
        }
    }
}

/// The photographers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CameraSpec {
    pub count: usize,
    /// Any COLMAP model name this project projects (SIMPLE_PINHOLE … FISHEYE).
    pub model: String,
    /// Scales the model's default distortion coefficients (0 = none).
    pub distortion: f64,
    /// Shorter sides of photos are drawn between these (the longer follows from 4:3, 3:4 or 3:2).
    pub min_size: u32,
    pub max_size: u32,
    /// Fraction of small photos (shorter side 200–330 px, longer under 450 px).
    pub small_fraction: f64,
    /// Fraction of photos that look mostly away from the landmark.
    pub away_fraction: f64,
    /// One camera shared by all photos (then all photos have one size).
    pub shared: bool,
    /// Rays a pixel per axis: a pixel's colour is the mean of `n × n` rays spread evenly over
    /// it, as a sensor integrates its pixel's area (1: the centre ray alone, which aliases fine
    /// texture seen at a grazing angle, as the ground is). Depth and labels stay the centre's.
    #[serde(skip_serializing_if = "one_ray")]
    pub pixel_samples: u32,
    /// Distance range from the façade, metres.
    pub min_distance: f64,
    pub max_distance: f64,
}

impl Default for CameraSpec {
    fn default() -> Self {
        CameraSpec {
            count: 24,
            model: "SIMPLE_RADIAL".into(),
            distortion: 1.0,
            min_size: 480,
            max_size: 800,
            small_fraction: 0.15,
            away_fraction: 0.15,
            shared: false,
            pixel_samples: 1,
            min_distance: 12.0,
            max_distance: 40.0,
        }
    }
}

/// Whether a pixel is one ray (the default, left out of a written spec so that the scenes
/// written before `pixel_samples` existed keep their bytes).
fn one_ray(n: &u32) -> bool {
    *n == 1
}

/// The sparse model's keypoints and tracks.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ObservationSpec {
    /// Surface points tried as SfM features; those seen by two photos become 3D points.
    pub features: usize,
    /// Gaussian keypoint noise (pixels, per axis): the honest reprojection error.
    pub noise_px: f64,
    /// Unmatched keypoints per matched one (COLMAP keeps many).
    pub extra_keypoints: f64,
}

impl Default for ObservationSpec {
    fn default() -> Self {
        ObservationSpec {
            features: 3000,
            noise_px: 0.5,
            extra_keypoints: 0.3,
        }
    }
}

/// Photo effects; each is simulated only when present.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EffectsSpec {
    /// Times of day to draw from: day, overcast, sunset, night. Absent: flat neutral light.
    pub appearance: Option<Vec<Appearance>>,
    /// Standard deviation of exposure offsets, in stops.
    pub exposure_ev: Option<f64>,
    /// Standard deviation of red/blue white-balance gains.
    pub white_balance: Option<f64>,
    /// Haze density per metre (0.01 ≈ 37% veiled at 100 m).
    pub haze: Option<f64>,
    /// Mean number of people per photo (with ADE20K label maps, person = 13).
    pub transients: Option<f64>,
    /// Sensor noise standard deviation on [0, 1] intensities.
    pub noise: Option<f64>,
    /// Write photos as JPEG at this quality (else lossless PNG).
    pub jpeg_quality: Option<u8>,
    /// Floating points added to dense/fused.ply, as a fraction of its surface points (the
    /// multi-view-stereo clutter `ingest --denoise` removes); they are the file's last
    /// vertices, counted in ground_truth/outliers.json.
    pub outliers: Option<f64>,
    /// Fine surface texture (stone grain, brick and pavement wear) as a relative albedo
    /// variation, e.g. 0.3: what multi-view stereo matches on; simulated only when present.
    pub texture: Option<f64>,
}

/// A time of day.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Appearance {
    Day,
    Overcast,
    Sunset,
    Night,
}

impl Appearance {
    /// Lower-case label used in ground truth and reports.
    pub fn label(self) -> &'static str {
        match self {
            Appearance::Day => "day",
            Appearance::Overcast => "overcast",
            Appearance::Sunset => "sunset",
            Appearance::Night => "night",
        }
    }
}

/// Most points a synthetic scene may have (its generator holds them all in f64).
pub const MAX_POINTS: usize = 50_000_000;

impl SceneSpec {
    /// The embedded default demo scene.
    pub fn demo() -> SceneSpec {
        toml::from_str(DEMO_TOML).expect("embedded demo spec parses")
    }

    /// The same scene at test or benchmark size: `photos` photos whose shorter sides lie in
    /// `sizes`, every one usable (none small, none looking away), `points` dense points.
    pub fn shrunk(mut self, photos: usize, sizes: (u32, u32), points: usize) -> SceneSpec {
        self.cameras.count = photos;
        (self.cameras.min_size, self.cameras.max_size) = sizes;
        self.cameras.small_fraction = 0.0;
        self.cameras.away_fraction = 0.0;
        self.geometry.points = points;
        self
    }

    /// Parse a spec file's text; `origin` names the file in errors.
    pub fn from_toml(text: &str, origin: &str) -> Result<SceneSpec> {
        let spec: SceneSpec = toml::from_str(text).map_err(|e| SynthError::Spec {
            file: origin.into(),
            problem: e.to_string(),
        })?;
        spec.validate(origin)?;
        Ok(spec)
    }

    /// Reject specs that cannot make a scene, naming the key.
    pub fn validate(&self, origin: &str) -> Result<()> {
        self.check_geometry()
            .and_then(|()| self.check_cameras())
            .and_then(|()| self.check_effects())
            .map_err(|(key, problem)| SynthError::Spec {
                file: origin.into(),
                problem: format!("{key}: {problem}"),
            })
    }

    /// The geometry's sizes, counts and origin.
    fn check_geometry(&self) -> Checked {
        let g = &self.geometry;
        if !(g.facade_width > 1.0 && g.facade_height > 1.0) {
            return bad("geometry.facade_width/height", "must exceed 1 m");
        }
        if g.bays == 0 || g.floors == 0 || g.bays > 64 || g.floors > 64 {
            return bad("geometry.bays/floors", "must be 1 to 64");
        }
        if g.points > MAX_POINTS {
            return bad(
                "geometry.points",
                format!("{} is more than 5·10⁷ (MAX_POINTS)", g.points),
            );
        }
        if !g.origin.iter().all(|v| v.is_finite()) {
            return bad("geometry.origin", "must be finite");
        }
        Ok(())
    }

    /// The cameras' model, count, sizes, fractions and distances, and the keypoints' noise.
    fn check_cameras(&self) -> Checked {
        let c = &self.cameras;
        match nrw_colmap::CameraModel::from_name(&c.model) {
            None => {
                return bad(
                    "cameras.model",
                    format!("unknown camera model {:?}", c.model),
                )
            }
            Some(m) if m.is_spherical() => {
                return bad(
                    "cameras.model",
                    format!(
                    "{m} is a 360° panorama: the renderer draws perspective and fisheye views only"
                ),
                )
            }
            Some(_) => {}
        }
        if c.count == 0 || c.count > 100_000 {
            return bad("cameras.count", "must be 1 to 100000");
        }
        if !(16 <= c.min_size && c.min_size <= c.max_size && c.max_size <= 8192) {
            return bad("cameras.min_size/max_size", "need 16 ≤ min ≤ max ≤ 8192");
        }
        if !(1..=16).contains(&c.pixel_samples) {
            return bad(
                "cameras.pixel_samples",
                "must be 1 to 16 rays a pixel per axis",
            );
        }
        for (k, v) in [
            ("small_fraction", c.small_fraction),
            ("away_fraction", c.away_fraction),
        ] {
            if !(0.0..=1.0).contains(&v) {
                return bad(&format!("cameras.{k}"), format!("{v} is not in [0, 1]"));
            }
        }
        if !(c.min_distance > 1.0 && c.min_distance <= c.max_distance) {
            return bad("cameras.min_distance/max_distance", "need 1 < min ≤ max");
        }
        if !(self.observations.noise_px >= 0.0 && self.observations.extra_keypoints >= 0.0) {
            return bad("observations", "noise_px and extra_keypoints must be ≥ 0");
        }
        Ok(())
    }

    /// Each effect's value, where the spec asks for it.
    fn check_effects(&self) -> Checked {
        let e = &self.effects;
        if e.appearance.as_ref().is_some_and(|a| a.is_empty()) {
            return bad(
                "effects.appearance",
                "list at least one time of day, or leave it out",
            );
        }
        for (k, v) in [
            ("exposure_ev", e.exposure_ev),
            ("white_balance", e.white_balance),
            ("haze", e.haze),
            ("transients", e.transients),
            ("noise", e.noise),
            ("texture", e.texture),
        ] {
            if v.is_some_and(|v| !(v >= 0.0 && v.is_finite())) {
                return bad(&format!("effects.{k}"), "must be a finite number ≥ 0");
            }
        }
        if e.jpeg_quality.is_some_and(|q| !(1..=100).contains(&q)) {
            return bad("effects.jpeg_quality", "must be 1 to 100");
        }
        Ok(())
    }
}

/// The default demo scene, embedded so `nrw-etl demo` needs no file.
pub const DEMO_TOML: &str = include_str!("../../../scenes/demo.toml");

/// A spec check's outcome: the key at fault and what is wrong with it.
type Checked = std::result::Result<(), (String, String)>;

/// A failed check of `key`.
fn bad(key: &str, problem: impl Into<String>) -> Checked {
    Err((key.to_string(), problem.into()))
}
