//! `export --layout gsplat` on a synthetic scene with people and ground truth: masks equal the
//! truth (people ignored, sky where rays miss the geometry), graphdeco's inverse-depth
//! convention gives the render's depth back within the PNG's step, every pyramid level
//! projects every SfM point to the level-0 position / 2^k and holds the box filter of level 0,
//! and nerfbaselines' own loader (PyPI 1.2.12) reads the split, images, masks and points.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use nrw_dataset::reader::Dataset;

use super::{ok, python};

/// ADE20K ids in the synthetic truth (nrw_synth::geometry).
const PERSON: u8 = 13;
const SKY: u8 = 3;
/// The photos' shorter side.
const SIDE: u32 = 121;

/// A split dataset of a PINHOLE synthetic scene with people, ingested with its truth labels,
/// and its gsplat export: (scene, dataset, export).
pub(crate) fn exported(dir: &Path) -> (PathBuf, PathBuf, PathBuf) {
    let scene = dir.join("scene");
    // Shorter sides of 121 px rendered at 121 px: views stored unscaled (the truth applies as
    // it is) and sizes not a multiple of 2, 4 or 8 (the pyramid's floor matters).
    let mut spec = nrw_synth::SceneSpec::demo().shrunk(5, (SIDE, SIDE), 60_000);
    spec.cameras.model = "PINHOLE".into();
    spec.cameras.distortion = 0.0;
    spec.effects.transients = Some(6.0);
    nrw_synth::generate(&spec, &scene, &|| {}).unwrap();
    let ds = dir.join("ds");
    let labels = scene.join("ground_truth/semantics");
    ok(&[
        "ingest",
        scene.to_str().unwrap(),
        "--out",
        ds.to_str().unwrap(),
        "--semantics",
        labels.to_str().unwrap(),
        "--min-photo-side",
        "100",
        "--min-dim",
        &SIDE.to_string(),
        "--max-empty",
        "1.0",
        "--quiet",
    ]);
    ok(&["split", ds.to_str().unwrap(), "--val", "1"]);
    let out = dir.join("gs");
    ok(&[
        "export",
        ds.to_str().unwrap(),
        "--layout",
        "gsplat",
        "--out",
        out.to_str().unwrap(),
        "--quiet",
    ]);
    (scene, ds, out)
}

fn gray(path: &Path) -> image::GrayImage {
    image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_luma8()
}

/// The views of the export: (image id, file under images/).
fn files(ds: &Dataset) -> Vec<(u32, String)> {
    let mut out = Vec::new();
    for (split, _) in ds.splits() {
        for &id in ds.ids(&split).unwrap() {
            let v = ds.get(id).unwrap();
            out.push((id, nrw_export::nerfw::file_name(&v.name)));
        }
    }
    out
}

