//! COLMAP's binary model files (little-endian), read with every count checked against the bytes left.

use std::collections::btree_map::Entry;
use std::collections::BTreeMap;
use std::path::Path;

use glam::{DVec2, DVec3};

use crate::camera::{Camera, CameraModel};
use crate::error::{ColmapError, Record, Result};
use crate::model::{Frame, Image, Point2D, Point3D, Rig, SensorId, TrackElement};
use crate::parse::{check_finite, make_pose, pose_flag, PoseCheck};
use crate::pose::Rigid3;

/// A bounds-checked little-endian cursor that names the file in its errors.
pub(crate) struct Bin<'a> {
    path: &'a Path,
    data: &'a [u8],
    pos: usize,
}

impl<'a> Bin<'a> {
    pub(crate) fn new(path: &'a Path, data: &'a [u8]) -> Self {
        Bin { path, data, pos: 0 }
    }

    fn remaining(&self) -> usize {
        self.data.len() - self.pos
    }

    fn take(&mut self, n: usize, rec: Record, field: &str) -> Result<&'a [u8]> {
        if self.remaining() < n {
            return Err(ColmapError::invalid(
                self.path,
                rec,
                field,
                format!(
                    "file is truncated: {n} bytes needed at byte offset {}, but the file ends at byte {}",
                    self.pos,
                    self.data.len()
                ),
            ));
        }
        let s = &self.data[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }

    fn arr<const N: usize>(&mut self, rec: Record, field: &str) -> Result<[u8; N]> {
        let s = self.take(N, rec, field)?;
        let mut a = [0u8; N];
        a.copy_from_slice(s);
        Ok(a)
    }

    fn u8(&mut self, rec: Record, field: &str) -> Result<u8> {
        Ok(self.arr::<1>(rec, field)?[0])
    }
    fn u32(&mut self, rec: Record, field: &str) -> Result<u32> {
        Ok(u32::from_le_bytes(self.arr(rec, field)?))
    }
    fn i32(&mut self, rec: Record, field: &str) -> Result<i32> {
        Ok(i32::from_le_bytes(self.arr(rec, field)?))
    }
    fn u64(&mut self, rec: Record, field: &str) -> Result<u64> {
        Ok(u64::from_le_bytes(self.arr(rec, field)?))
    }
    fn f64(&mut self, rec: Record, field: &str) -> Result<f64> {
        Ok(f64::from_le_bytes(self.arr(rec, field)?))
    }
    fn finite(&mut self, rec: Record, field: &str) -> Result<f64> {
        let v = self.f64(rec, field)?;
        check_finite(self.path, rec, field, v)
    }

    /// A record count, refused if even the smallest records could not fit in the bytes left.
    fn count(&mut self, rec: Record, field: &str, min_record_bytes: usize) -> Result<usize> {
        let n = self.u64(rec, field)?;
        let fits = (self.remaining() / min_record_bytes.max(1)) as u64;
        if n > fits {
            return Err(ColmapError::invalid(
                self.path,
                rec,
                field,
                format!(
                    "count {n} cannot be right (file truncated or corrupt): {} bytes remain, room for at most {fits} records of {min_record_bytes} bytes",
                    self.remaining()
                ),
            ));
        }
        Ok(n as usize)
    }

    fn cstr(&mut self, rec: Record, field: &str) -> Result<&'a str> {
        let rest = &self.data[self.pos..];
        let Some(end) = rest.iter().position(|&b| b == 0) else {
            return Err(ColmapError::invalid(
                self.path,
                rec,
                field,
                format!(
                    "file is truncated: no NUL terminator after byte offset {}",
                    self.pos
                ),
            ));
        };
        let s = std::str::from_utf8(&rest[..end])
            .map_err(|e| ColmapError::invalid(self.path, rec, field, format!("not UTF-8: {e}")))?;
        self.pos += end + 1;
        Ok(s)
    }

    fn pose(&mut self, rec: Record, field: &str) -> Result<([f64; 4], [f64; 3])> {
        let mut q = [0.0; 4];
        for (i, name) in ["qw", "qx", "qy", "qz"].iter().enumerate() {
            q[i] = self.finite(rec, &format!("{field}{name}"))?;
        }
        let mut t = [0.0; 3];
        for (i, name) in ["tx", "ty", "tz"].iter().enumerate() {
            t[i] = self.finite(rec, &format!("{field}{name}"))?;
        }
        Ok((q, t))
    }

    fn sensor(&mut self, rec: Record, field: &str) -> Result<SensorId> {
        let kind = self.i32(rec, &format!("{field}.type"))?;
        let id = self.u32(rec, &format!("{field}.id"))?;
        Ok(SensorId { kind, id })
    }

    fn finish(&self) -> Result<()> {
        if self.pos != self.data.len() {
            return Err(ColmapError::invalid(
                self.path,
                Record::File,
                "end of file",
                format!(
                    "{} unexpected bytes after the last record (byte offset {})",
                    self.data.len() - self.pos,
                    self.pos
                ),
            ));
        }
        Ok(())
    }
}

