//! The generator's contract: determinism, a genuine COLMAP model with honest errors, photos
//! and depth that agree with the cloud, only the asked-for effects, and the hard-case scenes.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use glam::DVec2;
use nrw_colmap::{read_model, read_ply, reprojection_stats, Format};
use nrw_dataset::depth::read_exr;
use nrw_synth::{generate, SceneSpec, SynthReport};

fn scenes() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes")
}

/// A scene file shrunk so a test runs in well under a second in debug builds.
fn tiny(name: &str) -> SceneSpec {
    let text = std::fs::read_to_string(scenes().join(format!("{name}.toml"))).unwrap();
    let mut s = SceneSpec::from_toml(&text, name).unwrap();
    s.geometry.points = 4000;
    s.cameras.count = s.cameras.count.min(4);
    s.cameras.min_size = 96;
    s.cameras.max_size = 160;
    s.observations.features = 600;
    s
}

fn run(spec: &SceneSpec) -> (tempfile::TempDir, SynthReport) {
    let dir = tempfile::tempdir().unwrap();
    let r = generate(spec, dir.path(), &|| {}).unwrap();
    (dir, r)
}

fn files(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.insert(
                    p.strip_prefix(dir).unwrap().to_path_buf(),
                    std::fs::read(&p).unwrap(),
                );
            }
        }
    }
    out
}

#[test]
fn same_seed_same_bytes_on_any_thread_count() {
    let spec = tiny("demo");
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let (a, _) = one.install(|| run(&spec));
    let (b, _) = run(&spec);
    let (fa, fb) = (files(a.path()), files(b.path()));
    assert_eq!(fa.keys().collect::<Vec<_>>(), fb.keys().collect::<Vec<_>>());
    for (k, v) in &fa {
        assert!(v == &fb[k], "{} differs between runs", k.display());
    }
    assert!(
        fa.len() >= 4 * 3 + 8,
        "photos, depth, labels, model, cloud, truth: {}",
        fa.len()
    );
    let mut other = spec.clone();
    other.seed += 1;
    let (c, _) = run(&other);
    assert_ne!(
        files(c.path())[Path::new("sparse/0/images.bin")],
        fa[Path::new("sparse/0/images.bin")]
    );
}

#[test]
fn the_model_is_genuine_and_its_errors_are_honest() {
    let (dir, report) = run(&tiny("demo"));
    for f in [Format::Binary, Format::Text] {
        let rec = read_model(&dir.path().join("sparse/0"), Some(f)).unwrap();
        assert_eq!(rec.images.len(), report.photos);
        assert_eq!(rec.num_observations(), report.observations);
        assert!(rec.points.values().all(|p| p.track.len() >= 2));
        // Mean over observations as our reader measures it = the track-weighted mean of the
        // errors the generator wrote into points3D = the noise it added.
        let s = reprojection_stats(&rec);
        let written: f64 = rec
            .points
            .values()
            .map(|p| p.error * p.track.len() as f64)
            .sum::<f64>()
            / rec.num_observations() as f64;
        let measured = s.mean_px.unwrap();
        assert!(
            (measured - written).abs() < 1e-9,
            "{f:?}: read {measured} vs written {written}"
        );
        assert!((measured - report.mean_reprojection_error_px.unwrap()).abs() < 1e-9);
        // 0.5 px per axis of Gaussian noise has a mean norm of 0.5·√(π/2) ≈ 0.63 px.
        assert!((measured - 0.627).abs() < 0.1, "{measured}");
    }
}

/// Project every cloud point into every photo and compare with the true depth there.
/// Returns (points compared, points agreeing, points in front of the true surface).
fn depth_agreement(dir: &Path) -> (usize, usize, usize) {
    let rec = read_model(&dir.join("sparse/0"), Some(Format::Binary)).unwrap();
    let cloud = read_ply(&dir.join("dense/fused.ply")).unwrap();
    let origin = rec.scene_origin();
    let (mut compared, mut agree, mut in_front) = (0, 0, 0);
    for img in rec.images.values() {
        let cam = &rec.cameras[&img.camera_id];
        let local = img.cam_from_world.recentred(origin);
        let fold = cam.injective_radius();
        let stem = Path::new(&img.name).with_extension("");
        let depth = read_exr(
            &dir.join("ground_truth/depth")
                .join(format!("{}.exr", stem.display())),
        )
        .unwrap();
        let (w, h) = (depth.width as i64, depth.height as i64);
        for p in &cloud.positions {
            let c = local.transform(*p - origin);
            // Beyond the lens's fold a point lands on another direction's pixel: not in view.
            if c.z <= 0.0 || cam.normalized_radius(c) > fold {
                continue;
            }
            let Some(px) = cam.img_from_cam(c) else {
                continue;
            };
            let (x, y) = (px.x.floor() as i64, px.y.floor() as i64);
            if x < 1 || y < 1 || x >= w - 1 || y >= h - 1 {
                continue;
            }
            // Away from depth edges: the 3×3 neighbourhood varies less than the tolerance.
            let at = |x: i64, y: i64| depth.data[(y * w + x) as usize] as f64;
            let nb: Vec<f64> = (-1..=1)
                .flat_map(|dy| (-1..=1).map(move |dx| (dx, dy)))
                .map(|(dx, dy)| at(x + dx, y + dy))
                .collect();
            let (lo, hi) = nb
                .iter()
                .fold((f64::MAX, 0.0f64), |(l, h), &v| (l.min(v), h.max(v)));
            if lo <= 0.0 || hi - lo > 0.005 * lo {
                continue;
            }
            compared += 1;
            let gt = at(x, y);
            // 0.5%: a point sits up to half a pixel from the pixel centre where depth was
            // taken; on these oblique planes depth changes < 0.3% per pixel; f32 storage.
            if (gt - c.z).abs() <= 0.005 * c.z {
                agree += 1;
            } else if gt > c.z {
                in_front += 1; // a point floating in front of the visible surface: a bug
            }
        }
    }
    (compared, agree, in_front)
}