#[test]
fn masks_depth_priors_and_pyramids_hold_what_they_claim() {
    let tmp = tempfile::tempdir().unwrap();
    let (scene, ds_dir, out) = exported(tmp.path());
    let ds = Dataset::open(ds_dir.as_path()).unwrap();
    let params: BTreeMap<String, serde_json::Value> =
        serde_json::from_slice(&std::fs::read(out.join("sparse/0/depth_params.json")).unwrap())
            .unwrap();
    let rec = nrw_colmap::read_model(&out.join("sparse/0"), None).unwrap();
    let (mut people, mut sky, mut depth_px, mut projected) = (0usize, 0usize, 0usize, 0usize);
    for (id, file) in files(&ds) {
        let v = ds.get(id).unwrap();
        // 1. Masks against the synthetic truth, at the photo's own size.
        let truth = gray(
            &nrw_dataset::semantics::label_path(&scene.join("ground_truth/semantics"), &v.name)
                .unwrap(),
        );
        assert_eq!(
            truth.dimensions(),
            (v.width, v.height),
            "{file}: stored unscaled"
        );
        let mask = gray(&out.join("masks").join(&file));
        let colmap_mask = gray(&out.join("masks").join(format!("{file}.png")));
        let sky_mask = gray(&out.join("sky").join(&file));
        assert_eq!(mask, colmap_mask, "{file}: one mask under both names");
        for ((t, m), s) in truth
            .as_raw()
            .iter()
            .zip(mask.as_raw())
            .zip(sky_mask.as_raw())
        {
            assert_eq!(*m == 0, *t == PERSON, "{file}: ignored ⇔ a person");
            assert_eq!(
                *s == 255,
                *t == SKY,
                "{file}: sky ⇔ the ray missed the geometry"
            );
            people += (*t == PERSON) as usize;
            sky += (*t == SKY) as usize;
        }
        // 2. graphdeco: png / 2^16 × scale + offset = 1 / z within half a step.
        let key = file.trim_end_matches(".png");
        let p = &params[key];
        let (scale, offset) = (p["scale"].as_f64().unwrap(), p["offset"].as_f64().unwrap());
        let png = image::open(out.join("depths").join(&file))
            .unwrap()
            .to_luma16();
        let depth = v.depth().unwrap();
        let valid = gray(&out.join("depth_masks").join(&file));
        for (m, z) in valid.as_raw().iter().zip(&depth.data) {
            assert_eq!(
                *m == 255,
                *z > 0.0,
                "{file}: the validity mask is the render's coverage"
            );
        }
        assert!(
            !out.join("depth_confidence").exists(),
            "the render's z-buffer has no confidence"
        );
        for (q, z) in png.as_raw().iter().zip(&depth.data) {
            let inv = *q as f64 / 65536.0 * scale + offset;
            if *z > 0.0 {
                let want = 1.0 / *z as f64;
                assert!(
                    (inv - want).abs() <= scale / 65536.0 / 2.0 * (1.0 + 1e-9),
                    "{file}: {inv} vs {want}"
                );
                depth_px += 1;
            } else {
                assert_eq!(*q, 0, "{file}: no depth stays 0");
            }
        }
        // 3. Pyramids: gsplat's parser (examples/datasets/colmap.py: `K[:2, :] /= factor`,
        // `imsize = (cam.width // factor, …)`, then K scaled by actual / imsize) on our files.
        let cam = &rec.cameras[&rec.images[&id].camera_id];
        assert_eq!(cam.id, id, "camera id = image id");
        let pose = rec.images[&id].cam_from_world;
        let level0 = image::open(out.join("images").join(&file))
            .unwrap()
            .to_rgb8();
        for f in [2u32, 4, 8] {
            let img = image::open(out.join(format!("images_{f}")).join(&file))
                .unwrap()
                .to_rgb8();
            let imsize = (cam.width as u32 / f, cam.height as u32 / f);
            assert_eq!(img.dimensions(), imsize, "{file} level {f}: gsplat's size");
            let (sx, sy) = (
                img.width() as f64 / imsize.0 as f64,
                img.height() as f64 / imsize.1 as f64,
            );
            let p = &cam.params;
            let k = [
                p[0] / f as f64 * sx,
                p[1] / f as f64 * sy,
                p[2] / f as f64 * sx,
                p[3] / f as f64 * sy,
            ];
            for pt in rec.points.values() {
                let c = pose.transform(pt.xyz);
                if c.z <= 0.0 {
                    continue;
                }
                let u0 = cam.img_from_cam(c).unwrap();
                let (u, w) = (k[0] * c.x / c.z + k[2], k[1] * c.y / c.z + k[3]);
                let d = (u - u0.x / f as f64).hypot(w - u0.y / f as f64);
                assert!(d <= 1e-9, "{file} level {f}: {d} px");
                projected += 1;
            }
            // The level holds whole f × f blocks of level 0 (box filter, half up).
            for (x, y, px) in img.enumerate_pixels() {
                let mut sum = [0u32; 3];
                for dy in 0..f {
                    for dx in 0..f {
                        let q = level0.get_pixel(x * f + dx, y * f + dy).0;
                        (0..3).for_each(|c| sum[c] += q[c] as u32);
                    }
                }
                let n = f * f;
                assert_eq!(
                    px.0,
                    sum.map(|s| ((s + n / 2) / n) as u8),
                    "{file} level {f} ({x}, {y})"
                );
            }
            let m = gray(&out.join(format!("masks_{f}")).join(&file));
            assert_eq!(m.dimensions(), imsize);
            let d = image::open(out.join(format!("depths_{f}")).join(&file))
                .unwrap()
                .to_luma16();
            assert_eq!(d.dimensions(), imsize);
        }
    }
    eprintln!(
        "gsplat export: {people} person and {sky} sky pixels matched the truth; {depth_px} depth \
         pixels round-trip graphdeco's convention; {projected} point projections at levels 2, 4, 8"
    );
    assert!(people > 0 && sky > 0 && depth_px > 0 && projected > 0);
    // The split as nerfbaselines reads it.
    let lists = |f: &str| {
        std::fs::read_to_string(out.join(f))
            .unwrap()
            .lines()
            .count()
    };
    assert_eq!(lists("train_list.txt") + lists("test_list.txt"), ds.len());
    assert_eq!(lists("test_list.txt"), 1);
}

