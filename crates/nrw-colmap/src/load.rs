//! Finding a model on disk, choosing its encoding, reading it and checking it as a whole.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use crate::error::{ColmapError, Record, Result};
use crate::model::{Format, Reconstruction, SensorId, Warning};
use crate::parse::PoseCheck;

/// The three files every COLMAP sparse model has.
pub const MODEL_FILES: [&str; 3] = ["cameras", "images", "points3D"];

/// Whether `dir` holds a model's cameras file in either encoding.
pub(crate) fn has_model(dir: &Path) -> bool {
    [Format::Binary, Format::Text]
        .iter()
        .any(|f| dir.join(format!("cameras.{}", f.ext())).is_file())
}

/// The model folder of a scene: the folder itself, `sparse/0/` or `sparse/` below it.
pub fn find_model_dir(scene: &Path) -> Result<PathBuf> {
    let candidates = [
        scene.to_path_buf(),
        scene.join("sparse").join("0"),
        scene.join("sparse"),
    ];
    for c in &candidates {
        if has_model(c) {
            return Ok(c.clone());
        }
    }
    if !scene.exists() {
        return Err(ColmapError::io(
            scene,
            std::io::Error::new(std::io::ErrorKind::NotFound, "no such file or directory"),
        ));
    }
    Err(ColmapError::NoModel {
        path: scene.to_path_buf(),
        looked: candidates
            .iter()
            .map(|c| c.display().to_string())
            .collect::<Vec<_>>()
            .join(", "),
    })
}

/// Which encoding a model folder holds: binary when all three .bin files exist, else text.
pub fn detect_format(dir: &Path) -> Result<Format> {
    for f in [Format::Binary, Format::Text] {
        let present: Vec<bool> = MODEL_FILES
            .iter()
            .map(|n| dir.join(format!("{n}.{}", f.ext())).is_file())
            .collect();
        if present.iter().all(|&p| p) {
            return Ok(f);
        }
        if present[0] {
            let missing: Vec<String> = MODEL_FILES
                .iter()
                .zip(&present)
                .filter(|(_, &p)| !p)
                .map(|(n, _)| format!("{n}.{}", f.ext()))
                .collect();
            // A partial binary model next to a complete text one is fine: use the text one.
            let other = if f == Format::Binary {
                Format::Text
            } else {
                Format::Binary
            };
            if MODEL_FILES
                .iter()
                .all(|n| dir.join(format!("{n}.{}", other.ext())).is_file())
            {
                return Ok(other);
            }
            return Err(ColmapError::invalid(
                dir,
                Record::File,
                "files",
                format!("incomplete model: {} missing", missing.join(" and ")),
            ));
        }
    }
    Err(ColmapError::NoModel {
        path: dir.to_path_buf(),
        looked: dir.display().to_string(),
    })
}

fn read_bytes(path: &Path) -> Result<Vec<u8>> {
    std::fs::read(path).map_err(|e| ColmapError::io(path, e))
}

/// Read the scene's model (see [`find_model_dir`]) in the encoding found there.
pub fn read_scene(scene: &Path) -> Result<Reconstruction> {
    let dir = find_model_dir(scene)?;
    read_model(&dir, None)
}

/// Read a model folder; `format` forces an encoding, `None` prefers binary.
pub fn read_model(dir: &Path, format: Option<Format>) -> Result<Reconstruction> {
    let format = match format {
        Some(f) => f,
        None => detect_format(dir)?,
    };
    let file = |n: &str| dir.join(format!("{n}.{}", format.ext()));
    let optional = |p: PathBuf| -> Result<Option<(PathBuf, Vec<u8>)>> {
        if p.is_file() {
            let bytes = read_bytes(&p)?;
            Ok(Some((p, bytes)))
        } else {
            Ok(None)
        }
    };
    let files = ModelFiles {
        cameras: (file("cameras"), read_bytes(&file("cameras"))?),
        images: (file("images"), read_bytes(&file("images"))?),
        points: (file("points3D"), read_bytes(&file("points3D"))?),
        rigs: optional(file("rigs"))?,
        frames: optional(file("frames"))?,
    };
    model_from_bytes(format, &files)
}

/// A model's file contents with the names to report them under (no file system needed).
#[derive(Debug, Clone, Default)]
pub struct ModelFiles {
    pub cameras: (PathBuf, Vec<u8>),
    pub images: (PathBuf, Vec<u8>),
    pub points: (PathBuf, Vec<u8>),
    pub rigs: Option<(PathBuf, Vec<u8>)>,
    pub frames: Option<(PathBuf, Vec<u8>)>,
}

