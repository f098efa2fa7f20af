//! Writing models in COLMAP's own encodings, so synthetic scenes and test cases are genuine
//! COLMAP models that COLMAP, pycolmap and our readers all accept.

use std::fmt::Write as _;
use std::io::Write;
use std::path::Path;

use crate::model::{Format, Reconstruction, SensorId, NO_POINT3D};
use crate::pose::Rigid3;

fn sensor_name(kind: i32) -> String {
    match kind {
        SensorId::CAMERA => "CAMERA".into(),
        SensorId::IMU => "IMU".into(),
        k => k.to_string(),
    }
}

fn pose_le(out: &mut Vec<u8>, p: &Rigid3) {
    for v in p.qvec().into_iter().chain(p.translation.to_array()) {
        out.extend_from_slice(&v.to_le_bytes());
    }
}

fn pose_txt(p: &Rigid3) -> String {
    let q = p.qvec();
    let t = p.translation;
    format!(
        "{} {} {} {} {} {} {}",
        q[0], q[1], q[2], q[3], t.x, t.y, t.z
    )
}

/// Write `cameras`, `images`, `points3D` (and `rigs`, `frames` when present) into `dir`.
///
/// Each file is written to a temporary name and renamed, so a reader never sees half a file.
pub fn write_model(rec: &Reconstruction, dir: &Path, format: Format) -> std::io::Result<()> {
    std::fs::create_dir_all(dir)?;
    let files: Vec<(&str, Vec<u8>)> = match format {
        Format::Binary => binary(rec),
        Format::Text => text(rec)
            .into_iter()
            .map(|(n, s)| (n, s.into_bytes()))
            .collect(),
    };
    for (name, bytes) in files {
        let path = dir.join(format!("{name}.{}", format.ext()));
        let tmp = dir.join(format!(".{name}.{}.tmp", format.ext()));
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(&bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, &path)?;
    }
    Ok(())
}

fn binary(rec: &Reconstruction) -> Vec<(&'static str, Vec<u8>)> {
    files(
        rec,
        [cameras_bin, images_bin, points_bin, rigs_bin, frames_bin],
    )
}

/// A model's files by stem, each made by its encoder: cameras, images and points3D, then
/// rigs and frames for a COLMAP 4 model.
fn files<T>(
    rec: &Reconstruction,
    encoders: [fn(&Reconstruction) -> T; 5],
) -> Vec<(&'static str, T)> {
    let count = if rec.is_colmap4() { 5 } else { 3 };
    ["cameras", "images", "points3D", "rigs", "frames"]
        .into_iter()
        .zip(encoders)
        .take(count)
        .map(|(stem, encode)| (stem, encode(rec)))
        .collect()
}

/// cameras.bin.
fn cameras_bin(rec: &Reconstruction) -> Vec<u8> {
    let mut cams = Vec::new();
    cams.extend_from_slice(&(rec.cameras.len() as u64).to_le_bytes());
    for c in rec.cameras.values() {
        cams.extend_from_slice(&c.id.to_le_bytes());
        cams.extend_from_slice(&c.model.id().to_le_bytes());
        cams.extend_from_slice(&c.width.to_le_bytes());
        cams.extend_from_slice(&c.height.to_le_bytes());
        for p in &c.params {
            cams.extend_from_slice(&p.to_le_bytes());
        }
    }
    cams
}

/// images.bin.
fn images_bin(rec: &Reconstruction) -> Vec<u8> {
    let mut imgs = Vec::new();
    imgs.extend_from_slice(&(rec.images.len() as u64).to_le_bytes());
    for i in rec.images.values() {
        imgs.extend_from_slice(&i.id.to_le_bytes());
        pose_le(&mut imgs, &i.cam_from_world);
        imgs.extend_from_slice(&i.camera_id.to_le_bytes());
        imgs.extend_from_slice(i.name.as_bytes());
        imgs.push(0);
        imgs.extend_from_slice(&(i.points2d.len() as u64).to_le_bytes());
        for p in &i.points2d {
            imgs.extend_from_slice(&p.xy.x.to_le_bytes());
            imgs.extend_from_slice(&p.xy.y.to_le_bytes());
            imgs.extend_from_slice(&p.point3d_id.to_le_bytes());
        }
    }
    imgs
}

/// points3D.bin.
fn points_bin(rec: &Reconstruction) -> Vec<u8> {
    let mut pts = Vec::new();
    pts.extend_from_slice(&(rec.points.len() as u64).to_le_bytes());
    for p in rec.points.values() {
        pts.extend_from_slice(&p.id.to_le_bytes());
        for v in p.xyz.to_array() {
            pts.extend_from_slice(&v.to_le_bytes());
        }
        pts.extend_from_slice(&p.rgb);
        pts.extend_from_slice(&p.error.to_le_bytes());
        pts.extend_from_slice(&(p.track.len() as u64).to_le_bytes());
        for el in &p.track {
            pts.extend_from_slice(&el.image_id.to_le_bytes());
            pts.extend_from_slice(&el.point2d_idx.to_le_bytes());
        }
    }
    pts
}