/// graphdeco's own loader (its `scene/` and `utils/` at the checkout `NRW_GRAPHDECO_SRC` names;
/// torch, so never in CI; tests/oracles/gsplat_graphdeco_torch.py) reads the export as `train.py -d
/// depths` does: every camera at the view's size and field of view, every depth prior
/// reliable and, after its scale and offset, 1 / z of the render within half the PNG's step
/// (0 where the render has no depth), and the initialisation cloud with its normals.
#[test]
fn graphdeco_itself_reads_the_depth_priors() {
    let (Some(py), Some(src)) = (
        std::env::var_os("NRW_TORCH_PYTHON"),
        std::env::var_os("NRW_GRAPHDECO_SRC"),
    ) else {
        eprintln!(
            "skipped: NRW_TORCH_PYTHON and NRW_GRAPHDECO_SRC (a checkout of \
             graphdeco-inria/gaussian-splatting) are not both set; CI keeps the transcription"
        );
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let (_, ds_dir, out) = exported(tmp.path());
    let ds = Dataset::open(ds_dir.as_path()).unwrap();
    let dump = tmp.path().join("dump");
    std::fs::create_dir_all(&dump).unwrap();
    let got = super::script_json(
        py.as_ref(),
        "gsplat_graphdeco_torch.py",
        &[&out, Path::new(&src), &dump],
    );
    let params: BTreeMap<String, serde_json::Value> =
        serde_json::from_slice(&std::fs::read(out.join("sparse/0/depth_params.json")).unwrap())
            .unwrap();
    let rec = nrw_colmap::read_model(&out.join("sparse/0"), None).unwrap();
    let cameras = got["cameras"].as_array().unwrap();
    let views = files(&ds);
    assert_eq!(cameras.len(), views.len(), "every view trains: {got}");
    let mut pixels = 0usize;
    for (id, file) in views {
        let cam = cameras
            .iter()
            .find(|c| c["image_name"] == file.as_str())
            .unwrap_or_else(|| panic!("{file} not among graphdeco's cameras: {got}"));
        let v = ds.get(id).unwrap();
        assert_eq!(cam["size"], serde_json::json!([v.width, v.height]), "{cam}");
        assert_eq!(
            cam["depth_shape"],
            serde_json::json!([v.height, v.width]),
            "{cam}"
        );
        assert_eq!(cam["reliable"], true, "{file}: the prior is used: {cam}");
        assert_eq!(cam["depth_mask_zeros"], 0, "{cam}");
        let colmap = &rec.cameras[&rec.images[&id].camera_id];
        let fovx = 2.0 * (v.width as f64 / (2.0 * colmap.params[0])).atan();
        assert!(
            (cam["fovx"].as_f64().unwrap() - fovx).abs() < 1e-12,
            "{cam}"
        );
        let scale = params[file.trim_end_matches(".png")]["scale"]
            .as_f64()
            .unwrap();
        let inv = super::npy::read_npy_f64(&dump.join(file.replace(".png", ".npy")));
        let depth = v.depth().unwrap();
        assert_eq!(inv.len(), depth.data.len(), "{file}");
        for (got, z) in inv.iter().zip(&depth.data) {
            if *z > 0.0 {
                let want = 1.0 / *z as f64;
                // Half the PNG's step, and float32 (graphdeco's arrays) on top.
                let tol = scale / 65536.0 / 2.0 + want * 1e-6;
                assert!((got - want).abs() <= tol, "{file}: {got} vs 1/z = {want}");
                pixels += 1;
            } else {
                assert_eq!(*got, 0.0, "{file}: no depth reads as 0");
            }
        }
    }
    let points = got["points"].as_u64().unwrap();
    assert!(points > 0 && got["normals_nonzero"] == points, "{got}");
    eprintln!(
        "graphdeco itself: {} cameras, every prior reliable; {pixels} depth pixels read back \
         as 1 / z within half a step; {points} initialisation points, every one with a normal",
        cameras.len()
    );
}

#[test]
fn nerfbaselines_reads_the_split_images_masks_and_points() {
    if !python::python_runs(
        "import nerfbaselines.datasets.colmap, PIL, numpy",
        "NRW_REQUIRE_PY_ORACLES",
        "nerfbaselines 1.2.12",
    ) {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let (_, ds_dir, out) = exported(tmp.path());
    let ds = Dataset::open(ds_dir.as_path()).unwrap();
    let o = std::process::Command::new("python3")
        .arg(
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../../tests/oracles/gsplat_nerfbaselines.py"),
        )
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let got: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let rec = nrw_colmap::read_model(&out.join("sparse/0"), None).unwrap();
    assert_eq!(got["points"].as_u64().unwrap() as usize, rec.points.len());
    let by_file: BTreeMap<String, u32> = files(&ds).into_iter().map(|(id, f)| (f, id)).collect();
    let (mut ignored, mut poses) = (0, 0);
    for (split, ours) in [("train", "train"), ("test", "val")] {
        let views = got["splits"][split].as_array().unwrap();
        assert_eq!(views.len(), ds.ids(ours).unwrap().len(), "{split}");
        for v in views {
            let file = v["file"].as_str().unwrap();
            let id = by_file[file];
            assert!(ds.ids(ours).unwrap().contains(&id), "{file} in {split}");
            assert!(v["image_equal"].as_bool().unwrap(), "{file}: pixels");
            assert!(v["mask_equal"].as_bool().unwrap(), "{file}: mask");
            ignored += v["ignored"].as_u64().unwrap();
            let cam = &rec.cameras[&id];
            let k: Vec<f64> = serde_json::from_value(v["intrinsics"].clone()).unwrap();
            for (a, b) in k.iter().zip(&cam.params) {
                assert_eq!(
                    *a, *b as f32 as f64,
                    "{file}: intrinsics (float32 in nerfbaselines)"
                );
            }
            // Its pose: camera-to-world [Rᵀ | −Rᵀt] of the image's (OpenCV axes), in float32.
            let w2c = &rec.images[&id].cam_from_world;
            let rt = w2c.matrix().transpose();
            let centre = -(rt * w2c.translation);
            let pose: Vec<Vec<f64>> = serde_json::from_value(v["pose"].clone()).unwrap();
            for (row, got) in pose.iter().take(3).enumerate() {
                let want = [rt.col(0)[row], rt.col(1)[row], rt.col(2)[row], centre[row]];
                for (a, b) in got.iter().zip(want) {
                    assert!(
                        (a - b).abs() <= 1e-6 * (1.0 + b.abs()),
                        "{file}: pose row {row}: nerfbaselines {got:?}, ours {want:?}"
                    );
                }
                poses += 1;
            }
        }
    }
    assert_eq!(poses, 3 * ds.len(), "every view's pose compared");
    assert!(
        ignored > 0,
        "nerfbaselines sees the people as ignored pixels"
    );
    // images_2: nerfbaselines rescales K itself from the sizes. Where both sides are even it
    // gets K / 2 (what the export's whole-block levels need) exactly; where one is odd it
    // estimates the factor as size / ⌊size / 2⌋ and misses K / 2, which export.json warns of.
    let (mut worst, mut odd) = (0f64, 0);
    for v in got["images_2"].as_array().unwrap() {
        let cam = &rec.cameras[&by_file[v["file"].as_str().unwrap()]];
        let size: Vec<u32> = serde_json::from_value(v["size"].clone()).unwrap();
        assert_eq!(
            size,
            [cam.width as u32 / 2, cam.height as u32 / 2],
            "floor sizes"
        );
        let k: Vec<f64> = serde_json::from_value(v["intrinsics"].clone()).unwrap();
        let off = k
            .iter()
            .zip(&cam.params)
            .map(|(a, b)| (a - (*b as f32 as f64 / 2.0) as f32 as f64).abs())
            .fold(0.0, f64::max);
        if cam.width.is_multiple_of(2) && cam.height.is_multiple_of(2) {
            assert_eq!(off, 0.0, "even sizes: nerfbaselines' K is K / 2");
        } else {
            worst = worst.max(off);
            odd += 1;
        }
    }
    assert!(
        odd > 0 && worst > 1e-2,
        "odd sizes: nerfbaselines' K off K / 2 by {worst}"
    );
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("export.json")).unwrap()).unwrap();
    let warned = summary["warnings"].as_array().unwrap();
    assert!(
        warned
            .iter()
            .any(|w| w.as_str().unwrap().contains("at images_2")),
        "{warned:?}"
    );
    eprintln!("nerfbaselines at images_2: K off K / 2 by up to {worst:.3} px on {odd} odd-sized views, as export.json warns");
}

