//! `export --layout megadepth` read by its consumer: D2-Net's own
//! `megadepth_utils/preprocess_scene.py` (../shared/consumers/d2-net, unmodified) run on the
//! export writes a `scene_info` equal to the export's (paths, K, poses, overlap, scale ratios,
//! angles, point counts), and h5py reads every depth `.h5` back as the dataset's depth, bit
//! for bit.

use std::path::Path;

use nrw_dataset::reader::Dataset;

use super::{npy, nrw, ok, python, shared};

/// The scene name the export is made under (`--name`, D2-Net's `--scene_id`).
const SCENE: &str = "synthetic0001";

/// The metric scale the export is given (IMC 2022's scaling factor).
const METRES_PER_UNIT: &str = "0.25";

#[test]
fn d2net_preprocessing_of_the_export_gives_its_scene_info() {
    let Some(d2net) = shared::shared("consumers/d2-net/preprocess_scene.py") else {
        return;
    };
    if !python::python_has("import numpy, h5py, imagesize") {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let (scene, ds, out) = exported(tmp.path(), 60_000);
    let theirs_dir = tmp.path().join("theirs");
    std::fs::create_dir_all(&theirs_dir).unwrap();
    let run = std::process::Command::new("python3")
        .arg(&d2net)
        .args(["--base_path", out.to_str().unwrap(), "--scene_id", SCENE])
        .args(["--output_path", theirs_dir.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let theirs = theirs_dir.join(format!("{SCENE}.npz"));
    assert!(
        theirs.is_file(),
        "preprocess_scene.py wrote nothing: it found no scene"
    );
    let dump = tmp.path().join("dump");
    std::fs::create_dir_all(&dump).unwrap();
    let ours = out.join(format!("scene_info/{SCENE}.npz"));
    let got = script_json("megadepth_d2net.py", &[&theirs, &ours, &out, &dump]);
    for key in ["image_paths", "depth_paths"] {
        assert_eq!(got[key][0], got[key][1], "{key}");
    }
    let d = Dataset::open(ds.as_path()).unwrap();
    assert_eq!(got["image_paths"][0].as_array().unwrap().len(), d.len());
    for (key, tol) in [
        ("intrinsics", 0.0),
        ("poses", 1e-15),
        ("overlap_matrix", 0.0),
        ("scale_ratio_matrix", 1e-12),
        ("angles", 1e-5),
        ("n_points3D", 0.0),
    ] {
        let k = &got[key];
        assert_eq!(k["shape"][0], k["shape"][1], "{key}: {k}");
        let diff = k["max_abs"].as_f64().unwrap();
        assert!(diff <= tol, "{key}: theirs and ours differ by {diff}");
    }
    assert_eq!(
        got["keys_ours"], got["keys_theirs"],
        "every key the script writes"
    );
    let dicts = &got["dicts"];
    assert_eq!(dicts["lengths"][0], dicts["lengths"][1]);
    assert!(dicts["same_2d_and_keys"].as_bool().unwrap(), "{dicts}");
    assert!(
        dicts["ndepth_max_abs"].as_f64().unwrap() <= 1e-12,
        "{dicts}"
    );
    assert_eq!(
        dicts["ndepth_types"],
        serde_json::json!(["float64"]),
        "numpy scalars"
    );
    let pairs = got["overlap_matrix"]["valid_pairs"].as_u64().unwrap();
    assert!(pairs > 0, "some views share points");
    // Depth: h5py's reading of each file is the dataset's depth of that view.
    let by_path: std::collections::BTreeMap<String, u32> = d
        .splits()
        .iter()
        .flat_map(|(s, _)| d.ids(s).unwrap().to_vec())
        .map(|id| {
            let v = d.get(id).unwrap();
            let stem = nrw_export::nerfw::file_name(&v.name);
            let stem = stem.trim_end_matches(".png");
            (
                format!("phoenix/S6/zl548/MegaDepth_v1/{SCENE}/dense0/depths/{stem}.h5"),
                id,
            )
        })
        .collect();
    for (i, dep) in got["depths"].as_array().unwrap().iter().enumerate() {
        let v = d.get(by_path[dep["path"].as_str().unwrap()]).unwrap();
        let depth = v.depth().unwrap();
        assert_eq!(dep["shape"], serde_json::json!([v.height, v.width]));
        assert_eq!(dep["dtype"], "float32");
        let read = npy::read_npy_f64(&dump.join(format!("{i}.npy")));
        let want: Vec<f64> = depth.data.iter().map(|z| *z as f64).collect();
        assert!(read == want, "{}: depth differs", dep["path"]);
    }
    // The tracks: each observation carried into the stored (undistorted, scaled) view lands
    // where the stored camera projects its point, within the model's own reprojection error.
    let model = nrw_colmap::read_model(
        &out.join(format!("Undistorted_SfM/{SCENE}/sparse-txt")),
        None,
    )
    .unwrap();
    let source = nrw_colmap::read_scene(&scene).unwrap();
    let model_max = nrw_colmap::reprojection_stats(&source).max_px.unwrap();
    let (mut n, mut worst) = (0usize, 0f64);
    for img in model.images.values() {
        let cam = &model.cameras[&img.camera_id];
        assert_eq!(cam.model, nrw_colmap::CameraModel::Pinhole);
        for p in &img.points2d {
            let uv = cam
                .img_from_cam(
                    img.cam_from_world
                        .transform(model.points[&p.point3d_id].xyz),
                )
                .unwrap();
            worst = worst.max((uv - p.xy).length());
            n += 1;
        }
    }
    assert!(
        n > 0 && worst <= model_max * 1.5,
        "{n} observations, worst {worst} px vs the model's {model_max}"
    );
    dust3r_reads_its_folder(&out, &dump, &d);
    matchers_read_their_indices(&out, &theirs);
    imc2022_reads_its_folder(&out, &theirs);
    eprintln!(
        "D2-Net's scene_info of the export equals ours: {} views, {pairs} overlapping ordered \
         pairs; angles within {:.1e}°, scale ratios within {:.1e}",
        d.len(),
        got["angles"]["max_abs"].as_f64().unwrap(),
        got["scale_ratio_matrix"]["max_abs"].as_f64().unwrap()
    );
}

/// RoMa itself (romatch 0.1.2), LoFTR and DUSt3R themselves (their sources, where
/// `NRW_LOFTR_SRC` and `NRW_DUST3R_SRC` name checkouts), which need torch, read
/// the export through their own datasets: RoMa's and LoFTR's own ground-truth warps carry every
/// SfM observation of view A whose depth the file holds onto view B's observation of the same
/// point, and DUSt3R's point maps hold the SfM points, as closely as the export's numbers allow
/// (tests/oracles/megadepth_torch.py). Runs where `NRW_TORCH_PYTHON` names a Python with torch and
/// romatch (CI installs both from PyPI: RoMa runs there; LoFTR's and DUSt3R's sources are not
/// on PyPI, so there their transcriptions in tests/oracles/megadepth_matchers.py and
/// tests/oracles/megadepth_dust3r.py stand in); skips and says so elsewhere.
#[test]
fn roma_loftr_and_dust3r_themselves_read_the_export() {
    let Some(py) = python::torch_python("romatch", "RoMa, romatch 0.1.2", true) else {
        return;
    };
    let loftr = std::env::var_os("NRW_LOFTR_SRC");
    if loftr.is_none() {
        eprintln!("LoFTR skipped: NRW_LOFTR_SRC does not name a checkout of zju3dv/LoFTR");
    }
    let dust3r = std::env::var_os("NRW_DUST3R_SRC");
    if dust3r.is_none() {
        eprintln!("DUSt3R skipped: NRW_DUST3R_SRC does not name a checkout of naver/dust3r");
    }
    let tmp = tempfile::tempdir().unwrap();
    // A dense cloud: depth files with few holes, so a warp has depth to read.
    let (_, _, out) = exported(tmp.path(), 600_000);
    let none = std::ffi::OsString::from("-");
    let mut args: Vec<&Path> = vec![&out, Path::new(SCENE)];
    args.push(Path::new(loftr.as_ref().unwrap_or(&none)));
    if let Some(src) = &dust3r {
        args.push(Path::new(src));
    }
    let got = super::script_json(py.as_ref(), "megadepth_torch.py", &args);
    let roma = &got["roma"];
    assert_eq!(roma["scenes"], 1, "{roma}");
    assert_eq!(
        roma["pairs"], roma["stored_pairs"],
        "RoMa keeps every pair: {roma}"
    );
    warps_onto_the_tracks("RoMa", roma);
    if loftr.is_some() {
        let l = &got["loftr"];
        assert_eq!(l["bands"], 3, "{l}");
        assert!(l["pairs"].as_u64().unwrap() > 0, "{l}");
        warps_onto_the_tracks("LoFTR", l);
    }
    if dust3r.is_some() {
        let d = &got["dust3r"];
        assert!(
            d["k_max_abs"].as_f64().unwrap() < 1e-9,
            "DUSt3R's opencv_to_colmap_intrinsics of our K is the view's COLMAP K: {d}"
        );
        let (valid, n, median, theirs) = close_to_independent("DUSt3R", d);
        eprintln!(
            "DUSt3R itself: {} pairs, its point map valid at {valid} of {n} SfM points whose depth \
             the view holds, {median:.2e} of depth from the point (median) against {theirs:.2e} \
             from scene_info.npz; its K back in COLMAP's within {:.1e}",
            d["pairs"],
            d["k_max_abs"].as_f64().unwrap()
        );
    }
}

/// What a consumer of tests/oracles/megadepth_torch.py read (`got`): no problem reading, valid at half
/// the observations or more, and its median error within 1.25 times the same quantity computed
/// independently from scene_info.npz; (valid, observations, median, independent median).
fn close_to_independent(who: &str, got: &serde_json::Value) -> (u64, u64, f64, f64) {
    assert_eq!(got["problems"], serde_json::json!([]), "{who}: {got}");
    let (n, valid) = (
        got["observations"].as_u64().unwrap(),
        got["valid"].as_u64().unwrap(),
    );
    assert!(
        n > 0 && valid * 2 >= n,
        "{who} valid at {valid} of {n}: {got}"
    );
    let (median, theirs) = (
        got["median"].as_f64().unwrap(),
        got["independent_median"].as_f64().unwrap(),
    );
    assert!(
        median <= 1.25 * theirs,
        "{who}'s median {median} vs {theirs} independently: {got}"
    );
    (valid, n, median, theirs)
}

/// A consumer's warp (`got` from tests/oracles/megadepth_torch.py), printed after
/// [`close_to_independent`]'s checks (RoMa resamples depth bilinearly, LoFTR rounds the
/// keypoint).
fn warps_onto_the_tracks(who: &str, got: &serde_json::Value) {
    let (valid, n, median, theirs) = close_to_independent(who, got);
    eprintln!(
        "{who} itself: {} pairs, its warp valid at {valid} of {n} observations whose depth holds \
         their point, landing {median:.3} px (median; 90th percentile {:.3} px) from view B's \
         own; warped independently from scene_info.npz: {theirs:.3} px",
        got["pairs"],
        got["p90_px"].as_f64().unwrap()
    );
}

/// The synthetic scene (SIMPLE_RADIAL, 6 views of 200 px and more), its undistorted dataset and
/// that dataset's `--layout megadepth` export under `tmp`: (scene, dataset, export).
fn exported(
    tmp: &Path,
    points: usize,
) -> (std::path::PathBuf, std::path::PathBuf, std::path::PathBuf) {
    let scene = tmp.join("scene");
    // Views of 200 px and more: depth files over the script's 100 KiB mask threshold.
    let mut spec = nrw_synth::SceneSpec::demo().shrunk(6, (200, 220), points);
    spec.cameras.model = "SIMPLE_RADIAL".into();
    nrw_synth::generate(&spec, &scene, &|| {}).unwrap();
    let ds = tmp.join("ds");
    ok(&[
        "ingest",
        scene.to_str().unwrap(),
        "--out",
        ds.to_str().unwrap(),
        "--undistort",
        "--min-photo-side",
        "100",
        "--min-dim",
        "200",
        "--max-empty",
        "1.0",
        "--quiet",
    ]);
    ok(&["split", ds.to_str().unwrap(), "--val", "1"]);
    let out = tmp.join("md");
    let o = nrw(&[
        "export",
        ds.to_str().unwrap(),
        "--layout",
        "megadepth",
        "--name",
        SCENE,
        "--metres-per-unit",
        METRES_PER_UNIT,
        "--out",
        out.to_str().unwrap(),
    ]);
    // Warnings go to standard error (none for this dataset), the summary to standard output.
    let (summary, err) = (
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr),
    );
    assert!(o.status.success(), "{err}");
    assert!(
        summary.contains("exported") && !err.contains("warning"),
        "{summary}\n{err}"
    );
    (scene, ds, out)
}

/// tests/SCRIPT run by python3 with `args`; the one JSON object it prints.
fn script_json(script: &str, args: &[&Path]) -> serde_json::Value {
    super::script_json("python3".as_ref(), script, args)
}

/// LoFTR's and RoMa's loaders, transcribed (tests/oracles/megadepth_matchers.py), read the export's
/// `index/` and `prep_scene_info/`: every pair's views open, and the pairs, scores and central
/// matches are those D2-Net's own overlap matrix and dicts (`theirs`) give.
fn matchers_read_their_indices(out: &Path, theirs: &Path) {
    let got = script_json("megadepth_matchers.py", &[out, theirs, Path::new(SCENE)]);
    let (loftr, roma) = (&got["loftr"], &got["roma"]);
    assert_eq!(loftr["problems"], serde_json::json!([]), "LoFTR: {got}");
    assert_eq!(roma["problems"], serde_json::json!([]), "RoMa: {got}");
    assert_eq!(
        loftr["keys"],
        serde_json::json!(["depth_paths", "image_paths", "intrinsics", "poses"]),
        "what LoFTR's loader keeps after taking pair_infos"
    );
    assert_eq!(
        roma["keys"],
        serde_json::json!([
            "depth_paths",
            "image_paths",
            "intrinsics",
            "overlaps",
            "pairs",
            "poses"
        ])
    );
    assert_eq!(roma["dtypes"], serde_json::json!(["int64", "float64"]));
    let sharing = got["sharing_pairs"].as_u64().unwrap();
    let bands: Vec<(String, u64)> = loftr["bands"]
        .as_object()
        .unwrap()
        .iter()
        .map(|(k, v)| (k.clone(), v.as_u64().unwrap()))
        .collect();
    assert_eq!(bands.len(), 3, "{bands:?}");
    assert!(
        sharing > 0 && bands.iter().any(|b| b.1 > 0),
        "pairs to check: {got}"
    );
    eprintln!(
        "LoFTR's index: {bands:?} of {sharing} pairs sharing points; RoMa's: {} pairs",
        roma["pairs"]
    );
}

/// IMC 2022's evaluation code, transcribed (tests/oracles/megadepth_imc2022.py), reads the export's
/// `imc2022/train/`: calibration equals D2-Net's K and poses, the pairs are those sharing points
/// in D2-Net's overlap matrix, each covisibility is the bounding-box rule recomputed from
/// D2-Net's dicts, each F is the organisers' `ComputeFundamentalMatrix`, and submitted as a
/// prediction it scores as the ground truth.
fn imc2022_reads_its_folder(out: &Path, theirs: &Path) {
    let got = script_json("megadepth_imc2022.py", &[out, theirs, Path::new(SCENE)]);
    assert_eq!(got["problems"], serde_json::json!([]), "{got}");
    assert_eq!(
        got["scaling_dict"][SCENE].as_f64(),
        METRES_PER_UNIT.parse().ok(),
        "{got}"
    );
    let pairs = got["pairs"].as_u64().unwrap();
    assert!(
        pairs > 0 && got["recommended"].as_u64().unwrap() > 0,
        "{got}"
    );
    let worst = &got["worst"];
    let at_most = |key: &str, tol: f64| {
        let x = worst[key].as_f64().unwrap();
        assert!(x <= tol, "{key}: {x} > {tol} ({got})");
    };
    at_most("covisibility", 1e-12);
    at_most("F_relative", 1e-12);
    at_most("err_q_deg", 1e-4);
    at_most("err_t", 1e-6);
    eprintln!(
        "IMC 2022's reading: {pairs} pairs ({} at covisibility ≥ 0.1), worst covisibility \
         difference {:.1e}, F {:.1e} relative, the export's F scored as a prediction: {:.1e}° \
         and {:.1e} m",
        got["recommended"],
        worst["covisibility"].as_f64().unwrap(),
        worst["F_relative"].as_f64().unwrap(),
        worst["err_q_deg"].as_f64().unwrap(),
        worst["err_t"].as_f64().unwrap(),
    );
}

/// DUSt3R's loader, transcribed (tests/oracles/megadepth_dust3r.py) with OpenCV's own readers, on the
/// export's `dust3r/` folder: every pair's views open; depth is the dataset's bit for bit; K is
/// the view's in OpenCV's convention; cam2world inverts the view's world-to-camera pose; the JPEG is the photo within
/// JPEG's error.
fn dust3r_reads_its_folder(out: &Path, dump: &Path, d: &Dataset) {
    let got = script_json("megadepth_dust3r.py", &[&out.join("dust3r"), dump]);
    assert_eq!(
        got["fields"],
        serde_json::json!(["scene_id", "im1_id", "im2_id", "score"])
    );
    let pairs = got["pairs"].as_array().unwrap();
    assert!(!pairs.is_empty(), "pairs of views sharing points");
    let ids: Vec<u32> = d
        .splits()
        .iter()
        .flat_map(|(s, _)| d.ids(s).unwrap().to_vec())
        .collect::<std::collections::BTreeSet<u32>>()
        .into_iter()
        .collect();
    for (stem, v) in got["views"].as_object().unwrap() {
        let view = d.get(ids[v["id"].as_u64().unwrap() as usize]).unwrap();
        assert!(
            view.name.starts_with(stem.as_str()),
            "{stem} is {}",
            view.name
        );
        let (w, h) = (view.width as u64, view.height as u64);
        assert_eq!(v["image_shape"], serde_json::json!([h, w, 3]));
        assert_eq!(v["depth_dtype"], "float32");
        let depth = npy::read_npy_f64(&dump.join(format!("dust3r_{}.npy", v["id"])));
        let want: Vec<f64> = view
            .depth()
            .unwrap()
            .data
            .iter()
            .map(|z| *z as f64)
            .collect();
        assert!(depth == want, "{stem}: depth");
        // DUSt3R's K is in OpenCV's convention: the view's (COLMAP's) principal point - 0.5,
        // which its `opencv_to_colmap_intrinsics` (+0.5) turns back into the view's.
        let p = &view.params;
        let k: Vec<Vec<f64>> = serde_json::from_value(v["intrinsics"].clone()).unwrap();
        assert_eq!(
            k,
            vec![
                vec![p[0] as f32 as f64, 0.0, (p[2] - 0.5) as f32 as f64],
                vec![0.0, p[1] as f32 as f64, (p[3] - 0.5) as f32 as f64],
                vec![0.0, 0.0, 1.0],
            ]
        );
        let c2w: Vec<Vec<f64>> = serde_json::from_value(v["cam2world"].clone()).unwrap();
        let (pose, _) = nrw_colmap::Rigid3::from_colmap(view.qvec, view.tvec).unwrap();
        let centre = pose.centre();
        let r = pose.matrix();
        for (row, c2w_row) in c2w.iter().enumerate().take(3) {
            // cam2world's rotation is Rᵀ: its row `row` is R's column `row`.
            for (col, x) in c2w_row.iter().enumerate().take(3) {
                assert!((x - r.col(row)[col]).abs() < 1e-6, "{stem}: rotation");
            }
            assert!(
                (c2w_row[3] - centre[row]).abs() < 1e-5 * centre.length().max(1.0),
                "{stem}: centre"
            );
        }
        let photo = view.photo().unwrap();
        let rgb: Vec<f64> = serde_json::from_value(v["rgb"].clone()).unwrap();
        let err: f64 = rgb
            .iter()
            .zip(photo.as_raw())
            .map(|(a, b)| (a - *b as f64).abs())
            .sum::<f64>()
            / rgb.len() as f64;
        assert!(err < 4.0, "{stem}: JPEG mean error {err}");
    }
    eprintln!(
        "DUSt3R's loader read {} pairs of the export (EXR read by {})",
        pairs.len(),
        got["exr_reader"]
    );
}
