//! The COLMAP models every layout writes carry the scene's SfM observations where the stored
//! photos show them: on a distorted synthetic scene ingested with `--undistort` and stored
//! smaller than the photos, pycolmap 4.2.1 (every layout's model) and nerfbaselines 1.2.12's
//! own `colmap` loader (gsplat's and nerfbaselines' layouts) find every SfM observation of
//! every exported image, each keypoint where its image's own camera projects its point (the
//! median within the source model's reprojection error).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::{ok, python};

/// A SIMPLE_RADIAL synthetic scene (k1 = −0.2), ingested undistorted with views stored at a
/// shorter side of 150 px (photos 220–260 px), one view held out: (scene, dataset).
fn distorted_dataset(dir: &Path) -> (PathBuf, PathBuf) {
    let scene = dir.join("scene");
    let mut spec = nrw_synth::SceneSpec::demo().shrunk(5, (220, 260), 60_000);
    spec.cameras.model = "SIMPLE_RADIAL".into();
    spec.cameras.distortion = 5.0;
    nrw_synth::generate(&spec, &scene, &|| {}).unwrap();
    let ds = dir.join("ds");
    ok(&[
        "ingest",
        scene.to_str().unwrap(),
        "--out",
        ds.to_str().unwrap(),
        "--undistort",
        "--min-photo-side",
        "100",
        "--min-dim",
        "150",
        "--max-empty",
        "1.0",
        "--quiet",
    ]);
    ok(&["split", ds.to_str().unwrap(), "--val", "1"]);
    (scene, ds)
}

/// Per exported file name: the source model's observations of that image that have a
/// viewing ray (the ones an undistorted view can hold).
fn source_observations(scene: &Path) -> (BTreeMap<String, usize>, f64) {
    let rec = nrw_colmap::read_model(&scene.join("sparse/0"), None).unwrap();
    let counts = rec
        .images
        .values()
        .map(|im| {
            let cam = &rec.cameras[&im.camera_id];
            let n = im
                .points2d
                .iter()
                .filter(|p| p.has_point3d() && cam.cam_ray_from_img(p.xy).is_some())
                .count();
            (nrw_export::nerfw::file_name(&im.name), n)
        })
        .collect();
    let mean = nrw_colmap::reprojection_stats(&rec).mean_px.unwrap();
    (counts, mean)
}

/// Every image of one reader's answer holds all its source observations; the median distance
/// to its camera's projection. Returns (images, observations, median px).
fn check_reader(
    reader: &str,
    layout: &str,
    images: &serde_json::Map<String, serde_json::Value>,
    source: &BTreeMap<String, usize>,
) -> (usize, usize, f64) {
    let mut all = Vec::new();
    for (file, dists) in images {
        let dists: Vec<f64> = dists
            .as_array()
            .unwrap()
            .iter()
            .map(|d| d.as_f64().unwrap())
            .collect();
        let want = source
            .get(file)
            .unwrap_or_else(|| panic!("{layout}: {reader} reads an image {file} the scene lacks"));
        assert_eq!(
            dists.len(),
            *want,
            "{layout}, {reader}: {file} holds {} of its {want} SfM observations",
            dists.len()
        );
        all.extend(dists);
    }
    all.sort_by(f64::total_cmp);
    (images.len(), all.len(), all[all.len() / 2])
}

/// A layout, its model folder, and nerfbaselines' images and colmap folders where it reads it.
type Layout = (
    &'static str,
    &'static str,
    Option<(&'static str, &'static str)>,
);

#[test]
fn every_layouts_colmap_model_keeps_the_sfm_observations_where_the_views_show_them() {
    if !python::python_runs(
        "import pycolmap, nerfbaselines.datasets.colmap, numpy",
        "NRW_REQUIRE_PY_ORACLES",
        "pycolmap 4.2.1 and nerfbaselines 1.2.12",
    ) {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let (scene, ds) = distorted_dataset(tmp.path());
    let (source, source_error) = source_observations(&scene);
    let views: usize = nrw_dataset::reader::Dataset::open(ds.as_path())
        .unwrap()
        .splits()
        .iter()
        .map(|(_, n)| n)
        .sum();
    let layouts: [Layout; 4] = [
        ("gsplat", "sparse/0", Some(("images", "sparse/0"))),
        ("nerfbaselines", "sparse", Some(("images", "sparse"))),
        ("nerfw", "dense/sparse", None),
        ("megadepth", "Undistorted_SfM/ds/sparse-txt", None),
    ];
    for (layout, model, nb) in layouts {
        let out = tmp.path().join(layout);
        ok(&[
            "export",
            ds.to_str().unwrap(),
            "--layout",
            layout,
            "--out",
            out.to_str().unwrap(),
            "--quiet",
        ]);
        let mut cmd = std::process::Command::new("python3");
        cmd.arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/oracles/export_models.py"))
            .arg(out.join(model));
        if let Some((images, colmap)) = nb {
            cmd.arg("nerfbaselines").arg(&out).arg(images).arg(colmap);
        }
        let o = cmd.output().unwrap();
        assert!(
            o.status.success(),
            "{layout}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        let got: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let py = &got["pycolmap"];
        let (n, obs, median) = check_reader(
            "pycolmap",
            layout,
            py["images"].as_object().unwrap(),
            &source,
        );
        assert_eq!(
            n, views,
            "{layout}: every exported view is an image of the model"
        );
        assert_eq!(
            py["track_elements"].as_u64().unwrap() as usize,
            obs,
            "{layout}: tracks rebuilt from exactly the observations"
        );
        eprintln!(
            "{layout}: pycolmap reads {n} images, {obs} observations, {} points; median \
             distance to the projection {median:.4} px (source model's mean reprojection \
             error {source_error:.4} px)",
            py["points"]
        );
        assert!(median <= source_error, "{layout}: median {median} px");
        if nb.is_some() {
            let (n2, obs2, median2) = check_reader(
                "nerfbaselines",
                layout,
                got["nerfbaselines"]["images"].as_object().unwrap(),
                &source,
            );
            assert_eq!(
                (n2, obs2),
                (n, obs),
                "{layout}: nerfbaselines reads the same"
            );
            eprintln!("{layout}: nerfbaselines' loader: median {median2:.4} px");
            assert!(median2 <= source_error, "{layout}: median {median2} px");
        }
    }
}
