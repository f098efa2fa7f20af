//! COLMAP's text model files, with line numbers in every error.

use std::collections::BTreeMap;
use std::path::Path;
use std::str::FromStr;

use glam::{DVec2, DVec3};

use crate::camera::{Camera, CameraModel};
use crate::error::{ColmapError, Record, Result};
use crate::model::{Frame, Image, Point2D, Point3D, Rig, SensorId, TrackElement, NO_POINT3D};
use crate::parse::{check_camera, check_finite, make_pose, pose_flag, PoseCheck};

/// Whitespace-separated tokens of one line, parsed with the file, line and field in errors.
struct Tokens<'a> {
    path: &'a Path,
    rec: Record,
    it: std::str::SplitAsciiWhitespace<'a>,
}

impl<'a> Tokens<'a> {
    fn new(path: &'a Path, rec: Record, line: &'a str) -> Self {
        Tokens {
            path,
            rec,
            it: line.split_ascii_whitespace(),
        }
    }

    fn str(&mut self, field: &str) -> Result<&'a str> {
        self.it.next().ok_or_else(|| {
            ColmapError::invalid(self.path, self.rec, field, "missing: the line ends early")
        })
    }

    fn num<T: FromStr>(&mut self, field: &str) -> Result<T>
    where
        T::Err: std::fmt::Display,
    {
        let s = self.str(field)?;
        s.parse::<T>().map_err(|e| {
            ColmapError::invalid(
                self.path,
                self.rec,
                field,
                format!("cannot parse {s:?}: {e}"),
            )
        })
    }

    fn finite(&mut self, field: &str) -> Result<f64> {
        let v = self.num::<f64>(field)?;
        check_finite(self.path, self.rec, field, v)
    }

    fn pose(&mut self, prefix: &str) -> Result<([f64; 4], [f64; 3])> {
        let mut q = [0.0; 4];
        for (i, n) in ["qw", "qx", "qy", "qz"].iter().enumerate() {
            q[i] = self.finite(&format!("{prefix}{n}"))?;
        }
        let mut t = [0.0; 3];
        for (i, n) in ["tx", "ty", "tz"].iter().enumerate() {
            t[i] = self.finite(&format!("{prefix}{n}"))?;
        }
        Ok((q, t))
    }

    fn sensor(&mut self, field: &str) -> Result<SensorId> {
        let kind_s = self.str(&format!("{field}.type"))?;
        let kind = match kind_s {
            "CAMERA" => SensorId::CAMERA,
            "IMU" => SensorId::IMU,
            other => other.parse::<i32>().map_err(|_| {
                ColmapError::invalid(
                    self.path,
                    self.rec,
                    format!("{field}.type"),
                    format!("unknown sensor type {other:?} (expected CAMERA or IMU)"),
                )
            })?,
        };
        let id = self.num::<u32>(&format!("{field}.id"))?;
        Ok(SensorId { kind, id })
    }

    fn end(mut self) -> Result<()> {
        match self.it.next() {
            None => Ok(()),
            Some(extra) => Err(ColmapError::invalid(
                self.path,
                self.rec,
                "end of line",
                format!("unexpected extra value {extra:?}"),
            )),
        }
    }
}

/// Data lines (1-based number, text) of a COLMAP text file: comments and blank lines skipped.
fn data_lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    text.lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'))
}

fn duplicate(path: &Path, rec: Record, what: &str, id: u64) -> ColmapError {
    ColmapError::invalid(path, rec, "id", format!("duplicate {what} id {id}"))
}

/// cameras.txt
pub(crate) fn read_cameras(path: &Path, text: &str) -> Result<BTreeMap<u32, Camera>> {
    let mut out = BTreeMap::new();
    for (line, l) in data_lines(text) {
        let mut rec = Record::Line {
            kind: "camera",
            line,
            id: None,
        };
        let mut t = Tokens::new(path, rec, l);
        let id: u32 = t.num("CAMERA_ID")?;
        rec = rec.with_id(id as u64);
        t.rec = rec;
        let name = t.str("MODEL")?;
        let model = CameraModel::from_name(name).ok_or_else(|| {
            ColmapError::invalid(path, rec, "MODEL", format!("unknown camera model {name:?}"))
        })?;
        let width: u64 = t.num("WIDTH")?;
        let height: u64 = t.num("HEIGHT")?;
        let params: Vec<&str> = t.it.by_ref().collect();
        if params.len() != model.num_params() {
            return Err(ColmapError::invalid(
                path,
                rec,
                "PARAMS",
                format!(
                    "{} takes {} parameters ({}), found {}",
                    model.name(),
                    model.num_params(),
                    model.param_names().join(", "),
                    params.len()
                ),
            ));
        }
        let mut values = Vec::with_capacity(params.len());
        for (s, pname) in params.iter().zip(model.param_names()) {
            let mut tk = Tokens::new(path, rec, s);
            values.push(tk.finite(pname)?);
        }
        let cam = Camera {
            id,
            model,
            width,
            height,
            params: values,
        };
        check_camera(path, rec, &cam)?;
        if out.insert(id, cam).is_some() {
            return Err(duplicate(path, rec, "camera", id as u64));
        }
    }
    Ok(out)
}

