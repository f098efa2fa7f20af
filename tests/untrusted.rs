//! Untrusted input stays in its box: image names from a model are checked before they become
//! paths, photos that link out of the images folder are refused, and writers join every
//! name-derived path through one checked function. Each case lists the folders around the
//! scene and the output before and after, so a read or write outside them would show.

use std::path::{Path, PathBuf};

use super::{fails, ok, walk};

/// A small synthetic scene inside `boxdir/scene`, its model rewritten as text by `edit`.
fn scene_with(boxdir: &Path, edit: impl Fn(&mut nrw_colmap::Reconstruction, &Path)) -> PathBuf {
    let scene = boxdir.join("scene");
    let mut spec = nrw_synth::SceneSpec::demo().shrunk(4, (120, 150), 20_000);
    spec.observations.features = 300;
    nrw_synth::generate(&spec, &scene, &|| {}).unwrap();
    let mut rec = nrw_colmap::read_scene(&scene).unwrap();
    edit(&mut rec, &scene);
    let model = scene.join("sparse/0");
    for f in std::fs::read_dir(&model).unwrap().flatten() {
        std::fs::remove_file(f.path()).unwrap();
    }
    nrw_colmap::write_model(&rec, &model, nrw_colmap::Format::Text).unwrap();
    scene
}