fn duplicate(path: &Path, rec: Record, what: &str, id: u64) -> ColmapError {
    ColmapError::invalid(path, rec, "id", format!("duplicate {what} id {id}"))
}

/// cameras.bin
pub(crate) fn read_cameras(path: &Path, data: &[u8]) -> Result<BTreeMap<u32, Camera>> {
    let mut b = Bin::new(path, data);
    let n = b.count(Record::File, "num_cameras", 24)?;
    let mut out = BTreeMap::new();
    for index in 0..n as u64 {
        let mut rec = Record::Nth {
            kind: "camera",
            index,
            id: None,
        };
        let id = b.u32(rec, "camera_id")?;
        rec = rec.with_id(id as u64);
        let model_id = b.i32(rec, "model_id")?;
        let model = CameraModel::from_id(model_id).ok_or_else(|| {
            ColmapError::invalid(
                path,
                rec,
                "model_id",
                format!("unknown camera model id {model_id} (known: 0-17, COLMAP 4.2's)"),
            )
        })?;
        let width = b.u64(rec, "width")?;
        let height = b.u64(rec, "height")?;
        let mut params = Vec::with_capacity(model.num_params());
        for name in model.param_names() {
            params.push(b.finite(rec, name)?);
        }
        let cam = Camera {
            id,
            model,
            width,
            height,
            params,
        };
        crate::parse::check_camera(path, rec, &cam)?;
        match out.entry(id) {
            Entry::Occupied(_) => return Err(duplicate(path, rec, "camera", id as u64)),
            Entry::Vacant(v) => {
                v.insert(cam);
            }
        }
    }
    b.finish()?;
    Ok(out)
}

/// images.bin
pub(crate) fn read_images(
    path: &Path,
    data: &[u8],
    checks: &mut PoseCheck,
) -> Result<BTreeMap<u32, Image>> {
    let mut b = Bin::new(path, data);
    let n = b.count(Record::File, "num_reg_images", 4 + 56 + 4 + 1 + 8)?;
    let mut out = BTreeMap::new();
    for index in 0..n as u64 {
        let mut rec = Record::Nth {
            kind: "image",
            index,
            id: None,
        };
        let id = b.u32(rec, "image_id")?;
        rec = rec.with_id(id as u64);
        let (q, t) = b.pose(rec, "")?;
        let (cam_from_world, stored_quat_norm) = make_pose(path, rec, "q", q, t, checks)?;
        let camera_id = b.u32(rec, "camera_id")?;
        let name = b.cstr(rec, "name")?.to_owned();
        let np = b.count(rec, "num_points2D", 24)?;
        let mut points2d = Vec::with_capacity(np);
        for k in 0..np {
            let x = b.f64(rec, "points2D.x")?;
            let y = b.f64(rec, "points2D.y")?;
            let point3d_id = b.u64(rec, "points2D.point3D_id")?;
            if !(x.is_finite() && y.is_finite()) {
                return Err(ColmapError::invalid(
                    path,
                    rec,
                    format!("points2D[{k}].xy"),
                    format!("not finite: ({x}, {y})"),
                ));
            }
            points2d.push(Point2D {
                xy: DVec2::new(x, y),
                point3d_id,
            });
        }
        let img = Image {
            id,
            name,
            camera_id,
            cam_from_world,
            stored_quat_norm,
            points2d,
        };
        crate::names::check_model_name(path, rec, "name", &img.name)?;
        match out.entry(id) {
            Entry::Occupied(_) => return Err(duplicate(path, rec, "image", id as u64)),
            Entry::Vacant(v) => {
                v.insert(img);
            }
        }
    }
    b.finish()?;
    Ok(out)
}

