//! Checks shared by the binary and text readers, so both encodings reject the same things.

use std::path::Path;

use crate::camera::Camera;
use crate::error::{ColmapError, Record, Result};
use crate::model::Warning;
use crate::pose::{Rigid3, QUAT_NORM_TOLERANCE};

/// Warnings collected while poses are read (renormalised quaternions).
#[derive(Debug, Default)]
pub(crate) struct PoseCheck {
    pub warnings: Vec<Warning>,
}

pub(crate) fn check_finite(path: &Path, rec: Record, field: &str, v: f64) -> Result<f64> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(ColmapError::invalid(
            path,
            rec,
            field,
            format!("not a finite number: {v}"),
        ))
    }
}

/// A pose from stored numbers: normalises the quaternion, warns when it was off, refuses a zero one.
pub(crate) fn make_pose(
    path: &Path,
    rec: Record,
    field: &str,
    q: [f64; 4],
    t: [f64; 3],
    checks: &mut PoseCheck,
) -> Result<(Rigid3, f64)> {
    let Some((pose, norm)) = Rigid3::from_colmap(q, t) else {
        return Err(ColmapError::invalid(
            path,
            rec,
            field,
            format!(
                "quaternion ({}, {}, {}, {}) has zero norm: no rotation",
                q[0], q[1], q[2], q[3]
            ),
        ));
    };
    if (norm - 1.0).abs() > QUAT_NORM_TOLERANCE {
        checks.warnings.push(Warning {
            path: path.to_path_buf(),
            record: rec.to_string(),
            field: field.to_string(),
            message: format!("quaternion norm was {norm:.9}; normalised to 1"),
        });
    }
    Ok((pose, norm))
}

/// Reject cameras no projection can use: zero size, non-positive or non-finite focal length.
pub(crate) fn check_camera(path: &Path, rec: Record, cam: &Camera) -> Result<()> {
    if cam.width == 0 || cam.height == 0 {
        return Err(ColmapError::invalid(
            path,
            rec,
            if cam.width == 0 { "width" } else { "height" },
            format!("image size {}x{} is empty", cam.width, cam.height),
        ));
    }
    let names = cam.model.param_names();
    let nf = if cam.model.single_focal() { 1 } else { 2 };
    for (i, name) in names.iter().enumerate().take(nf) {
        let f = cam.params[i];
        if !(f > 0.0 && f.is_finite()) {
            return Err(ColmapError::invalid(
                path,
                rec,
                *name,
                format!("focal length must be positive and finite, found {f}"),
            ));
        }
    }
    for (name, v) in names.iter().zip(&cam.params) {
        check_finite(path, rec, name, *v)?;
    }
    Ok(())
}

/// COLMAP's has-pose flag of a rig sensor: 0 or 1, nothing else.
pub(crate) fn pose_flag(path: &Path, rec: Record, field: &str, v: u8) -> Result<bool> {
    match v {
        0 => Ok(false),
        1 => Ok(true),
        v => Err(ColmapError::invalid(
            path,
            rec,
            field,
            format!("must be 0 or 1, found {v}"),
        )),
    }
}
