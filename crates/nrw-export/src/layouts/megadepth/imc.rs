//! The Image Matching Challenge 2022 training layout (Kaggle), which pose-evaluation and
//! matcher-training scripts read, written beside MegaDepth's from the same views and tracks:
//!
//! ```text
//! OUT/imc2022/train/NAME/images/ID.jpg            the photos (ID = the file's stem)
//! OUT/imc2022/train/NAME/calibration.csv          image_id, camera_intrinsics (K, row-major),
//!                                                 rotation_matrix (R, row-major),
//!                                                 translation_vector (T): x_cam = R X + T
//! OUT/imc2022/train/NAME/pair_covisibility.csv    pair ("ID1-ID2", ID1 > ID2), covisibility,
//!                                                 fundamental_matrix (row-major)
//! OUT/imc2022/train/scaling_factors.csv           scene, scaling_factor (metres a model unit)
//! ```
//!
//! Matrices are space-separated numbers in the shortest form that reads back to the same f64.
//! The fundamental matrix is the organisers' `ComputeFundamentalMatrix(K1, K2, R1, R2, T1, T2)`
//! of their evaluation code, image 1 being the pair's first id, so `x2ᵀ F x1 = 0`.
//!
//! Covisibility follows the description IMC 2022 points to (Jin et al., "Image Matching across
//! Wide Baselines", IJCV 2021, Sec. 3.2 and Fig. 5), as we read it: the SfM points the two
//! photos share, their bounding box in each photo as a share of that photo's area, the smaller
//! of the two. The organisers' own script is not published, so the number is ours; every pair
//! that shares a point is listed (the organisers recommend pairs at 0.1 or above).
//!
//! `scaling_factors.csv` needs the scene's metric scale, which SfM does not know: it is
//! written only when the export is given one (`--metres-per-unit`), and a warning says so
//! otherwise.

use crate::error::{ExportError, Result};
use crate::staging::Staged;

/// What IMC 2022's files need that a model does not hold.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ImcOptions {
    /// Metres a model unit, when known: `scaling_factors.csv` (left out without it).
    pub metres_per_unit: Option<f64>,
}

/// A 3 × 3 matrix as rows.
pub type Mat3 = [[f64; 3]; 3];

/// One view as the IMC files name, size and calibrate it.
pub struct ImcView<'a> {
    /// The image id: the photo's file stem.
    pub id: &'a str,
    /// The export-relative path of the view's JPEG, copied into `images/`.
    pub jpg: &'a str,
    /// The stored view's size, the unit of its covisibility.
    pub width: u64,
    pub height: u64,
    /// PINHOLE K, world-to-camera R and T (`x_cam = R X + T`).
    pub k: Mat3,
    pub r: Mat3,
    pub t: [f64; 3],
}

/// Two views (indices into the views) that share SfM points, with the area of the shared
/// points' bounding box in each, in square pixels.
pub struct Shared {
    pub i: usize,
    pub j: usize,
    pub areas: [f64; 2],
}

/// View i's pairs with later views that share points, computed by the caller (which holds
/// the tracks), a view at a time so the pair list is never held whole.
pub type PairsOf<'a> = &'a dyn Fn(usize) -> Vec<Shared>;

/// The folder of every IMC scene of the export.
const ROOT: &str = "imc2022/train";

