//! The COLMAP models every layout writes carry the scene's SfM observations where the stored
//! photos show them: on a distorted synthetic scene ingested with `--undistort` and stored
//! smaller than the photos, pycolmap 4.2.1 (every layout's model) and nerfbaselines 1.2.12's
//! own `colmap` loader (gsplat's and nerfbaselines' layouts) find every SfM observation of
//! every exported image, each keypoint where its image's own camera projects its point (the
//! median within the source model's reprojection error). And each of those models is COLMAP
//! 3.8's `image_undistorter` model of the scene (run in the test), each camera rescaled to its
//! stored view as COLMAP rescales one: cameras, poses, points, every observation within 1e-4 px.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::{ok, python};

/// A SIMPLE_RADIAL synthetic scene (k1 = −0.2), ingested undistorted with views stored at a
/// shorter side of 150 px (photos 220–260 px), one view held out: (scene, dataset).
fn distorted_dataset(dir: &Path) -> (PathBuf, PathBuf) {
    let scene = super::undistort::lens_scene(dir, 5, "SIMPLE_RADIAL", 5.0, false);
    let ds = dir.join("ds");
    let (s, d) = (scene.to_str().unwrap(), ds.to_str().unwrap());
    let mut args = vec!["ingest", s, "--out", d, "--undistort", "--quiet"];
    args.extend(super::undistort::SMALL_VIEWS);
    ok(&args);
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
    let undistorted =
        super::densify::colmap_undistorts(&scene.join("sparse/0"), &scene.join("images"), None);
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
        if let Some(theirs) = &undistorted {
            let ours = nrw_colmap::read_model(&out.join(model), None).unwrap();
            let (n, obs, cam, kp) = against_the_undistorter(layout, &ours, theirs);
            eprintln!(
                "{layout}: COLMAP's image_undistorter, rescaled to the stored views, and our \
                 model agree: {n} images, {obs} observations, the largest camera parameter \
                 difference {cam:.1e} px, the largest keypoint difference {kp:.1e} px"
            );
        }
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

/// `theirs`'s PINHOLE camera rescaled to `width`×`height` as COLMAP's `Camera::Rescale` does:
/// the focal length and principal point along each axis by the ratio of the sizes on it.
fn rescaled(theirs: &nrw_colmap::Camera, width: u64, height: u64) -> ([f64; 4], f64, f64) {
    let (sx, sy) = (
        width as f64 / theirs.width as f64,
        height as f64 / theirs.height as f64,
    );
    let p = &theirs.params;
    ([p[0] * sx, p[1] * sy, p[2] * sx, p[3] * sy], sx, sy)
}

/// Our exported model against COLMAP's undistorted model of the whole scene: every image of
/// ours is one of theirs (by file name) with the same pose, its camera theirs rescaled to the
/// stored view (1e-9 px), its observations theirs in the same order, each keypoint theirs
/// scaled by the same ratios (what their rescaled camera's projection gives) within 1e-4 px,
/// and every point where theirs is. Returns (images, observations, largest camera parameter
/// difference, largest keypoint difference).
fn against_the_undistorter(
    layout: &str,
    ours: &nrw_colmap::Reconstruction,
    theirs: &nrw_colmap::Reconstruction,
) -> (usize, usize, f64, f64) {
    let by_name: BTreeMap<String, &nrw_colmap::Image> = theirs
        .images
        .values()
        .map(|im| (nrw_export::nerfw::file_name(&im.name), im))
        .collect();
    let (mut observations, mut worst_camera, mut worst_keypoint) = (0, 0.0f64, 0.0f64);
    for im in ours.images.values() {
        let t = by_name
            .get(&im.name)
            .unwrap_or_else(|| panic!("{layout}: image {} is not in the scene", im.name));
        let (tq, oq) = (t.cam_from_world.qvec(), im.cam_from_world.qvec());
        let (tt, ot) = (t.cam_from_world.translation, im.cam_from_world.translation);
        assert!(
            tq.iter().zip(oq).all(|(a, b)| (a - b).abs() <= 1e-12) && (tt - ot).length() <= 1e-9,
            "{layout}, {}: pose {tq:?} {tt} vs ours {oq:?} {ot}",
            im.name
        );
        let (cam, tcam) = (&ours.cameras[&im.camera_id], &theirs.cameras[&t.camera_id]);
        assert_eq!(
            (cam.model, tcam.model),
            (
                nrw_colmap::CameraModel::Pinhole,
                nrw_colmap::CameraModel::Pinhole
            ),
            "{layout}, {}",
            im.name
        );
        let (want, sx, sy) = rescaled(tcam, cam.width, cam.height);
        for (a, b) in want.iter().zip(&cam.params) {
            worst_camera = worst_camera.max((a - b).abs());
        }
        assert!(
            worst_camera <= 1e-9,
            "{layout}, {}: camera {:?} vs COLMAP's rescaled {want:?}",
            im.name,
            cam.params
        );
        let seen: Vec<_> = t.points2d.iter().filter(|p| p.has_point3d()).collect();
        assert_eq!(seen.len(), im.points2d.len(), "{layout}, {}", im.name);
        for (k, (a, b)) in seen.iter().zip(&im.points2d).enumerate() {
            assert_eq!(
                a.point3d_id, b.point3d_id,
                "{layout}, {} observation {k}",
                im.name
            );
            let d = (glam::DVec2::new(a.xy.x * sx, a.xy.y * sy) - b.xy).length();
            assert!(
                d <= 1e-4,
                "{layout}, {} observation {k}: COLMAP's {} rescaled vs ours {} ({d} px)",
                im.name,
                a.xy,
                b.xy
            );
            worst_keypoint = worst_keypoint.max(d);
        }
        observations += im.points2d.len();
    }
    for (id, p) in &ours.points {
        assert!(
            (theirs.points[id].xyz - p.xyz).length() <= 1e-9,
            "{layout}: point {id}"
        );
    }
    assert!(observations > 0, "{layout}: no observation compared");
    (
        ours.images.len(),
        observations,
        worst_camera,
        worst_keypoint,
    )
}