/// Every file under `dir`, relative, sorted.
fn files(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = walk(dir)
        .iter()
        .map(|p| p.strip_prefix(dir).unwrap().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// Rename image `id`'s photo to `name` (relative to the images folder) in the model, moving
/// the file to where that name points.
fn rename(rec: &mut nrw_colmap::Reconstruction, scene: &Path, id: u32, name: &str) {
    let img = rec.images.get_mut(&id).unwrap();
    let from = scene.join("images").join(&img.name);
    let to = scene.join("images").join(name);
    std::fs::create_dir_all(to.parent().unwrap()).unwrap();
    std::fs::rename(from, to).unwrap();
    img.name = name.into();
}

/// `ingest` of the small scene (every view kept); its stderr when it fails, else None.
fn ingest(scene: &Path, out: &Path, extra: &[&str]) -> Option<String> {
    let o = super::ingest_small(
        scene,
        out,
        &[&["--max-empty", "1.0", "--quiet"], extra].concat(),
    );
    (!o.status.success()).then(|| String::from_utf8_lossy(&o.stderr).into_owned())
}

#[test]
fn escaping_and_absolute_names_are_refused_naming_the_image_and_nothing_outside_changes() {
    let tmp = tempfile::tempdir().unwrap();
    let boxdir = tmp.path().join("box");
    let first = |rec: &nrw_colmap::Reconstruction| *rec.images.keys().next().unwrap();
    for (case, hostile) in [
        ("climb", "../../pwn_src/0000.jpg".to_string()),
        (
            "absolute",
            tmp.path().join("abs/0000.jpg").display().to_string(),
        ),
    ] {
        let b = boxdir.join(case);
        let scene = scene_with(&b, |rec, scene| {
            let id = first(rec);
            let img = rec.images.get_mut(&id).unwrap();
            // The photo is placed where the hostile name points.
            let target = if hostile.starts_with('/') {
                PathBuf::from(&hostile)
            } else {
                scene.join("images").join(&hostile)
            };
            std::fs::create_dir_all(target.parent().unwrap()).unwrap();
            std::fs::rename(scene.join("images").join(&img.name), &target).unwrap();
            img.name = hostile.clone();
        });
        let before = files(tmp.path());
        let out = b.join("out");
        let e = ingest(&scene, &out, &[]).expect("refused");
        assert!(
            e.contains("images.txt") && e.contains("field `NAME`") && e.contains(&hostile),
            "{case}: {e}"
        );
        assert!(
            e.contains("climbs out") || e.contains("absolute path"),
            "{case}: {e}"
        );
        assert_eq!(
            files(tmp.path()),
            before,
            "{case}: nothing written anywhere"
        );
        // inspect reads the same model and says the same.
        let e = fails(&["inspect", scene.to_str().unwrap()]);
        assert!(e.contains(&hostile), "{case}: {e}");
    }
}

#[test]
fn a_photo_linking_out_of_the_images_folder_is_refused_unless_allowed() {
    let tmp = tempfile::tempdir().unwrap();
    let outside = tmp.path().join("outside");
    std::fs::create_dir_all(&outside).unwrap();
    let scene = scene_with(tmp.path(), |rec, scene| {
        let id = *rec.images.keys().next().unwrap();
        let photo = scene.join("images").join(&rec.images[&id].name);
        let kept = outside.join("real.jpg");
        std::fs::rename(&photo, &kept).unwrap();
        std::os::unix::fs::symlink(&kept, &photo).unwrap();
    });
    let out = tmp.path().join("out");
    let e = ingest(&scene, &out, &[]).expect("refused");
    assert!(
        e.contains("outside the images folder")
            && e.contains("real.jpg")
            && e.contains("--follow-outside-links"),
        "{e}"
    );
    assert_eq!(ingest(&scene, &out, &["--follow-outside-links"]), None);
    let labels = tmp.path().join("labels");
    let model = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/fixtures/segformer_tiny");
    let e = fails(&[
        "segment",
        scene.to_str().unwrap(),
        "--weights",
        model.to_str().unwrap(),
        "--out",
        labels.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(e.contains("outside the images folder"), "segment: {e}");
}

#[test]
fn a_subfolder_name_works_end_to_end_in_every_export_layout() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = scene_with(tmp.path(), |rec, scene| {
        let id = *rec.images.keys().next().unwrap();
        rename(rec, scene, id, "cam0/sub/0000.jpg");
    });
    let out = tmp.path().join("ds");
    // Undistorted, so the nerfw layout takes it (pinhole cameras only).
    assert_eq!(ingest(&scene, &out, &["--undistort"]), None);
    let d = out.to_str().unwrap();
    ok(&["split", d, "--val", "1"]);
    let ds = nrw_dataset::reader::Dataset::open(&out).unwrap();
    let names: Vec<String> = ["train", "val"]
        .iter()
        .flat_map(|s| ds.ids(s).unwrap().to_vec())
        .map(|i| ds.get(i).unwrap().name)
        .collect();
    assert!(names.iter().any(|n| n == "cam0/sub/0000.jpg"), "{names:?}");
    for (layout, want) in [
        ("official", "0000_reference.png"),
        ("files", "cam0/sub/0000/photo.png"),
        ("nerfw", "dense/images/cam0/sub/0000.png"),
        ("nerfstudio", "images/cam0/sub/0000.png"),
    ] {
        let exp = tmp.path().join(format!("x_{layout}"));
        let mut a = vec![
            "export",
            d,
            "--layout",
            layout,
            "--out",
            exp.to_str().unwrap(),
            "--quiet",
        ];
        if layout == "official" {
            a.extend(["--crop", "none", "--no-semantics"]);
        }
        ok(&a);
        let f = files(&exp);
        assert!(f.iter().any(|p| p.ends_with(want)), "{layout}: {f:?}");
    }
}

#[test]
fn the_one_join_refuses_every_hostile_name_a_writer_could_be_given() {
    let root = Path::new("/data/export");
    for bad in [
        "../x.png",
        "/etc/x",
        "a/../../x",
        "a\\..\\x",
        "a\0b",
        "",
        "C:x",
        "a//b",
    ] {
        let e = nrw_dataset::export::join_under(root, bad)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("/data/export") && e.contains("field `name`"),
            "{bad:?}: {e}"
        );
    }
    assert_eq!(
        nrw_dataset::export::join_under(root, "train/cam0/0001.png").unwrap(),
        root.join("train/cam0/0001.png")
    );
}