/// Write a scene's IMC 2022 files; the warnings of what was not written and why.
pub fn write(
    name: &str,
    views: &[ImcView],
    pairs_of: PairsOf,
    metres_per_unit: Option<f64>,
    staged: &Staged,
) -> Result<Vec<String>> {
    if let Some(bad) = views.iter().find(|v| !usable_id(v.id)) {
        return Ok(vec![format!(
            "IMC 2022's scripts split pair keys on '-' and rows on ',': image id {:?} holds one \
             of - , \" so imc2022/ was not written (rename the photos to write it)",
            bad.id
        )]);
    }
    let dir = format!("{ROOT}/{name}");
    for v in views {
        let from = staged.dir().join(v.jpg);
        let to = staged.claim(&format!("{dir}/images/{}.jpg", v.id))?;
        if let Some(d) = to.parent() {
            std::fs::create_dir_all(d).map_err(|e| ExportError::io(d, e))?;
        }
        std::fs::copy(&from, &to).map_err(|e| ExportError::io(&to, e))?;
    }
    staged.write(
        &format!("{dir}/calibration.csv"),
        calibration_csv(views).as_bytes(),
    )?;
    let rel = format!("{dir}/pair_covisibility.csv");
    let path = staged.dir().join(&rel);
    staged.write_with(&rel, &mut |w| {
        write_pairs(views, pairs_of, w).map_err(|e| ExportError::io(&path, e))
    })?;
    Ok(match metres_per_unit {
        Some(s) => {
            let csv = format!("scene,scaling_factor\n{name},{}\n", num(s));
            staged.write(&format!("{ROOT}/scaling_factors.csv"), csv.as_bytes())?;
            Vec::new()
        }
        None => vec![format!(
            "IMC 2022's scaling_factors.csv was not written: the model's metric scale is unknown \
             (give --metres-per-unit, e.g. a known length in metres over its length in the model); \
             its evaluation multiplies translations by it"
        )],
    })
}

/// Whether IMC's scripts read an image id back whole: no pair separator, no CSV syntax.
fn usable_id(id: &str) -> bool {
    !id.is_empty() && !id.contains(['-', ',', '"', '\n', '\r'])
}

/// A number in the shortest form that reads back to the same f64.
fn num(x: f64) -> String {
    format!("{x:?}")
}

/// Numbers space-separated, as IMC's readers `split(' ')` them.
fn nums<const N: usize>(xs: [f64; N]) -> String {
    xs.map(num).join(" ")
}

/// `calibration.csv`: one row a view, in scene_info's order.
fn calibration_csv(views: &[ImcView]) -> String {
    let mut out = String::from("image_id,camera_intrinsics,rotation_matrix,translation_vector\n");
    for v in views {
        let (k, r) = (flat(v.k), flat(v.r));
        out += &format!("{},{},{},{}\n", v.id, nums(k), nums(r), nums(v.t));
    }
    out
}

/// A 3 × 3 matrix's rows, one after the other.
fn flat(m: [[f64; 3]; 3]) -> [f64; 9] {
    let mut out = [0.0; 9];
    for (row, dst) in m.iter().zip(out.chunks_mut(3)) {
        dst.copy_from_slice(row);
    }
    out
}

/// A view's K, R and T, as `fundamental` takes them.
fn krt(v: &ImcView) -> (Mat3, Mat3, [f64; 3]) {
    (v.k, v.r, v.t)
}

/// `pair_covisibility.csv`, a view's pairs at a time.
pub fn write_pairs(
    views: &[ImcView],
    pairs_of: PairsOf,
    w: &mut dyn std::io::Write,
) -> std::io::Result<()> {
    w.write_all(b"pair,covisibility,fundamental_matrix\n")?;
    let share = |k: usize, area: f64| area / (views[k].width as f64 * views[k].height as f64);
    for i in 0..views.len() {
        for p in pairs_of(i) {
            let covisibility = share(p.i, p.areas[0]).min(share(p.j, p.areas[1]));
            let (a, b) = if views[p.i].id > views[p.j].id {
                (p.i, p.j)
            } else {
                (p.j, p.i)
            };
            let f: [f64; 9] = flat(fundamental(krt(&views[a]), krt(&views[b])));
            writeln!(
                w,
                "{}-{},{},{}",
                views[a].id,
                views[b].id,
                num(covisibility),
                nums(f)
            )?;
        }
    }
    Ok(())
}

