//! D2-Net's `scene_info` (what `preprocess_scene.py` computes from the layout's files) and
//! the pair files of LoFTR, RoMa and DUSt3R derived from it, a row of the N × N matrices at a
//! time.

use std::collections::{BTreeMap, HashMap};

use glam::DVec3;
use nrw_colmap::{Point2D, Reconstruction};

use super::view::View;
use crate::error::{ExportError, Result};
use crate::imc::ImcView;
use crate::npz::{self, Array};
use crate::pickle::{DictValue, Dtype, Pickler};
use crate::staging::Staged;

mod pairs;

/// MegaDepth's `scene_info`, computed as preprocess_scene.py computes it from the files this
/// layout writes: K from PINHOLE params; R from the re-normalised quaternion by the script's
/// formula; principal axis R[2]; w2c poses; normalised depth of an observed point
/// `(R[2]·X + t_z) / ((fx + fy) / 2)`; `overlap[i, j] = |common points| / |points of i|`;
/// `scale_ratio[i, j] = min over common points of max(nd_i / nd_j, nd_j / nd_i)` (−1 without
/// common points, and on the diagonal with overlap); `angles = degrees(arccos(clip(a·b)))`.
/// The N × N matrices are never held: each is written a row at a time from the points' views
/// ([`SceneInfo::row`]), so memory grows with the observations, not with N².
pub struct SceneInfo {
    pub image_paths: Vec<String>,
    pub depth_paths: Vec<String>,
    pub intrinsics: Vec<[[f64; 3]; 3]>,
    pub poses: Vec<[[f64; 4]; 4]>,
    pub n_points3d: Vec<i64>,
    /// Per view, `{point id: [x, y]}` in the script's insertion order (first observation of a
    /// point, last one's value).
    pub points3d_id_to_2d: Vec<Vec<(u64, DictValue)>>,
    /// Per view, `{point id: normalised depth}` in the same order.
    pub points3d_id_to_ndepth: Vec<Vec<(u64, DictValue)>>,
    /// Each view's principal axis (R's third row).
    axes: Vec<DVec3>,
    /// Per point: the views that observe it, with its normalised depth and position in each.
    seen: HashMap<u64, Vec<(usize, f64, [f64; 2])>>,
}

/// Which N × N matrix of scene_info.
#[derive(Clone, Copy)]
enum Matrix {
    Overlap,
    ScaleRatio,
    Angles,
}

/// LoFTR's overlap bands: its index folder `scene_info_0.1_0.7` holds a scene's pairs in one
/// file a band, named `SCENE_LO_HI.npz`.
pub const LOFTR_BANDS: [(f64, f64); 3] = [(0.1, 0.3), (0.3, 0.5), (0.5, 0.7)];

/// One view as scene_info takes it: where its files are, its camera and what it observes.
pub struct SceneView {
    pub image_path: String,
    pub depth_path: String,
    /// PINHOLE fx, fy, cx, cy.
    pub pinhole: [f64; 4],
    /// World-to-camera rotation as written in images.txt: (qw, qx, qy, qz).
    pub qvec: [f64; 4],
    pub tvec: [f64; 3],
    /// Each observed point once, in the script's order: id, [x, y] in the view's pixels, and
    /// the point's world position.
    pub points: Vec<(u64, [f64; 2], DVec3)>,
}

impl SceneInfo {
    /// The scene info of the written views, in images.txt order (image id).
    pub(super) fn of(views: &BTreeMap<u32, View>, rec: &Reconstruction) -> SceneInfo {
        SceneInfo::new(views.values().map(|v| {
            let points = first_seen_last_value(&v.points2d)
                .into_iter()
                .map(|(id, at)| (id, at, rec.points[&id].xyz))
                .collect();
            let p = &v.camera.params;
            SceneView {
                image_path: v.image_path.clone(),
                depth_path: v.depth_path.clone(),
                pinhole: [p[0], p[1], p[2], p[3]],
                qvec: v.qvec,
                tvec: v.tvec,
                points,
            }
        }))
    }