#[test]
fn cloud_points_lie_on_the_true_depth() {
    for name in ["demo", "utm", "fisheye"] {
        // Large enough pixels-per-metre that most of a façade is smooth at the pixel scale.
        let mut spec = tiny(name).shrunk(3, (480, 640), 20_000);
        spec.effects.transients = None; // people are not in the cloud
        let (dir, _) = run(&spec);
        let (compared, agree, in_front) = depth_agreement(dir.path());
        assert!(compared > 500, "{name}: {compared}");
        assert_eq!(
            in_front, 0,
            "{name}: {in_front} of {compared} points float in front of the surface"
        );
        // The rest are occluded (behind the building, a column, a window jamb): true depth
        // there is nearer than the point, as it must be.
        assert!(agree > 200, "{name}: only {agree} of {compared} agree");
    }
}

fn counters(spec: &SceneSpec) -> BTreeMap<&'static str, u64> {
    run(spec).1.counters
}

#[test]
fn effects_not_asked_for_cost_nothing() {
    let mut bare = tiny("sparse_views");
    bare.cameras.model = "PINHOLE".into();
    bare.effects = Default::default();
    let c = counters(&bare);
    for (k, v) in &c {
        match *k {
            "primary_rays" | "png_photos" => assert!(*v > 0, "{k}"),
            _ => assert_eq!(*v, 0, "{k} ran {v} times in a scene that asked for nothing"),
        }
    }
    // Distortion is paid exactly by models that have it.
    let mut radial = bare.clone();
    radial.cameras.model = "SIMPLE_RADIAL".into();
    let c = counters(&radial);
    assert_eq!(c["distortion_inversions"], c["primary_rays"]);
    // One effect asked for: that one runs, no other.
    let mut hazy = bare.clone();
    hazy.effects.haze = Some(0.01);
    let c = counters(&hazy);
    assert!(c["haze"] > 0);
    for k in [
        "sun_shading",
        "shadow_rays",
        "window_glow",
        "exposure",
        "white_balance",
        "transient_tests",
        "sensor_noise",
        "jpeg_photos",
        "distortion_inversions",
    ] {
        assert_eq!(c[k], 0, "{k} ran in a haze-only scene");
    }
    // Everything asked for: everything runs.
    let mut all = tiny("demo");
    all.effects.appearance = Some(vec![
        nrw_synth::Appearance::Day,
        nrw_synth::Appearance::Night,
    ]);
    all.effects.transients = Some(5.0);
    all.cameras.count = 4;
    let c = counters(&all);
    for k in [
        "exposure",
        "white_balance",
        "haze",
        "sensor_noise",
        "jpeg_photos",
        "transient_tests",
    ] {
        assert!(c[k] > 0, "{k} did not run although asked for");
    }
}

#[test]
fn a_georeferenced_scene_keeps_its_digits() {
    let spec = tiny("utm");
    let (dir, report) = run(&spec);
    let rec = read_model(&dir.path().join("sparse/0"), Some(Format::Binary)).unwrap();
    assert!(rec.points.values().all(|p| p.xyz.x > 4.9e6));
    let s = reprojection_stats(&rec);
    let d = (s.mean_px.unwrap() - report.mean_reprojection_error_px.unwrap()).abs();
    assert!(d < 1e-6, "reprojection moved by {d:e} px at 5·10⁶ m");
    // The cloud is written in doubles: no decimetre rounding.
    let header = std::fs::read(dir.path().join("dense/fused.ply")).unwrap();
    assert!(String::from_utf8_lossy(&header[..200]).contains("property double x"));
}

#[test]
fn wide_fisheye_photos_have_black_corners_and_valid_models() {
    let spec = tiny("fisheye");
    let (dir, _) = run(&spec);
    let rec = read_model(&dir.path().join("sparse/0"), Some(Format::Binary)).unwrap();
    let cam = rec.cameras.values().next().unwrap();
    assert_eq!(cam.model.name(), "OPENCV_FISHEYE");
    // Corners beyond 90° have no ray: the camera model says so and the label map agrees.
    let corner = DVec2::new(0.5, 0.5);
    let img = rec.images.values().find(|i| i.camera_id == cam.id).unwrap();
    let labels = image::open(
        dir.path()
            .join("ground_truth/semantics")
            .join(Path::new(&img.name).with_extension("png")),
    )
    .unwrap()
    .to_luma8();
    assert_eq!(
        cam.cam_ray_from_img(corner).is_none(),
        labels.get_pixel(0, 0)[0] == 0
    );
}