#[test]
fn nerfbaselines_reads_its_phototourism_layout_through_nb_info() {
    if !python::python_runs(
        "import nerfbaselines.datasets.colmap, PIL, numpy",
        "NRW_REQUIRE_PY_ORACLES",
        "nerfbaselines 1.2.12",
    ) {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let (_, ds_dir, _) = exported(tmp.path());
    let out = tmp.path().join("nb");
    ok(&[
        "export",
        ds_dir.to_str().unwrap(),
        "--layout",
        "nerfbaselines",
        "--name",
        "synthetic",
        "--out",
        out.to_str().unwrap(),
        "--quiet",
    ]);
    let ds = Dataset::open(ds_dir.as_path()).unwrap();
    let o = std::process::Command::new("python3")
        .arg(
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../../tests/oracles/gsplat_nerfbaselines.py"),
        )
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let got: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(
        got["metadata"],
        serde_json::json!({"id": "phototourism", "scene": "synthetic", "evaluation_protocol": "nerfw"})
    );
    let rec = nrw_colmap::read_model(&out.join("sparse"), None).unwrap();
    assert_eq!(got["points"].as_u64().unwrap() as usize, rec.points.len());
    let mut ignored = 0;
    for (split, ours) in [("train", "train"), ("test", "val")] {
        let views = got["splits"][split].as_array().unwrap();
        assert_eq!(views.len(), ds.ids(ours).unwrap().len(), "{split}");
        for v in views {
            assert!(v["image_equal"].as_bool().unwrap() && v["mask_equal"].as_bool().unwrap());
            ignored += v["ignored"].as_u64().unwrap();
        }
    }
    assert!(
        ignored > 0,
        "nerfbaselines sees the people as ignored pixels"
    );
    // NeRF-W's split file beside it, as nerf_pl and the downloader write it.
    let csv = std::fs::read_to_string(out.join("nerfw_split.csv")).unwrap();
    assert!(csv.starts_with("filename\tid\tsplit\tdataset\n"), "{csv}");
    assert_eq!(csv.lines().filter(|l| l.contains("\ttest\t")).count(), 1);
}