/// points3D.bin
pub(crate) fn read_points(path: &Path, data: &[u8]) -> Result<BTreeMap<u64, Point3D>> {
    let mut b = Bin::new(path, data);
    let n = b.count(Record::File, "num_points3D", 8 + 24 + 3 + 8 + 8)?;
    let mut out = BTreeMap::new();
    for index in 0..n as u64 {
        let mut rec = Record::Nth {
            kind: "point3D",
            index,
            id: None,
        };
        let id = b.u64(rec, "point3D_id")?;
        rec = rec.with_id(id);
        let x = b.finite(rec, "x")?;
        let y = b.finite(rec, "y")?;
        let z = b.finite(rec, "z")?;
        let rgb = [b.u8(rec, "r")?, b.u8(rec, "g")?, b.u8(rec, "b")?];
        let error = b.f64(rec, "error")?;
        if error.is_nan() {
            return Err(ColmapError::invalid(path, rec, "error", "is NaN"));
        }
        let nt = b.count(rec, "track_length", 8)?;
        let mut track = Vec::with_capacity(nt);
        for _ in 0..nt {
            let image_id = b.u32(rec, "track.image_id")?;
            let point2d_idx = b.u32(rec, "track.point2D_idx")?;
            track.push(TrackElement {
                image_id,
                point2d_idx,
            });
        }
        let p = Point3D {
            id,
            xyz: DVec3::new(x, y, z),
            rgb,
            error,
            track,
        };
        match out.entry(id) {
            Entry::Occupied(_) => return Err(duplicate(path, rec, "point3D", id)),
            Entry::Vacant(v) => {
                v.insert(p);
            }
        }
    }
    b.finish()?;
    Ok(out)
}

/// rigs.bin (COLMAP 4)
pub(crate) fn read_rigs(
    path: &Path,
    data: &[u8],
    checks: &mut PoseCheck,
) -> Result<BTreeMap<u32, Rig>> {
    let mut b = Bin::new(path, data);
    let n = b.count(Record::File, "num_rigs", 8)?;
    let mut out = BTreeMap::new();
    for index in 0..n as u64 {
        let mut rec = Record::Nth {
            kind: "rig",
            index,
            id: None,
        };
        let id = b.u32(rec, "rig_id")?;
        rec = rec.with_id(id as u64);
        let num_sensors = b.u32(rec, "num_sensors")? as usize;
        let mut ref_sensor = None;
        let mut sensors = Vec::new();
        if num_sensors > 0 {
            ref_sensor = Some(b.sensor(rec, "ref_sensor")?);
            // Each further sensor takes at least 9 bytes; refuse counts the file cannot hold.
            if (num_sensors - 1) > b.remaining() / 9 {
                return Err(ColmapError::invalid(
                    path,
                    rec,
                    "num_sensors",
                    format!(
                        "count {num_sensors} cannot fit in the {} bytes left",
                        b.remaining()
                    ),
                ));
            }
            for _ in 1..num_sensors {
                let s = b.sensor(rec, "sensor")?;
                let has_pose = b.u8(rec, "sensor.has_pose")?;
                let pose = if pose_flag(path, rec, "sensor.has_pose", has_pose)? {
                    let (q, t) = b.pose(rec, "sensor_from_rig.")?;
                    Some(make_pose(path, rec, "sensor_from_rig.q", q, t, checks)?.0)
                } else {
                    None
                };
                sensors.push((s, pose));
            }
        }
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
    b.finish()?;
    Ok(out)
}

/// frames.bin (COLMAP 4)
pub(crate) fn read_frames(
    path: &Path,
    data: &[u8],
    checks: &mut PoseCheck,
) -> Result<BTreeMap<u32, Frame>> {
    let mut b = Bin::new(path, data);
    let n = b.count(Record::File, "num_frames", 4 + 4 + 56 + 4)?;
    let mut out = BTreeMap::new();
    for index in 0..n as u64 {
        let mut rec = Record::Nth {
            kind: "frame",
            index,
            id: None,
        };
        let id = b.u32(rec, "frame_id")?;
        rec = rec.with_id(id as u64);
        let rig_id = b.u32(rec, "rig_id")?;
        let (q, t) = b.pose(rec, "rig_from_world.")?;
        let rig_from_world: Rigid3 = make_pose(path, rec, "rig_from_world.q", q, t, checks)?.0;
        let nd = b.u32(rec, "num_data_ids")? as usize;
        if nd > b.remaining() / 16 {
            return Err(ColmapError::invalid(
                path,
                rec,
                "num_data_ids",
                format!("count {nd} cannot fit in the {} bytes left", b.remaining()),
            ));
        }
        let mut frame_data = Vec::with_capacity(nd);
        for _ in 0..nd {
            let s = b.sensor(rec, "data_id.sensor")?;
            let d = b.u64(rec, "data_id.id")?;
            frame_data.push((s, d));
        }
        if out
            .insert(
                id,
                Frame {
                    id,
                    rig_id,
                    rig_from_world,
                    data: frame_data,
                },
            )
            .is_some()
        {
            return Err(duplicate(path, rec, "frame", id as u64));
        }
    }
    b.finish()?;
    Ok(out)
}