/// The organisers' `ComputeFundamentalMatrix(K1, K2, R1, R2, T1, T2)`, step for step:
/// dR = R2 R1ᵀ, dT = T2 − dR T1, A = K1 dRᵀ dT, F = K2⁻ᵀ (dR (K1ᵀ [A]×)).
fn fundamental((k1, r1, t1): (Mat3, Mat3, [f64; 3]), (k2, r2, t2): (Mat3, Mat3, [f64; 3])) -> Mat3 {
    let dr = mul(r2, transpose(r1));
    let dr_t1 = apply(dr, t1);
    let dt = [0, 1, 2].map(|k| t2[k] - dr_t1[k]);
    let a = apply(k1, apply(transpose(dr), dt));
    let c = [[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]];
    mul(
        transpose(pinhole_inverse(k2)),
        mul(dr, mul(transpose(k1), c)),
    )
}

/// The inverse of a pinhole K (upper triangular, no skew), in closed form.
fn pinhole_inverse(k: Mat3) -> Mat3 {
    let (fx, fy, cx, cy) = (k[0][0], k[1][1], k[0][2], k[1][2]);
    [
        [1.0 / fx, 0.0, -cx / fx],
        [0.0, 1.0 / fy, -cy / fy],
        [0.0, 0.0, 1.0],
    ]
}

fn transpose(m: Mat3) -> Mat3 {
    [0, 1, 2].map(|r| [0, 1, 2].map(|c| m[c][r]))
}

fn mul(a: Mat3, b: Mat3) -> Mat3 {
    [0, 1, 2].map(|r| [0, 1, 2].map(|c| (0..3).map(|k| a[r][k] * b[k][c]).sum()))
}

fn apply(m: Mat3, v: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|r| (0..3).map(|k| m[r][k] * v[k]).sum())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A camera looking down +z from `centre`, turned by `yaw` about y.
    fn camera(yaw: f64, centre: [f64; 3]) -> (Mat3, Mat3, [f64; 3]) {
        let k = [[500.0, 0.0, 320.0], [0.0, 510.0, 240.0], [0.0, 0.0, 1.0]];
        let (s, c) = yaw.sin_cos();
        let r = [[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]];
        let rc = apply(r, centre);
        (k, r, [-rc[0], -rc[1], -rc[2]])
    }

    fn project((k, r, t): (Mat3, Mat3, [f64; 3]), x: [f64; 3]) -> [f64; 3] {
        let c = apply(r, x);
        let c = [c[0] + t[0], c[1] + t[1], c[2] + t[2]];
        let p = apply(k, c);
        [p[0] / p[2], p[1] / p[2], 1.0]
    }

    #[test]
    fn the_fundamental_matrix_maps_image_1_points_to_image_2_epipolar_lines() {
        let one = camera(0.1, [0.0, 0.0, -5.0]);
        let two = camera(-0.3, [2.0, 0.5, -4.0]);
        let f = fundamental(one, two);
        let scale = f.iter().flatten().fold(0f64, |m, x| m.max(x.abs()));
        for x in [[0.0, 0.0, 3.0], [1.0, -0.5, 2.0], [-1.5, 0.7, 4.0]] {
            let (x1, x2) = (project(one, x), project(two, x));
            let residual: f64 = (0..3).map(|r| x2[r] * apply(f, x1)[r]).sum();
            assert!(residual.abs() < 1e-9 * scale, "x2ᵀ F x1 = {residual}");
            let swapped: f64 = (0..3).map(|r| x1[r] * apply(f, x2)[r]).sum();
            assert!(
                swapped.abs() > 1e-6 * scale,
                "F is not symmetric in its images"
            );
        }
    }

    #[test]
    fn ids_with_a_pair_separator_or_csv_syntax_are_not_usable() {
        assert!(usable_id("82983855_2939779395"));
        for bad in ["a-b", "a,b", "a\"b", "", "a\nb"] {
            assert!(!usable_id(bad), "{bad:?}");
        }
    }

    #[test]
    fn numbers_read_back_to_the_same_bits() {
        for x in [0.1, 1e-7, -3.0, 1234.5678901234567, f64::MIN_POSITIVE] {
            assert_eq!(num(x).parse::<f64>().unwrap().to_bits(), x.to_bits());
        }
    }
}