    /// The scene info of `views`, in their order.
    pub fn new(views: impl IntoIterator<Item = SceneView>) -> SceneInfo {
        let mut info = SceneInfo {
            image_paths: Vec::new(),
            depth_paths: Vec::new(),
            intrinsics: Vec::new(),
            poses: Vec::new(),
            n_points3d: Vec::new(),
            points3d_id_to_2d: Vec::new(),
            points3d_id_to_ndepth: Vec::new(),
            axes: Vec::new(),
            seen: HashMap::new(),
        };
        for (i, v) in views.into_iter().enumerate() {
            let [fx, fy, cx, cy] = v.pinhole;
            info.intrinsics
                .push([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]]);
            let r = rotation(v.qvec);
            let t = v.tvec;
            let mut pose = [[0.0; 4]; 4];
            for row in 0..3 {
                pose[row][..3].copy_from_slice(&r[row]);
                pose[row][3] = t[row];
            }
            pose[3][3] = 1.0;
            info.poses.push(pose);
            info.axes.push(DVec3::from_array(r[2]));
            let mut nd = Vec::with_capacity(v.points.len());
            let mut xy = Vec::with_capacity(v.points.len());
            for &(id, at, x) in &v.points {
                let z = r[2][0] * x.x + r[2][1] * x.y + r[2][2] * x.z + t[2];
                let d = z / (0.5 * (fx + fy));
                info.seen.entry(id).or_default().push((i, d, at));
                nd.push((id, DictValue::Scalar(d)));
                xy.push((id, DictValue::Pair(at)));
            }
            info.n_points3d.push(v.points.len() as i64);
            info.points3d_id_to_2d.push(xy);
            info.points3d_id_to_ndepth.push(nd);
            info.image_paths.push(v.image_path);
            info.depth_paths.push(v.depth_path);
        }
        info
    }

    /// Views in the scene.
    pub fn len(&self) -> usize {
        self.n_points3d.len()
    }

    /// View i as IMC 2022's files take it: its id, JPEG and size, with scene_info's K and pose.
    pub fn imc_view<'a>(
        &self,
        i: usize,
        id: &'a str,
        jpg: &'a str,
        width: u64,
        height: u64,
    ) -> ImcView<'a> {
        let p = &self.poses[i];
        ImcView {
            id,
            jpg,
            width,
            height,
            k: self.intrinsics[i],
            r: [0, 1, 2].map(|row| [p[row][0], p[row][1], p[row][2]]),
            t: [p[0][3], p[1][3], p[2][3]],
        }
    }

    /// View i's pairs with later views sharing points, with the shared points' bounding-box
    /// areas in both (IMC 2022's covisibility).
    pub fn shared_pairs_of(&self, i: usize) -> Vec<crate::imc::Shared> {
        self.pairs_of(i)
            .into_iter()
            .map(|p| crate::imc::Shared {
                i: p.i,
                j: p.j,
                areas: [p.boxes[0].area(), p.boxes[1].area()],
            })
            .collect()
    }

    /// Whether the scene has no view.
    pub fn is_empty(&self) -> bool {
        self.n_points3d.is_empty()
    }

    /// For view `i`, the points it shares with every view and the smallest scale ratio over
    /// them (infinite without common points).
    fn shared(&self, i: usize) -> (Vec<u64>, Vec<f64>) {
        let n = self.len();
        let (mut common, mut ratio) = (vec![0u64; n], vec![f64::INFINITY; n]);
        for (id, v) in &self.points3d_id_to_ndepth[i] {
            let DictValue::Scalar(ni) = *v else {
                unreachable!("normalised depths are scalars")
            };
            for &(j, nj, _) in &self.seen[id] {
                if j != i {
                    common[j] += 1;
                    ratio[j] = ratio[j].min((ni / nj).max(nj / ni));
                }
            }
        }
        (common, ratio)
    }

    /// Row `i` of one of the matrices.
    fn row(&self, m: Matrix, i: usize) -> Vec<f64> {
        let n = self.len();
        match m {
            Matrix::Angles => (0..n)
                .map(|j| {
                    self.axes[i]
                        .dot(self.axes[j])
                        .clamp(-1.0, 1.0)
                        .acos()
                        .to_degrees()
                })
                .collect(),
            Matrix::Overlap => {
                let (common, _) = self.shared(i);
                let own = self.n_points3d[i];
                (0..n)
                    .map(|j| match (j == i, own) {
                        (true, _) => -1.0,
                        (false, 0) => 0.0, // the script divides by zero here (see the warnings)
                        (false, own) => common[j] as f64 / own as f64,
                    })
                    .collect()
            }
            Matrix::ScaleRatio => {
                let (common, ratio) = self.shared(i);
                (0..n)
                    .map(|j| {
                        if j == i || common[j] == 0 {
                            -1.0
                        } else {
                            ratio[j]
                        }
                    })
                    .collect()
            }
        }
    }

    /// How many pairs (i < j) of views share points: one pass over the views.
    fn pair_count(&self) -> usize {
        (0..self.len()).map(|i| self.pairs_of(i).len()).sum()
    }

    /// DUSt3R's `all_metadata.npz` into `w`: `scenes` ("NAME 0"), `images` (the views' stems,
    /// in this scene info's order) and `pairs` (scene_id, im1_id, im2_id, score) for every
    /// pair of views that share SfM points, scored by the smaller of their two overlaps (our
    /// choice: DUSt3R publishes its pairs, not how they were scored). The pairs are streamed a
    /// view at a time (one pass counts them), so memory does not grow with their N².
    pub fn write_dust3r<W: std::io::Write + std::io::Seek>(
        &self,
        scene: &str,
        stems: &[String],
        w: W,
    ) -> std::io::Result<W> {
        let rows = self.pair_count();
        let fields = [
            ("scene_id", "<i4"),
            ("im1_id", "<i4"),
            ("im2_id", "<i4"),
            ("score", "<f4"),
        ];
        let header = Array::records(&fields, rows, Vec::new()).npy();
        let mut z = npz::NpzWriter::new(w);
        z.member("scenes", &Array::unicode(&[format!("{scene} 0")]).npy())?;
        z.member("images", &Array::unicode(stems).npy())?;
        let len = header.len() as u64 + rows as u64 * 16;
        z.streamed("pairs", len, |put| {
            put(&header)?;
            for i in 0..self.len() {
                let mut body = Vec::new();
                for p in self.pairs_of(i) {
                    body.extend_from_slice(&0i32.to_le_bytes());
                    body.extend_from_slice(&(p.i as i32).to_le_bytes());
                    body.extend_from_slice(&(p.j as i32).to_le_bytes());
                    // Precision given up here: DUSt3R's pairs hold float32 scores.
                    body.extend_from_slice(&(p.score as f32).to_le_bytes());
                }
                put(&body)?;
            }
            Ok(())
        })?;
        z.finish()
    }

    /// The keys LoFTR's and RoMa's files share with scene_info: image and depth paths (lists
    /// of str), intrinsics (N × 3 × 3) and world-to-camera poses (N × 4 × 4).
    fn pickle_views(&self, p: &mut Pickler) -> std::io::Result<()> {
        let n = self.len();
        let intrinsics: Vec<f64> = self
            .intrinsics
            .iter()
            .flatten()
            .flatten()
            .copied()
            .collect();
        let poses: Vec<f64> = self.poses.iter().flatten().flatten().copied().collect();
        p.str("image_paths")?;
        p.str_list(&self.image_paths)?;
        p.set_item()?;
        p.str("depth_paths")?;
        p.str_list(&self.depth_paths)?;
        p.set_item()?;
        p.str("intrinsics")?;
        p.f8_array(&[n, 3, 3], &intrinsics)?;
        p.set_item()?;
        p.str("poses")?;
        p.f8_array(&[n, 4, 4], &poses)?;
        p.set_item()
    }

    /// LoFTR's index of the pairs whose score is in [lo, hi): the views' keys and
    /// `pair_infos`, a list of `(array([i, j]), score, central_matches (1 × 4))`, written a
    /// view's pairs at a time.
    pub fn write_loftr(
        &self,
        (lo, hi): (f64, f64),
        w: &mut dyn std::io::Write,
    ) -> std::io::Result<()> {
        let mut p = Pickler::new(w)?;
        p.dict()?;
        self.pickle_views(&mut p)?;
        p.str("pair_infos")?;
        p.list()?;
        for i in 0..self.len() {
            for pair in self
                .pairs_of(i)
                .iter()
                .filter(|x| lo <= x.score && x.score < hi)
            {
                p.i8_array(&[2], &[pair.i as i64, pair.j as i64])?;
                p.float(pair.score)?;
                p.f8_array(&[1, 4], &pair.central)?;
                p.tuple3()?;
                p.append()?;
            }
        }
        p.set_item()?;
        p.stop()
    }

    /// RoMa's (and DKM's) scene info: the views' keys, `pairs` (P × 2 int64) and `overlaps`
    /// (P float64) of every pair sharing points, streamed (one pass counts P).
    pub fn write_roma(&self, w: &mut dyn std::io::Write) -> std::io::Result<()> {
        let n = self.len();
        let count = self.pair_count();
        w.write_all(&npz::npy_header("'|O'", &[]))?;
        let mut p = Pickler::new(w)?;
        p.object_scalar_begin()?;
        p.dict()?;
        self.pickle_views(&mut p)?;
        p.str("pairs")?;
        p.array_begin(Dtype::I8, &[count, 2])?;
        for i in 0..n {
            let row: Vec<u8> = self
                .pairs_of(i)
                .iter()
                .flat_map(|x| [x.i as i64, x.j as i64])
                .flat_map(i64::to_le_bytes)
                .collect();
            p.data(&row)?;
        }
        p.array_end()?;
        p.set_item()?;
        p.str("overlaps")?;
        p.array_begin(Dtype::F8, &[count])?;
        for i in 0..n {
            let row: Vec<u8> = self
                .pairs_of(i)
                .iter()
                .flat_map(|x| x.score.to_le_bytes())
                .collect();
            p.data(&row)?;
        }
        p.array_end()?;
        p.set_item()?;
        p.object_scalar_end()?;
        p.stop()
    }

    /// Write the `.npz` into `w`, with the arrays `np.savez` makes of the script's lists; the
    /// matrices a row at a time.
    pub fn write_npz<W: std::io::Write + std::io::Seek>(&self, w: W) -> std::io::Result<W> {
        let n = self.len();
        let flat = |m: &[[[f64; 3]; 3]]| m.iter().flatten().flatten().copied().collect::<Vec<_>>();
        let poses: Vec<f64> = self.poses.iter().flatten().flatten().copied().collect();
        let mut z = npz::NpzWriter::new(w);
        z.member("image_paths", &Array::unicode(&self.image_paths).npy())?;
        z.member("depth_paths", &Array::unicode(&self.depth_paths).npy())?;
        z.member(
            "intrinsics",
            &Array::f64(&[n, 3, 3], &flat(&self.intrinsics)).npy(),
        )?;
        z.member("poses", &Array::f64(&[n, 4, 4], &poses).npy())?;
        for (name, m) in [
            ("overlap_matrix", Matrix::Overlap),
            ("scale_ratio_matrix", Matrix::ScaleRatio),
            ("angles", Matrix::Angles),
        ] {
            let header = npz::npy_header("'<f8'", &[n, n]);
            let len = header.len() as u64 + (n * n * 8) as u64;
            z.streamed(name, len, |put| {
                put(&header)?;
                for i in 0..n {
                    let row: Vec<u8> = self
                        .row(m, i)
                        .iter()
                        .flat_map(|x| x.to_le_bytes())
                        .collect();
                    put(&row)?;
                }
                Ok(())
            })?;
        }
        z.member("n_points3D", &Array::i64(&self.n_points3d).npy())?;
        z.member("points3D_id_to_2D", &objects(&self.points3d_id_to_2d))?;
        z.member(
            "points3D_id_to_ndepth",
            &objects(&self.points3d_id_to_ndepth),
        )?;
        z.finish()
    }
}

