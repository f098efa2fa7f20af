//! nerfstudio's `transforms.json` layout, as its `colmap_to_json` writes it and its
//! `nerfstudio-data` parser reads it (also read by gsplat's and other splatting trainers):
//!
//! ```text
//! OUT/transforms.json
//! OUT/images/<name>.png      each view's photo as stored in the dataset
//! OUT/depth/<name>.npy       float32 (h, w): camera-space z × 1000, 0 = empty
//! OUT/masks/<name>.png       with semantics: 255 = use the pixel, 0 = transient object
//! OUT/sparse_pc.ply          the scene's 3D points, in nerfstudio's world frame
//! ```
//!
//! Each frame carries its own camera (`w`, `h`, `fl_x`, `fl_y`, `cx`, `cy`, distortion and
//! `camera_model`), mapped from COLMAP's models exactly as nerfstudio's
//! `parse_colmap_camera_params` maps them; models nerfstudio cannot represent exactly (FOV,
//! FULL_OPENCV, the thin-prism fisheyes) are refused by name. Poses are camera-to-world in
//! nerfstudio's OpenGL convention (x right, y up, z back) with `colmap_to_json`'s world
//! rotation (`applied_transform`, z up). The split goes into `train_filenames`,
//! `val_filenames` and `test_filenames` (= val).

use nrw_dataset::split::{TRAIN, VAL};
use std::path::Path;

use glam::{DMat3, DVec3};
use nrw_colmap::{CameraModel, PointCloud, Rigid3};
use serde_json::{json, Map, Value};

use nrw_dataset::ViewRow;

use crate::error::{ExportError, Result};
use crate::inputs::ScenePoint;
use crate::staging::Staged;
use crate::writer::{About, Job, WithPoints};
use crate::SplitExport;

/// nerfstudio's `applied_transform` (rows of a 3 × 4 matrix): world (x, y, z) → (x, z, −y).
pub const APPLIED_TRANSFORM: [[f64; 4]; 3] = [
    [1.0, 0.0, 0.0, 0.0],
    [0.0, 0.0, 1.0, 0.0],
    [0.0, -1.0, 0.0, 0.0],
];

/// Depth is stored × this: nerfstudio multiplies depth files by `depth_unit_scale_factor`
/// (1e-3 by default), which then gives back the scene's units.
pub const DEPTH_SCALE: f32 = 1000.0;

/// The per-frame camera keys nerfstudio reads for a view's camera, or a refusal naming it.
pub fn camera_keys(v: &ViewRow) -> Result<Map<String, Value>> {
    let p = &v.params;
    let model = CameraModel::from_name(&v.model);
    let refused = |why: &str| ExportError::Value {
        path: v.name.clone().into(),
        record: format!("image {}", v.image_id),
        field: "model".into(),
        problem: format!(
            "camera model {} {why}; nerfstudio represents SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, \
             RADIAL, OPENCV (as its OPENCV) and OPENCV_FISHEYE, SIMPLE_RADIAL_FISHEYE, \
             RADIAL_FISHEYE, SIMPLE_FISHEYE, FISHEYE (as its OPENCV_FISHEYE) exactly; ingest \
             with --undistort to store PINHOLE cameras",
            v.model
        ),
    };
    let n = model.map_or(0, |m| m.num_params());
    if model.is_none() || p.len() != n {
        return Err(refused("is unknown or has the wrong number of parameters"));
    }
    // (fl_x, fl_y, cx, cy, [k1, k2, p1, p2] or [k1, k2, k3, k4], nerfstudio's model).
    let (f, rest, fisheye): ([f64; 4], [f64; 4], bool) = match model.expect("checked") {
        CameraModel::SimplePinhole => ([p[0], p[0], p[1], p[2]], [0.0; 4], false),
        CameraModel::Pinhole => ([p[0], p[1], p[2], p[3]], [0.0; 4], false),
        CameraModel::SimpleRadial => ([p[0], p[0], p[1], p[2]], [p[3], 0.0, 0.0, 0.0], false),
        CameraModel::Radial => ([p[0], p[0], p[1], p[2]], [p[3], p[4], 0.0, 0.0], false),
        CameraModel::OpenCv => ([p[0], p[1], p[2], p[3]], [p[4], p[5], p[6], p[7]], false),
        CameraModel::OpenCvFisheye => ([p[0], p[1], p[2], p[3]], [p[4], p[5], p[6], p[7]], true),
        CameraModel::SimpleRadialFisheye => ([p[0], p[0], p[1], p[2]], [p[3], 0.0, 0.0, 0.0], true),
        CameraModel::RadialFisheye => ([p[0], p[0], p[1], p[2]], [p[3], p[4], 0.0, 0.0], true),
        CameraModel::SimpleFisheye => ([p[0], p[0], p[1], p[2]], [0.0; 4], true),
        CameraModel::Fisheye => ([p[0], p[1], p[2], p[3]], [0.0; 4], true),
        CameraModel::Fov => {
            return Err(refused(
                "(atan-based distortion) has no exact nerfstudio equivalent",
            ))
        }
        CameraModel::SimpleDivision | CameraModel::Division => {
            return Err(refused(
                "(Fitzgibbon's division model) has no exact nerfstudio equivalent",
            ))
        }
        CameraModel::Eucm => {
            return Err(refused(
                "(the enhanced unified camera model) has no exact nerfstudio equivalent",
            ))
        }
        CameraModel::Equirectangular => {
            return Err(refused("(a 360° panorama) is not a view a dataset holds"))
        }
        CameraModel::FullOpenCv => {
            return Err(refused(
                "(rational radial distortion, k4–k6 in the denominator) has no exact nerfstudio \
                 equivalent: nerfstudio's own converter refuses it too",
            ))
        }
        CameraModel::ThinPrismFisheye | CameraModel::RadTanThinPrismFisheye => {
            return Err(refused(
                "(thin-prism terms) has no exact nerfstudio equivalent",
            ))
        }
    };
    Ok(opencv_keys(v, f, rest, fisheye))
}