/// images.txt: two lines per image; the second (keypoints) may be empty.
pub(crate) fn read_images(
    path: &Path,
    text: &str,
    checks: &mut PoseCheck,
) -> Result<BTreeMap<u32, Image>> {
    let mut out = BTreeMap::new();
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l.trim()));
    while let Some((line, l)) = lines.next() {
        if l.is_empty() || l.starts_with('#') {
            continue;
        }
        let mut rec = Record::Line {
            kind: "image",
            line,
            id: None,
        };
        let mut t = Tokens::new(path, rec, l);
        let id: u32 = t.num("IMAGE_ID")?;
        rec = rec.with_id(id as u64);
        t.rec = rec;
        let (q, tr) = t.pose("")?;
        let (cam_from_world, stored_quat_norm) = make_pose(path, rec, "q", q, tr, checks)?;
        let camera_id: u32 = t.num("CAMERA_ID")?;
        // COLMAP writes the name last; it may contain spaces.
        let name = t.it.by_ref().collect::<Vec<_>>().join(" ");
        if name.is_empty() {
            return Err(ColmapError::invalid(
                path,
                rec,
                "NAME",
                "missing: the line ends early",
            ));
        }
        let Some((pline, pl)) = lines.next() else {
            return Err(ColmapError::invalid(
                path,
                rec,
                "POINTS2D",
                "file is truncated: the keypoint line after the image line is missing",
            ));
        };
        let prec = Record::Line {
            kind: "image points2D",
            line: pline,
            id: Some(id as u64),
        };
        let points2d = read_points2d(path, prec, pl)?;
        let img = Image {
            id,
            name,
            camera_id,
            cam_from_world,
            stored_quat_norm,
            points2d,
        };
        crate::names::check_model_name(path, rec, "NAME", &img.name)?;
        if out.insert(id, img).is_some() {
            return Err(duplicate(path, rec, "image", id as u64));
        }
    }
    Ok(out)
}

/// An image's keypoint line: (X, Y, POINT3D_ID) triples, −1 for a keypoint without a point.
fn read_points2d(path: &Path, prec: Record, pl: &str) -> Result<Vec<Point2D>> {
    let mut pt = Tokens::new(path, prec, pl);
    let mut points2d = Vec::new();
    let mut k = 0usize;
    while let Some(xs) = pt.it.next() {
        let field = |f: &str| format!("POINTS2D[{k}].{f}");
        let x = Tokens::new(path, prec, xs).finite(&field("X"))?;
        let y = pt.finite(&field("Y"))?;
        let pid: i64 = pt.num(&field("POINT3D_ID"))?;
        let point3d_id = match pid {
            -1 => NO_POINT3D,
            p if p >= 0 => p as u64,
            p => {
                return Err(ColmapError::invalid(
                    path,
                    prec,
                    field("POINT3D_ID"),
                    format!("must be -1 or a point id, found {p}"),
                ))
            }
        };
        points2d.push(Point2D {
            xy: DVec2::new(x, y),
            point3d_id,
        });
        k += 1;
    }
    Ok(points2d)
}