#[test]
fn one_photo_and_sparse_scenes_are_valid() {
    let (dir, r) = run(&tiny("one_photo"));
    let rec = read_model(&dir.path().join("sparse/0"), Some(Format::Text)).unwrap();
    assert_eq!(
        (rec.images.len(), rec.points.len(), r.sparse_points),
        (1, 0, 0)
    );
    let (dir, r) = run(&tiny("sparse_views"));
    assert_eq!(r.dense_points, 4000);
    assert!(read_ply(&dir.path().join("dense/fused.ply")).unwrap().len() == 4000);
}

#[test]
fn bad_specs_name_the_key() {
    let e = SceneSpec::from_toml("name='x'\nseed=1\n[cameras]\nmodel='NOPE'\n", "x.toml")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("x.toml") && e.contains("cameras.model") && e.contains("NOPE"),
        "{e}"
    );
    let e = SceneSpec::from_toml("name='x'\nseed=1\n[effects]\nhaze=-1\n", "x.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("effects.haze"), "{e}");
    let e = SceneSpec::from_toml("name='x'\nseed=1\n[effects]\nfog=1\n", "x.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("unknown field") && e.contains("fog"), "{e}");
    let e = SceneSpec::from_toml("name='x'\nseed=1\n[cameras]\npixel_samples=0\n", "x.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("cameras.pixel_samples"), "{e}");
}

/// The mean absolute grey step between vertically adjacent pixels that both show `class`,
/// over every photo of a scene, and how many such pairs there are.
fn vertical_steps(dir: &Path, class: u8) -> (f64, usize) {
    let (mut sum, mut pairs) = (0.0, 0);
    for e in std::fs::read_dir(dir.join("images")).unwrap() {
        let path = e.unwrap().path();
        let stem = path.file_stem().unwrap().to_str().unwrap().to_string();
        let photo = image::open(&path).unwrap().to_luma8();
        let labels = image::open(dir.join(format!("ground_truth/semantics/{stem}.png")))
            .unwrap()
            .to_luma8();
        for y in 0..photo.height() - 1 {
            for x in 0..photo.width() {
                if labels.get_pixel(x, y)[0] == class && labels.get_pixel(x, y + 1)[0] == class {
                    let (a, b) = (photo.get_pixel(x, y)[0], photo.get_pixel(x, y + 1)[0]);
                    sum += (a as f64 - b as f64).abs();
                    pairs += 1;
                }
            }
        }
    }
    (sum / pairs.max(1) as f64, pairs)
}

#[test]
fn a_pixel_integrates_its_area_where_asked() {
    // The textured ground seen at a grazing angle: one ray a pixel aliases its fine texture
    // into noise no two photos share; 3 × 3 rays a pixel average it as a sensor does.
    let mut spec = tiny("textured");
    spec.cameras.min_size = 200;
    spec.cameras.max_size = 220;
    spec.cameras.count = 2;
    let (one, _) = run(&spec);
    spec.cameras.pixel_samples = 3;
    let (three, _) = run(&spec);
    let ground = nrw_synth::geometry::Material::Pavement.ade20k();
    let (aliased, pairs) = vertical_steps(one.path(), ground);
    let (filtered, pairs3) = vertical_steps(three.path(), ground);
    assert!(
        pairs > 2000,
        "the photos show the ground: {pairs} pixel pairs"
    );
    assert_eq!(pairs, pairs3, "labels are the centre ray's at any sampling");
    assert!(
        filtered < 0.75 * aliased,
        "ground steps {filtered:.2} grey levels with 3 × 3 rays against {aliased:.2} with one"
    );
    let (a, b) = (files(one.path()), files(three.path()));
    for (name, bytes) in &a {
        if name.starts_with("ground_truth/depth") || name.starts_with("ground_truth/semantics") {
            assert!(b[name] == *bytes, "{name:?}: the truth is the centre ray's");
        }
    }
}

#[test]
fn every_scene_file_in_scenes_parses_and_validates() {
    let mut names = Vec::new();
    for e in std::fs::read_dir(scenes()).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "toml") {
            let name = p.file_stem().unwrap().to_string_lossy().into_owned();
            let text = std::fs::read_to_string(&p).unwrap();
            let spec = SceneSpec::from_toml(&text, &name)
                .unwrap_or_else(|e| panic!("{}: {e}", p.display()));
            assert_eq!(
                spec.name,
                name,
                "{}: the name inside is the file's",
                p.display()
            );
            names.push(name);
        }
    }
    // The benchmarks' scenes are among them (a renamed file would leave a script behind).
    for wanted in ["demo", "textured", "wild", "hard", "many", "fisheye"] {
        assert!(
            names.iter().any(|n| n == wanted),
            "{wanted} missing: {names:?}"
        );
    }
}
