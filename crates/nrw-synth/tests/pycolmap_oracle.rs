//! pycolmap, an independent reader, must read the generated model and measure the same
//! reprojection error the generator wrote. CI installs pycolmap and sets
//! NRW_REQUIRE_PY_ORACLES=1, so there a missing pycolmap fails instead of skipping.

use std::path::Path;
use std::process::Command;

const SCRIPT: &str = r#"
import sys, numpy as np, pycolmap
r = pycolmap.Reconstruction(sys.argv[1])
errs = []
for p in r.points3D.values():
    for el in p.track.elements:
        im = r.images[el.image_id]
        cam = r.cameras[im.camera_id]
        pose = im.cam_from_world() if callable(im.cam_from_world) else im.cam_from_world
        xy = cam.img_from_cam(pose * p.xyz)
        errs.append(np.linalg.norm(xy - im.points2D[el.point2D_idx].xy))
print(len(r.images), len(r.points3D), repr(float(np.mean(errs))))
"#;

fn pycolmap_available() -> bool {
    let ok = Command::new("python3")
        .args(["-c", "import pycolmap, numpy"])
        .status()
        .is_ok_and(|s| s.success());
    if !ok && std::env::var("NRW_REQUIRE_PY_ORACLES").is_ok_and(|v| v == "1") {
        panic!("NRW_REQUIRE_PY_ORACLES=1 but `python3 -c 'import pycolmap'` fails");
    }
    ok
}

#[test]
fn pycolmap_reads_the_generated_model_and_agrees_on_errors() {
    if !pycolmap_available() {
        eprintln!("pycolmap not installed: skipped (CI requires it)");
        return;
    }
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/demo.toml"),
    )
    .unwrap();
    let mut spec = nrw_synth::SceneSpec::from_toml(&text, "demo").unwrap();
    spec.cameras.count = 4;
    spec.cameras.min_size = 120;
    spec.cameras.max_size = 200;
    spec.geometry.points = 2000;
    spec.observations.features = 800;
    let dir = tempfile::tempdir().unwrap();
    let report = nrw_synth::generate(&spec, dir.path(), &|| {}).unwrap();
    // Each encoding alone in its own folder, so pycolmap has to read that one.
    for ext in ["bin", "txt"] {
        let only = dir.path().join(format!("only_{ext}"));
        std::fs::create_dir_all(&only).unwrap();
        for f in ["cameras", "images", "points3D"] {
            let name = format!("{f}.{ext}");
            std::fs::copy(dir.path().join("sparse/0").join(&name), only.join(&name)).unwrap();
        }
        let out = Command::new("python3")
            .args(["-c", SCRIPT])
            .arg(&only)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let text = String::from_utf8(out.stdout).unwrap();
        let v: Vec<&str> = text.split_whitespace().collect();
        assert_eq!(v[0].parse::<usize>().unwrap(), report.photos);
        assert_eq!(v[1].parse::<usize>().unwrap(), report.sparse_points);
        let mean: f64 = v[2].parse().unwrap();
        let ours = report.mean_reprojection_error_px.unwrap();
        assert!(
            (mean - ours).abs() < 1e-9,
            "{ext}: pycolmap {mean} vs generator {ours}"
        );
    }
}