/// points3D.txt
pub(crate) fn read_points(path: &Path, text: &str) -> Result<BTreeMap<u64, Point3D>> {
    let mut out = BTreeMap::new();
    for (line, l) in data_lines(text) {
        let mut rec = Record::Line {
            kind: "point3D",
            line,
            id: None,
        };
        let mut t = Tokens::new(path, rec, l);
        let id: u64 = t.num("POINT3D_ID")?;
        rec = rec.with_id(id);
        t.rec = rec;
        let xyz = DVec3::new(t.finite("X")?, t.finite("Y")?, t.finite("Z")?);
        let rgb = [t.num::<u8>("R")?, t.num::<u8>("G")?, t.num::<u8>("B")?];
        let error: f64 = t.num("ERROR")?;
        if error.is_nan() {
            return Err(ColmapError::invalid(path, rec, "ERROR", "is NaN"));
        }
        let mut track = Vec::new();
        while let Some(s) = t.it.next() {
            let k = track.len();
            let image_id: u32 = Tokens::new(path, rec, s).num(&format!("TRACK[{k}].IMAGE_ID"))?;
            let point2d_idx: u32 = t.num(&format!("TRACK[{k}].POINT2D_IDX"))?;
            track.push(TrackElement {
                image_id,
                point2d_idx,
            });
        }
        if out
            .insert(
                id,
                Point3D {
                    id,
                    xyz,
                    rgb,
                    error,
                    track,
                },
            )
            .is_some()
        {
            return Err(duplicate(path, rec, "point3D", id));
        }
    }
    Ok(out)
}

/// rigs.txt (COLMAP 4)
pub(crate) fn read_rigs(
    path: &Path,
    text: &str,
    checks: &mut PoseCheck,
) -> Result<BTreeMap<u32, Rig>> {
    let mut out = BTreeMap::new();
    for (line, l) in data_lines(text) {
        let mut rec = Record::Line {
            kind: "rig",
            line,
            id: None,
        };
        let mut t = Tokens::new(path, rec, l);
        let id: u32 = t.num("RIG_ID")?;
        rec = rec.with_id(id as u64);
        t.rec = rec;
        let n: usize = t.num("NUM_SENSORS")?;
        let mut ref_sensor = None;
        let mut sensors = Vec::new();
        if n > 0 {
            ref_sensor = Some(t.sensor("REF_SENSOR")?);
            // Each further sensor needs at least three tokens; a bigger count is a lie.
            if n - 1 > l.len() / 3 {
                return Err(ColmapError::invalid(
                    path,
                    rec,
                    "NUM_SENSORS",
                    format!("count {n} cannot fit on a line of {} bytes", l.len()),
                ));
            }
            for _ in 1..n {
                let s = t.sensor("SENSOR")?;
                let has_pose: u8 = t.num("HAS_POSE")?;
                let pose = if pose_flag(path, rec, "HAS_POSE", has_pose)? {
                    let (q, tr) = t.pose("SENSOR_FROM_RIG.")?;
                    Some(make_pose(path, rec, "SENSOR_FROM_RIG.q", q, tr, checks)?.0)
                } else {
                    None
                };
                sensors.push((s, pose));
            }
        }
        t.end()?;
        if out
            .insert(
                id,
                Rig {
                    id,
                    ref_sensor,
                    sensors,
                },
            )
            .is_some()
        {
            return Err(duplicate(path, rec, "rig", id as u64));
        }
    }
    Ok(out)
}

/// frames.txt (COLMAP 4)
pub(crate) fn read_frames(
    path: &Path,
    text: &str,
    checks: &mut PoseCheck,
) -> Result<BTreeMap<u32, Frame>> {
    let mut out = BTreeMap::new();
    for (line, l) in data_lines(text) {
        let mut rec = Record::Line {
            kind: "frame",
            line,
            id: None,
        };
        let mut t = Tokens::new(path, rec, l);
        let id: u32 = t.num("FRAME_ID")?;
        rec = rec.with_id(id as u64);
        t.rec = rec;
        let rig_id: u32 = t.num("RIG_ID")?;
        let (q, tr) = t.pose("RIG_FROM_WORLD.")?;
        let rig_from_world = make_pose(path, rec, "RIG_FROM_WORLD.q", q, tr, checks)?.0;
        let n: usize = t.num("NUM_DATA_IDS")?;
        if n > l.len() / 3 {
            return Err(ColmapError::invalid(
                path,
                rec,
                "NUM_DATA_IDS",
                format!("count {n} cannot fit on a line of {} bytes", l.len()),
            ));
        }
        let mut data = Vec::with_capacity(n);
        for _ in 0..n {
            let s = t.sensor("DATA_ID.SENSOR")?;
            let d: u64 = t.num("DATA_ID.ID")?;
            data.push((s, d));
        }
        t.end()?;
        if out
            .insert(
                id,
                Frame {
                    id,
                    rig_id,
                    rig_from_world,
                    data,
                },
            )
            .is_some()
        {
            return Err(duplicate(path, rec, "frame", id as u64));
        }
    }
    Ok(out)
}