/// nerfstudio's keys of an OPENCV (or, `fisheye`, OPENCV_FISHEYE) camera: size, focal
/// lengths and principal point `f`, and the four distortion coefficients `rest`.
fn opencv_keys(v: &ViewRow, f: [f64; 4], rest: [f64; 4], fisheye: bool) -> Map<String, Value> {
    let mut m = Map::new();
    m.insert("w".into(), v.width.into());
    m.insert("h".into(), v.height.into());
    for (k, x) in ["fl_x", "fl_y", "cx", "cy"].iter().zip(f) {
        m.insert((*k).into(), x.into());
    }
    let names = if fisheye {
        ["k1", "k2", "k3", "k4"]
    } else {
        ["k1", "k2", "p1", "p2"]
    };
    for (k, x) in names.iter().zip(rest) {
        m.insert((*k).into(), x.into());
    }
    m.insert(
        "camera_model".into(),
        if fisheye { "OPENCV_FISHEYE" } else { "OPENCV" }.into(),
    );
    m
}

/// The frame's `transform_matrix`: camera-to-world, OpenGL axes, nerfstudio's world frame.
pub fn transform_matrix(qvec: [f64; 4], tvec: [f64; 3]) -> Option<[[f64; 4]; 4]> {
    let (w2c, _) = Rigid3::from_colmap(qvec, tvec)?;
    let r: DMat3 = w2c.matrix();
    let rt = r.transpose();
    let centre: DVec3 = -(rt * w2c.translation);
    // c2w = [Rᵀ | C] with the camera's y and z axes flipped (OpenCV → OpenGL) …
    let mut c2w = [[0.0; 4]; 3];
    for (row, out) in c2w.iter_mut().enumerate() {
        let axis = |col: usize| rt.col(col)[row];
        *out = [axis(0), -axis(1), -axis(2), centre[row]];
    }
    // … then the world rotated as colmap_to_json does: rows (0, 2, 1), the new row 2 negated.
    Some([c2w[0], c2w[2], c2w[1].map(|x| -x), [0.0, 0.0, 0.0, 1.0]])
}

/// The file name stem a view gets (its name without extension, subfolders kept).
fn stem(name: &str) -> String {
    Path::new(name)
        .with_extension("")
        .to_string_lossy()
        .replace('\\', "/")
}

/// One view's files and frame.
fn frame(job: &Job, v: &ViewRow, staged: &Staged) -> Result<(String, Value)> {
    let s = stem(&v.name);
    let image = format!("images/{s}.png");
    staged.write(&image, &v.photo_png)?;
    let depth = job.prior_depth(v)?;
    let scaled: Vec<f32> = depth.data.iter().map(|z| z * DEPTH_SCALE).collect();
    let depth_file = format!("depth/{s}.npy");
    staged.write(
        &depth_file,
        &crate::npz::Array::f32(&[v.height as usize, v.width as usize], &scaled).npy(),
    )?;
    let pose = transform_matrix(v.qvec, v.tvec).ok_or_else(|| ExportError::Value {
        path: v.name.clone().into(),
        record: format!("image {}", v.image_id),
        field: "qvec".into(),
        problem: format!("{:?} is not a rotation", v.qvec),
    })?;
    let mut f = camera_keys(v)?;
    f.insert("file_path".into(), image.clone().into());
    f.insert("transform_matrix".into(), json!(pose));
    f.insert("colmap_im_id".into(), v.image_id.into());
    f.insert("depth_file_path".into(), depth_file.into());
    if let Some(t) = v.transient()? {
        let mask: Vec<u8> = t.as_raw().iter().map(|m| 255 - m).collect();
        let mask_file = format!("masks/{s}.png");
        let png = nrw_dataset::codec::encode_gray(&v.name, v.width, v.height, &mask)?;
        staged.write(&mask_file, &png)?;
        f.insert("mask_path".into(), mask_file.into());
    }
    Ok((image, Value::Object(f)))
}