/// A text model file's contents: UTF-8, and ending in a newline as COLMAP always writes.
fn utf8<'a>(path: &Path, bytes: &'a [u8]) -> Result<&'a str> {
    if bytes.last().is_some_and(|&b| b != b'\n') {
        // Without the final newline the last record may have been cut mid-number.
        let line = bytes.iter().filter(|&&b| b == b'\n').count() + 1;
        return Err(ColmapError::invalid(
            path,
            Record::Line {
                kind: "last",
                line,
                id: None,
            },
            "end of file",
            "file is truncated: the last line has no newline",
        ));
    }
    std::str::from_utf8(bytes).map_err(|e| {
        let at = e.valid_up_to();
        let line = bytes[..at].iter().filter(|&&b| b == b'\n').count() + 1;
        ColmapError::invalid(
            path,
            Record::Line {
                kind: "text",
                line,
                id: None,
            },
            "bytes",
            format!("not UTF-8 text (byte offset {at})"),
        )
    })
}

/// Parse and cross-check a model held in memory: what [`read_model`] does after reading files.
pub fn model_from_bytes(format: Format, files: &ModelFiles) -> Result<Reconstruction> {
    let mut checks = PoseCheck::default();
    let mut rec = Reconstruction {
        format: Some(format),
        ..Default::default()
    };
    let (cams, imgs, pts) = (&files.cameras, &files.images, &files.points);
    match format {
        Format::Binary => {
            rec.cameras = crate::bin::read_cameras(&cams.0, &cams.1)?;
            rec.images = crate::bin::read_images(&imgs.0, &imgs.1, &mut checks)?;
            rec.points = crate::bin::read_points(&pts.0, &pts.1)?;
            if let Some((p, b)) = &files.rigs {
                rec.rigs = crate::bin::read_rigs(p, b, &mut checks)?;
            }
            if let Some((p, b)) = &files.frames {
                rec.frames = crate::bin::read_frames(p, b, &mut checks)?;
            }
        }
        Format::Text => {
            rec.cameras = crate::txt::read_cameras(&cams.0, utf8(&cams.0, &cams.1)?)?;
            rec.images = crate::txt::read_images(&imgs.0, utf8(&imgs.0, &imgs.1)?, &mut checks)?;
            rec.points = crate::txt::read_points(&pts.0, utf8(&pts.0, &pts.1)?)?;
            if let Some((p, b)) = &files.rigs {
                rec.rigs = crate::txt::read_rigs(p, utf8(p, b)?, &mut checks)?;
            }
            if let Some((p, b)) = &files.frames {
                rec.frames = crate::txt::read_frames(p, utf8(p, b)?, &mut checks)?;
            }
        }
    }
    rec.files = [
        Some(cams),
        Some(imgs),
        Some(pts),
        files.rigs.as_ref(),
        files.frames.as_ref(),
    ]
    .into_iter()
    .flatten()
    .map(|(p, _)| p.clone())
    .collect();
    rec.warnings = checks.warnings;
    let frames_path = files
        .frames
        .as_ref()
        .map(|f| f.0.clone())
        .unwrap_or_default();
    validate(&mut rec, &imgs.0, &pts.0, &frames_path)?;
    Ok(rec)
}

/// Cross-reference checks: every id a record names must exist, and tracks must match keypoints.
fn validate(rec: &mut Reconstruction, imgs: &Path, pts: &Path, frames: &Path) -> Result<()> {
    let keypoint_links = check_images(rec, imgs)?;
    let track_links = check_tracks(rec, pts)?;
    if track_links != keypoint_links {
        return Err(ColmapError::invalid(
            imgs,
            Record::File,
            "points2D.point3D_id",
            format!(
                "{keypoint_links} keypoints name a 3D point but the tracks list {track_links} observations"
            ),
        ));
    }
    let warnings = check_frames(rec, frames)?;
    rec.warnings.extend(warnings);
    Ok(())
}

/// Each image's camera, name and keypoints' 3D points exist and its name is unique; returns
/// how many keypoints name a 3D point.
fn check_images(rec: &Reconstruction, imgs: &Path) -> Result<usize> {
    let mut names: HashMap<&str, u32> = HashMap::with_capacity(rec.images.len());
    let mut keypoint_links = 0usize;
    for img in rec.images.values() {
        let r = Record::Id {
            kind: "image",
            id: img.id as u64,
        };
        if !rec.cameras.contains_key(&img.camera_id) {
            return Err(ColmapError::invalid(
                imgs,
                r,
                "camera_id",
                format!(
                    "refers to camera {}, which the cameras file does not define",
                    img.camera_id
                ),
            ));
        }
        if let Some(other) = names.insert(img.name.as_str(), img.id) {
            return Err(ColmapError::invalid(
                imgs,
                r,
                "name",
                format!(
                    "duplicate image name {:?}: image {other} has it too",
                    img.name
                ),
            ));
        }
        for (k, p) in img.points2d.iter().enumerate() {
            if p.has_point3d() {
                if !rec.points.contains_key(&p.point3d_id) {
                    return Err(ColmapError::invalid(
                        imgs,
                        r,
                        format!("points2D[{k}].point3D_id"),
                        format!(
                            "refers to point {}, which the points3D file does not define",
                            p.point3d_id
                        ),
                    ));
                }
                keypoint_links += 1;
            }
        }
    }
    Ok(keypoint_links)
}