/// LoFTR's index (a file a band and the list of them) and RoMa's scene info.
pub(super) fn write_pair_indices(name: &str, info: &SceneInfo, staged: &Staged) -> Result<()> {
    let mut stems = Vec::new();
    for band in LOFTR_BANDS {
        let stem = format!("{name}_{}_{}", band.0, band.1);
        let rel = format!("index/scene_info_0.1_0.7/{stem}.npz");
        let path = staged.dir().join(&rel);
        staged.write_with(&rel, &mut |w| {
            info.write_loftr(band, w)
                .map_err(|e| ExportError::io(&path, e))
        })?;
        stems.push(stem);
    }
    let list: String = stems.iter().map(|s| format!("{s}\n")).collect();
    staged.write("index/trainvaltest_list/train_list.txt", list.as_bytes())?;
    let rel = format!("prep_scene_info/{name}.npy");
    let path = staged.dir().join(&rel);
    staged.write_with(&rel, &mut |w| {
        info.write_roma(w).map_err(|e| ExportError::io(&path, e))
    })
}

/// A view's observations as the script's dict holds them: each point once, where it was
/// first observed, with its last observation's position.
fn first_seen_last_value(obs: &[Point2D]) -> Vec<(u64, [f64; 2])> {
    let mut at: std::collections::HashMap<u64, usize> = Default::default();
    let mut out: Vec<(u64, [f64; 2])> = Vec::with_capacity(obs.len());
    for o in obs {
        let xy = [o.xy.x, o.xy.y];
        match at.get(&o.point3d_id) {
            Some(&k) => out[k].1 = xy,
            None => {
                at.insert(o.point3d_id, out.len());
                out.push((o.point3d_id, xy));
            }
        }
    }
    out
}

/// The `.npy` of a 1-D object array of dicts (numpy pickles its items).
fn objects(items: &[Vec<(u64, DictValue)>]) -> Vec<u8> {
    Array::objects(items.len(), crate::pickle::object_array_of_dicts(items)).npy()
}

/// The rotation matrix of a quaternion as preprocess_scene.py builds it: re-normalised, then
/// the explicit formula (not a library's), so the two agree to the last bits.
pub(super) fn rotation(q: [f64; 4]) -> [[f64; 3]; 3] {
    let norm = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    let [w, x, y, z] = q.map(|c| c / norm);
    [
        [
            1.0 - 2.0 * y * y - 2.0 * z * z,
            2.0 * x * y - 2.0 * z * w,
            2.0 * x * z + 2.0 * y * w,
        ],
        [
            2.0 * x * y + 2.0 * z * w,
            1.0 - 2.0 * x * x - 2.0 * z * z,
            2.0 * y * z - 2.0 * x * w,
        ],
        [
            2.0 * x * z - 2.0 * y * w,
            2.0 * y * z + 2.0 * x * w,
            1.0 - 2.0 * x * x - 2.0 * y * y,
        ],
    ]
}