/// The `nerfstudio` layout, as the CLI, pipeline files and `export.json` name it.
pub const ABOUT: About = About {
    name: "nerfstudio",
    summary: "nerfstudio's transforms.json (each frame's exact camera model, OpenGL camera-to-world poses with nerfstudio's applied_transform, depth/*.npy, masks/*.png from the transient mask, train/val/test_filenames) with images/ and sparse_pc.ply; refuses camera models nerfstudio cannot represent exactly (FOV, FULL_OPENCV, thin-prism fisheyes)",
    needs_points: true,
    writes_depth_priors: true,
    default_crop: None,
};

/// nerfstudio's layout.
pub static NERFSTUDIO: WithPoints = WithPoints(write);

/// Write the layout into `staged`. Returns the splits written.
fn write(
    job: &Job,
    points: &[ScenePoint],
    staged: &Staged,
) -> Result<(Vec<SplitExport>, Vec<String>)> {
    let (ds, cfg, tick) = (job.ds, job.cfg, job.tick);
    let mut frames = Vec::new();
    let mut lists: Map<String, Value> = Map::new();
    let mut out = Vec::new();
    let mut seen = std::collections::BTreeSet::new();
    let mut distorted = Vec::new();
    for (split, n) in &job.splits {
        if *n == 0 {
            continue;
        }
        let mut s = SplitExport::new(split);
        let mut files = Vec::new();
        for &id in ds.ids(split)? {
            let v = ds.get(id)?;
            let (image, f) = frame(job, &v, staged)?;
            if !seen.insert(image.clone()) {
                return Err(ExportError::refused(
                    &cfg.out,
                    format!("two views would both be written as {image}"),
                ));
            }
            if ["k1", "k2", "k3", "k4", "p1", "p2"]
                .iter()
                .any(|k| f[*k].as_f64().is_some_and(|x| x != 0.0))
            {
                distorted.push(v.name.clone());
            }
            files.push(Value::from(image.clone()));
            frames.push(f);
            s.image_ids.push(id);
            s.names.push(v.name.clone());
            s.files.push(image);
            tick();
        }
        let key = match split.as_str() {
            TRAIN => "train_filenames",
            VAL => "val_filenames",
            other => {
                return Err(ExportError::refused(
                    &cfg.out,
                    format!("split `{other}`: nerfstudio knows train, val and test"),
                ))
            }
        };
        lists.insert(key.into(), Value::Array(files));
        out.push(s);
    }
    // nerfstudio asks for every split's list once any is given; test = val here.
    let val = lists
        .entry("val_filenames")
        .or_insert_with(|| json!([]))
        .clone();
    lists.insert("test_filenames".into(), val);
    let ply = "sparse_pc.ply";
    write_points(points, &staged.claim(ply)?)?;
    let mut top = Map::new();
    top.insert("frames".into(), Value::Array(frames));
    top.insert("applied_transform".into(), json!(APPLIED_TRANSFORM));
    top.insert("ply_file_path".into(), ply.into());
    top.extend(lists);
    staged.write(
        "transforms.json",
        &serde_json::to_vec_pretty(&Value::Object(top)).expect("json"),
    )?;
    Ok((out, pinhole_only_warning(&distorted).into_iter().collect()))
}

/// Splatfacto-W and other loaders that take only undistorted cameras read the distortion
/// terms as absent: name the views that carry some.
fn pinhole_only_warning(distorted: &[String]) -> Option<String> {
    let first = distorted.first()?;
    Some(format!(
        "Splatfacto-W (and other PINHOLE-only loaders) assert undistorted cameras: {} frame(s) \
         carry distortion terms (first {first}); ingest with --undistort for them",
        distorted.len()
    ))
}

/// The scene's points in nerfstudio's world frame, as `colmap_to_json`'s `sparse_pc.ply`.
fn write_points(points: &[ScenePoint], path: &Path) -> Result<()> {
    let a = APPLIED_TRANSFORM;
    let positions = points
        .iter()
        .map(|p| {
            let x = p.xyz;
            DVec3::from(std::array::from_fn(|r| {
                a[r][0] * x[0] + a[r][1] * x[1] + a[r][2] * x[2] + a[r][3]
            }))
        })
        .collect();
    // Normals turn with the world: the rotation part of the applied transform.
    let normals = points
        .iter()
        .map(|p| {
            p.normal.map(|n| {
                std::array::from_fn(|r| {
                    a[r][0] as f32 * n[0] + a[r][1] as f32 * n[1] + a[r][2] as f32 * n[2]
                })
            })
        })
        .collect();
    let cloud = PointCloud {
        path: path.to_path_buf(),
        positions,
        colors: Some(points.iter().map(|p| p.rgb).collect()),
        normals,
    };
    nrw_colmap::write_ply(&cloud, path).map_err(|e| ExportError::io(path, e))
}