/// Each track element names an existing image and keypoint, and that keypoint names the
/// point back; returns how many elements the tracks hold.
fn check_tracks(rec: &Reconstruction, pts: &Path) -> Result<usize> {
    let mut track_links = 0usize;
    for p in rec.points.values() {
        let r = Record::Id {
            kind: "point3D",
            id: p.id,
        };
        for (k, el) in p.track.iter().enumerate() {
            let Some(img) = rec.images.get(&el.image_id) else {
                return Err(ColmapError::invalid(
                    pts,
                    r,
                    format!("track[{k}].image_id"),
                    format!(
                        "refers to image {}, which the images file does not define",
                        el.image_id
                    ),
                ));
            };
            let Some(kp) = img.points2d.get(el.point2d_idx as usize) else {
                return Err(ColmapError::invalid(
                    pts,
                    r,
                    format!("track[{k}].point2D_idx"),
                    format!(
                        "keypoint {} does not exist: image {} has {} keypoints",
                        el.point2d_idx,
                        el.image_id,
                        img.points2d.len()
                    ),
                ));
            };
            if kp.point3d_id != p.id {
                return Err(ColmapError::invalid(
                    pts,
                    r,
                    format!("track[{k}]"),
                    format!(
                        "image {} keypoint {} observes point {}, not this one",
                        el.image_id,
                        el.point2d_idx,
                        if kp.has_point3d() {
                            kp.point3d_id.to_string()
                        } else {
                            "none".into()
                        }
                    ),
                ));
            }
            track_links += 1;
        }
    }
    Ok(track_links)
}

/// Each frame's rig and images exist; a warning for each image whose stored pose differs
/// from the one its frame and rig compose (COLMAP 4 derives it from them).
fn check_frames(rec: &Reconstruction, frames: &Path) -> Result<Vec<Warning>> {
    let mut warnings: Vec<Warning> = Vec::new();
    let rig_sensors: BTreeMap<u32, _> = rec.rigs.iter().map(|(id, r)| (*id, r)).collect();
    for f in rec.frames.values() {
        let r = Record::Id {
            kind: "frame",
            id: f.id as u64,
        };
        let Some(rig) = rig_sensors.get(&f.rig_id) else {
            if rec.rigs.is_empty() {
                continue; // frames without a rigs file: nothing to compose with
            }
            return Err(ColmapError::invalid(
                frames,
                r,
                "rig_id",
                format!(
                    "refers to rig {}, which the rigs file does not define",
                    f.rig_id
                ),
            ));
        };
        for (sensor, data_id) in &f.data {
            if sensor.kind != SensorId::CAMERA {
                continue;
            }
            let image_id = u32::try_from(*data_id).ok();
            let Some(img) = image_id.and_then(|i| rec.images.get(&i)) else {
                return Err(ColmapError::invalid(
                    frames,
                    r,
                    "data_ids",
                    format!("refers to image {data_id}, which the images file does not define"),
                ));
            };
            // COLMAP 4 derives an image's pose from its frame; check the stored one agrees.
            let sensor_from_rig = if rig.ref_sensor == Some(*sensor) {
                Some(crate::pose::Rigid3::IDENTITY)
            } else {
                rig.sensors
                    .iter()
                    .find(|(s, _)| s == sensor)
                    .and_then(|(_, p)| *p)
            };
            if let Some(s) = sensor_from_rig {
                let composed = s.compose(&f.rig_from_world);
                let stored = img.cam_from_world;
                let dq = composed.rotation.dot(stored.rotation).abs();
                let dt = (composed.translation - stored.translation).length();
                let scale = stored.translation.length().max(1.0);
                if 1.0 - dq > 1e-12 || dt > 1e-9 * scale {
                    warnings.push(Warning {
                        path: frames.to_path_buf(),
                        record: r.to_string(),
                        field: "rig_from_world".into(),
                        message: format!(
                            "image {} pose in the images file differs from its frame's pose (|Δt| = {dt:.3e}); the images file's pose is used",
                            img.id
                        ),
                    });
                }
            }
        }
    }
    Ok(warnings)
}