/// rigs.bin (COLMAP 4).
fn rigs_bin(rec: &Reconstruction) -> Vec<u8> {
    let mut rigs = Vec::new();
    rigs.extend_from_slice(&(rec.rigs.len() as u64).to_le_bytes());
    for r in rec.rigs.values() {
        rigs.extend_from_slice(&r.id.to_le_bytes());
        let n = r.ref_sensor.map_or(0, |_| 1 + r.sensors.len()) as u32;
        rigs.extend_from_slice(&n.to_le_bytes());
        if let Some(s) = r.ref_sensor {
            rigs.extend_from_slice(&s.kind.to_le_bytes());
            rigs.extend_from_slice(&s.id.to_le_bytes());
            for (s, pose) in &r.sensors {
                rigs.extend_from_slice(&s.kind.to_le_bytes());
                rigs.extend_from_slice(&s.id.to_le_bytes());
                rigs.push(pose.is_some() as u8);
                if let Some(p) = pose {
                    pose_le(&mut rigs, p);
                }
            }
        }
    }
    rigs
}

/// frames.bin (COLMAP 4).
fn frames_bin(rec: &Reconstruction) -> Vec<u8> {
    let mut frames = Vec::new();
    frames.extend_from_slice(&(rec.frames.len() as u64).to_le_bytes());
    for f in rec.frames.values() {
        frames.extend_from_slice(&f.id.to_le_bytes());
        frames.extend_from_slice(&f.rig_id.to_le_bytes());
        pose_le(&mut frames, &f.rig_from_world);
        frames.extend_from_slice(&(f.data.len() as u32).to_le_bytes());
        for (s, d) in &f.data {
            frames.extend_from_slice(&s.kind.to_le_bytes());
            frames.extend_from_slice(&s.id.to_le_bytes());
            frames.extend_from_slice(&d.to_le_bytes());
        }
    }
    frames
}

fn text(rec: &Reconstruction) -> Vec<(&'static str, String)> {
    files(
        rec,
        [cameras_txt, images_txt, points_txt, rigs_txt, frames_txt],
    )
}

/// cameras.txt.
fn cameras_txt(rec: &Reconstruction) -> String {
    let mut cams = String::from(
        "# Camera list with one line of data per camera:\n#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n",
    );
    let _ = writeln!(cams, "# Number of cameras: {}", rec.cameras.len());
    for c in rec.cameras.values() {
        let _ = write!(cams, "{} {} {} {}", c.id, c.model.name(), c.width, c.height);
        for p in &c.params {
            let _ = write!(cams, " {p}");
        }
        cams.push('\n');
    }
    cams
}

/// images.txt: a line of pose, camera and name, then a line of keypoints, per image.
fn images_txt(rec: &Reconstruction) -> String {
    let mut imgs = String::from(
        "# Image list with two lines of data per image:\n#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n#   POINTS2D[] as (X, Y, POINT3D_ID)\n",
    );
    let _ = writeln!(imgs, "# Number of images: {}", rec.images.len());
    for i in rec.images.values() {
        let _ = writeln!(
            imgs,
            "{} {} {} {}",
            i.id,
            pose_txt(&i.cam_from_world),
            i.camera_id,
            i.name
        );
        let mut first = true;
        for p in &i.points2d {
            if !first {
                imgs.push(' ');
            }
            first = false;
            let id: i64 = if p.point3d_id == NO_POINT3D {
                -1
            } else {
                p.point3d_id as i64
            };
            let _ = write!(imgs, "{} {} {id}", p.xy.x, p.xy.y);
        }
        imgs.push('\n');
    }
    imgs
}

/// points3D.txt.
fn points_txt(rec: &Reconstruction) -> String {
    let mut pts = String::from(
        "# 3D point list with one line of data per point:\n#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n",
    );
    let _ = writeln!(pts, "# Number of points: {}", rec.points.len());
    for p in rec.points.values() {
        let _ = write!(
            pts,
            "{} {} {} {} {} {} {} {}",
            p.id, p.xyz.x, p.xyz.y, p.xyz.z, p.rgb[0], p.rgb[1], p.rgb[2], p.error
        );
        for el in &p.track {
            let _ = write!(pts, " {} {}", el.image_id, el.point2d_idx);
        }
        pts.push('\n');
    }
    pts
}

/// rigs.txt (COLMAP 4).
fn rigs_txt(rec: &Reconstruction) -> String {
    let mut rigs = String::from("# Rig calib list with one line of data per calib:\n");
    for r in rec.rigs.values() {
        match r.ref_sensor {
            None => {
                let _ = writeln!(rigs, "{} 0", r.id);
            }
            Some(s) => {
                let _ = write!(
                    rigs,
                    "{} {} {} {}",
                    r.id,
                    1 + r.sensors.len(),
                    sensor_name(s.kind),
                    s.id
                );
                for (s, pose) in &r.sensors {
                    let _ = write!(rigs, " {} {}", sensor_name(s.kind), s.id);
                    match pose {
                        Some(p) => {
                            let _ = write!(rigs, " 1 {}", pose_txt(p));
                        }
                        None => rigs.push_str(" 0"),
                    }
                }
                rigs.push('\n');
            }
        }
    }
    rigs
}

/// frames.txt (COLMAP 4).
fn frames_txt(rec: &Reconstruction) -> String {
    let mut frames = String::from("# Frame list with one line of data per frame:\n");
    for f in rec.frames.values() {
        let _ = write!(
            frames,
            "{} {} {} {}",
            f.id,
            f.rig_id,
            pose_txt(&f.rig_from_world),
            f.data.len()
        );
        for (s, d) in &f.data {
            let _ = write!(frames, " {} {} {d}", sensor_name(s.kind), s.id);
        }
        frames.push('\n');
    }
    frames
}
