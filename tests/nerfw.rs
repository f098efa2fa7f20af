//! `export --layout nerfw` read back by a transcription of nerf_pl's final Phototourism loader
//! (branch `nerfw`; tests/oracles/nerfw_reader.py, with pycolmap): every tsv row resolves to its image
//! and camera, intrinsics (with the loader's img_w = 2·cx), poses (its `poses[..., 1:3] *= -1`,
//! checked against our own rigid transform, not the same swap) and photos are the dataset's,
//! every image gets a near and far bound; `split --from-tsv` takes the tsv's sets back; a
//! dataset of distorted cameras is refused by name.

use std::path::Path;

use nrw_dataset::reader::Dataset;

use super::{data, fails, ok, python_has, shared};

/// An undistorted sacre_coeur dataset with a train/val split.
fn undistorted_dataset(out: &Path, undistort: bool) {
    let scene = data().join("sacre_coeur");
    let mut a = vec![
        "ingest",
        scene.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--max-empty",
        "1",
        "--min-dim",
        "300",
        "--quiet",
    ];
    if undistort {
        a.push("--undistort");
    }
    ok(&a);
    ok(&["split", out.to_str().unwrap(), "--val", "3"]);
}

#[test]
fn nerfw_export_reads_back_as_nerf_pl_reads_phototourism() {
    let Some(_) = shared::shared("data") else {
        return;
    };
    if !python_has("import pycolmap, numpy, PIL") {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let ds_dir = tmp.path().join("ds");
    undistorted_dataset(&ds_dir, true);
    let exp = tmp.path().join("nerfw");
    ok(&[
        "export",
        ds_dir.to_str().unwrap(),
        "--layout",
        "nerfw",
        "--out",
        exp.to_str().unwrap(),
        "--name",
        "sacre",
        "--quiet",
    ]);
    assert!(exp.join("sacre.tsv").is_file());
    let o = std::process::Command::new("python3")
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/oracles/nerfw_reader.py"))
        .arg(&exp)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let all: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let read = &all["images"];
    let scale = all["scale_factor"].as_f64().unwrap();
    let ds = Dataset::open(ds_dir.as_path()).unwrap();
    let mut seen = 0;
    for (split, tsv) in [("train", "train"), ("val", "test")] {
        for &id in ds.ids(split).unwrap() {
            let v = ds.get(id).unwrap();
            let r = &read[id.to_string()];
            assert_eq!(r["split"], tsv, "{}", v.name);
            assert_eq!(r["dataset"], "sacre");
            assert_eq!(r["id_column"], id.to_string());
            assert_eq!(r["model"], "CameraModelId.PINHOLE");
            // K: the loader rescales each entry by img_w_ / img_w (1 here), which may cost
            // the last bit.
            let k: Vec<f64> = serde_json::from_value(r["K"].clone()).unwrap();
            assert_eq!(k.len(), 4);
            for (a, b) in k.iter().zip(&v.params) {
                assert!(
                    (a - b).abs() <= 1e-12 * b.abs(),
                    "{}: K {k:?} is not the view's pinhole intrinsics {:?}",
                    v.name,
                    v.params
                );
            }
            assert_eq!(r["image_size"], serde_json::json!([v.width, v.height]));
            // The loader takes the image size as (2·cx, 2·cy): the principal point must be
            // the centre, as COLMAP's undistorter puts it.
            assert_eq!(
                r["img_wh_from_cx_cy"],
                serde_json::json!([v.width, v.height]),
                "{}: cx, cy = {:?}",
                v.name,
                &v.params[2..]
            );
            assert_eq!(r["camera_size"], serde_json::json!([v.width, v.height]));
            // The photo is the stored one, pixel for pixel.
            let photo = v.photo().unwrap();
            let sha = nrw_pipeline::sha256_hex(photo.as_raw());
            assert_eq!(r["rgb_sha"], sha, "{}", v.name);
            // nerf_pl's c2w: inverse of [R | t] with columns (x, −y, −z) and the centre divided
            // by the loader's scale (max far / 5), from our own rigid transform.
            let (rig, _) = nrw_colmap::Rigid3::from_colmap(v.qvec, v.tvec).unwrap();
            let m = rig.matrix();
            let c = rig.centre();
            let c2w: Vec<Vec<f64>> = serde_json::from_value(r["c2w"].clone()).unwrap();
            for row in 0..3 {
                // Row `row` of Rᵀ: (R[0][row], R[1][row], R[2][row]); glam is column-major.
                let rt = |col: usize| m.col(row)[col];
                let want = [rt(0), -rt(1), -rt(2), c[row] / scale];
                for (a, b) in c2w[row].iter().zip(want) {
                    assert!((a - b).abs() < 1e-9, "{}: c2w {c2w:?} vs {want:?}", v.name);
                }
            }
            let (near, far) = (r["near"].as_f64().unwrap(), r["far"].as_f64().unwrap());
            assert!(
                near > 0.0 && far > near,
                "{}: near {near}, far {far}",
                v.name
            );
            seen += 1;
        }
    }
    assert_eq!(
        seen,
        read.as_object().unwrap().len(),
        "every tsv row is a view"
    );
    assert_eq!(seen, 10);
    // The loader's far bounds are scaled so that the largest is 5.
    let fars = read
        .as_object()
        .unwrap()
        .values()
        .map(|r| r["far"].as_f64().unwrap());
    assert!((fars.fold(0.0, f64::max) - 5.0).abs() < 1e-5);
    // The tsv's sets come back with split --from-tsv, on a copy with another split first.
    let d = ds_dir.to_str().unwrap();
    let tsv = exp.join("sacre.tsv");
    let before = split_sets(&ds_dir);
    let text = std::fs::read_to_string(&tsv).unwrap();
    let swapped = exp.join("swapped.tsv");
    let flip = |l: &str| {
        l.replace("\ttrain\t", "\tX\t")
            .replace("\ttest\t", "\ttrain\t")
            .replace("\tX\t", "\ttest\t")
    };
    std::fs::write(
        &swapped,
        text.lines().map(flip).collect::<Vec<_>>().join("\n"),
    )
    .unwrap();
    let out = ok(&["split", d, "--from-tsv", swapped.to_str().unwrap()]);
    assert!(out.contains("3 train, 7 val"), "{out}");
    let out = ok(&["split", d, "--from-tsv", tsv.to_str().unwrap()]);
    assert!(out.contains("7 train, 3 val"), "{out}");
    assert_eq!(split_sets(&ds_dir), before);
    let ids = |key: &str| -> Vec<u32> { serde_json::from_value(all[key].clone()).unwrap() };
    let (train, test) = (ids("train"), ids("test"));
    let sets = split_sets(&ds_dir);
    assert_eq!(sets["train"], train.iter().copied().collect());
    assert_eq!(sets["val"], test.iter().copied().collect());
    // Rows without an id are ignored as nerf_pl ignores them; an unknown name is refused.
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let first: Vec<&str> = lines[1].split('\t').collect();
    let dropped = first[0].to_string();
    lines[1] = format!("{}\t\t{}\t{}", first[0], first[2], first[3]);
    let edited = exp.join("edited.tsv");
    std::fs::write(&edited, lines.join("\n") + "\n").unwrap();
    let err = super::nrw(&["split", d, "--from-tsv", edited.to_str().unwrap()]);
    assert!(err.status.success());
    assert!(String::from_utf8_lossy(&err.stderr).contains("1 kept photo(s) are not listed"));
    let sets = split_sets(&ds_dir);
    assert_eq!(
        sets.values().map(|s| s.len()).sum::<usize>(),
        9,
        "{dropped} is in no split"
    );
    lines.push("nowhere.jpg\t99\ttrain\tsacre".into());
    std::fs::write(&edited, lines.join("\n") + "\n").unwrap();
    let e = fails(&["split", d, "--from-tsv", edited.to_str().unwrap()]);
    assert!(
        e.contains("edited.tsv")
            && e.contains("\"nowhere.jpg\" (line 12)")
            && e.contains("match no image"),
        "{e}"
    );
}

/// split name → image ids of a dataset.
fn split_sets(ds: &Path) -> std::collections::BTreeMap<String, std::collections::BTreeSet<u32>> {
    let mut m = std::collections::BTreeMap::<_, std::collections::BTreeSet<u32>>::new();
    for a in nrw_dataset::split::read_splits(&nrw_dataset::Store::from(ds)).unwrap() {
        m.entry(a.split).or_default().insert(a.image_id);
    }
    m
}

#[test]
fn nerfw_export_refuses_distorted_cameras_by_name() {
    let Some(_) = shared::shared("data") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let ds_dir = tmp.path().join("ds");
    undistorted_dataset(&ds_dir, false);
    let exp = tmp.path().join("nerfw");
    let err = fails(&[
        "export",
        ds_dir.to_str().unwrap(),
        "--layout",
        "nerfw",
        "--out",
        exp.to_str().unwrap(),
    ]);
    assert!(
        err.contains("SIMPLE_RADIAL") && err.contains("--undistort") && err.contains("image "),
        "{err}"
    );
    assert!(!exp.exists(), "a refused export leaves nothing");
}

#[test]
fn nerfw_export_refuses_a_model_changed_since_ingest() {
    let Some(_) = shared::shared("data") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let src = data().join("sacre_coeur");
    let scene = tmp.path().join("scene");
    std::fs::create_dir_all(scene.join("sparse/0")).unwrap();
    for f in ["cameras.bin", "images.bin", "points3D.bin"] {
        std::fs::copy(src.join("sparse/0").join(f), scene.join("sparse/0").join(f)).unwrap();
    }
    super::copy_photos(&src.join("images"), &scene.join("images"));
    let ds_dir = tmp.path().join("ds");
    ok(&[
        "ingest",
        scene.to_str().unwrap(),
        "--out",
        ds_dir.to_str().unwrap(),
        "--undistort",
        "--max-empty",
        "1",
        "--min-dim",
        "200",
        "--quiet",
    ]);
    ok(&["split", ds_dir.to_str().unwrap(), "--val", "3"]);
    // The same model re-written (records in id order, not COLMAP's hash order): other bytes.
    let rec = nrw_colmap::read_model(&scene.join("sparse/0"), None).unwrap();
    nrw_colmap::write_model(&rec, &scene.join("sparse/0"), nrw_colmap::Format::Binary).unwrap();
    let exp = tmp.path().join("nerfw");
    let err = fails(&[
        "export",
        ds_dir.to_str().unwrap(),
        "--layout",
        "nerfw",
        "--out",
        exp.to_str().unwrap(),
    ]);
    assert!(
        err.contains("changed since this dataset was ingested"),
        "{err}"
    );
    assert!(err.contains("sparse/0/"), "{err}");
}
