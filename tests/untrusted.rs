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
/// Every file under `dir` with the SHA-256 of its bytes, so "nothing written" compares
/// contents, not names only (an overwritten manifest keeps its name).
/// `timings.json`, where stages (export included) add how long they took, is left out.
fn contents(dir: &Path) -> Vec<(String, String)> {
    files(dir)
        .into_iter()
        .filter(|rel| !rel.ends_with("timings.json"))
        .map(|rel| {
            let bytes = std::fs::read(dir.join(&rel)).unwrap();
            let sha = nrw_dataset::FileEntry::of_bytes(&rel, &bytes).sha256;
            (rel, sha)
        })
        .collect()
}

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
        let before = contents(tmp.path());
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
            contents(tmp.path()),
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
        ("tfrecord", ".tfrecord"),
        ("files", "cam0/sub/0000/photo.png"),
        ("nerfw", "dense/images/cam0/sub/0000.png"),
        ("nerfstudio", "images/cam0/sub/0000.png"),
        ("gsplat", "images_8/cam0/sub/0000.png"),
        ("megadepth", "dense0/depths/cam0/sub/0000.h5"),
        ("nerfbaselines", "images/cam0/sub/0000.png"),
    ] {
        let exp = tmp.path().join(format!("x_{layout}"));
        assert_eq!(export(&out, layout, &exp), None, "{layout}");
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
        let e = nrw_export::join_under(root, bad).unwrap_err().to_string();
        assert!(
            e.contains("/data/export") && e.contains("field `name`"),
            "{bad:?}: {e}"
        );
    }
    assert_eq!(
        nrw_export::join_under(root, "train/cam0/0001.png").unwrap(),
        root.join("train/cam0/0001.png")
    );
}

/// Rename views of the dataset at `ds` in its shards (and manifest), as a dataset made
/// elsewhere could name them: a dataset's names are data too, not only a model's.
fn rename_views(ds: &Path, rename: &dyn Fn(&str) -> Option<String>) {
    let store = nrw_dataset::Store::local(ds);
    let mut manifest = nrw_dataset::Manifest::read(&store).unwrap();
    for t in manifest.tables.clone() {
        if !nrw_dataset::views::is_shard(&t.path) {
            continue;
        }
        let path = ds.join(&t.path);
        let file = std::fs::File::open(&path).unwrap();
        let mut rows = nrw_dataset::reader::views_in(file, &path.clone().into()).unwrap();
        for r in &mut rows {
            if let Some(n) = rename(&r.name) {
                r.name = n;
            }
        }
        manifest.replace_table(nrw_dataset::write_shard(&store, &t.path, &rows).unwrap());
    }
    manifest.write(&store).unwrap();
}

/// A split, undistorted dataset of the small scene at `dir/ds` (every layout takes it), and
/// the names of its train views (one folder in every layout).
pub(crate) fn exportable_dataset(dir: &Path) -> (PathBuf, Vec<String>) {
    let scene = scene_with(dir, |_, _| {});
    let ds = dir.join("ds");
    assert_eq!(ingest(&scene, &ds, &["--undistort"]), None);
    ok(&["split", ds.to_str().unwrap(), "--val", "1"]);
    let d = nrw_dataset::reader::Dataset::open(&ds).unwrap();
    let names: Vec<String> = d
        .ids("train")
        .unwrap()
        .iter()
        .map(|&i| d.get(i).unwrap().name)
        .collect();
    assert!(names.len() >= 2, "{names:?}");
    (ds, names)
}

/// The arguments of `export --layout LAYOUT` of `ds` into `out` (a folder or a URL).
pub(crate) fn export_args(ds: &Path, layout: &str, out: &str) -> Vec<String> {
    let mut a: Vec<String> = [
        "export",
        ds.to_str().unwrap(),
        "--layout",
        layout,
        "--out",
        out,
        "--quiet",
    ]
    .map(String::from)
    .to_vec();
    if layout == "official" || layout == "tfrecord" {
        a.extend(["--crop", "none", "--no-semantics"].map(String::from));
    }
    a
}

/// `export --layout LAYOUT` of `ds` into `out`: its stderr when it fails, else None.
fn export(ds: &Path, layout: &str, out: &Path) -> Option<String> {
    let a = export_args(ds, layout, out.to_str().unwrap());
    let a: Vec<&str> = a.iter().map(String::as_str).collect();
    let o = super::nrw(&a);
    (!o.status.success()).then(|| String::from_utf8_lossy(&o.stderr).into_owned())
}

/// Every layout the tool has (a new one is tested here the day it is added).
pub(crate) const LAYOUTS: [&str; nrw_export::Layout::ALL.len()] = {
    let mut names = [""; nrw_export::Layout::ALL.len()];
    let mut i = 0;
    while i < names.len() {
        names[i] = nrw_export::Layout::ALL[i].name();
        i += 1;
    }
    names
};
/// The layouts whose file names come from the photos' names.
const NAMED_LAYOUTS: [&str; 6] = [
    "files",
    "nerfw",
    "nerfstudio",
    "gsplat",
    "megadepth",
    "nerfbaselines",
];

#[test]
fn hostile_names_in_a_dataset_reach_no_path_outside_any_export() {
    let tmp = tempfile::tempdir().unwrap();
    let (ds, names) = exportable_dataset(tmp.path());
    let absolute = tmp.path().join("abs/pwn.jpg").display().to_string();
    for hostile in [
        "../../pwn/0000.jpg",
        absolute.as_str(),
        "a\\..\\..\\pwn.jpg",
        "a\0b.jpg",
        "x/../../../pwn.jpg",
        // Aimed at files that exist: the dataset's own manifest, from wherever a layout
        // puts a photo (`SPLIT/NAME/`, `dense/images/NAME`, `images/NAME`).
        "../ds/manifest.json",
        "../../../ds/manifest.json",
        "../../../../ds/manifest.json",
    ] {
        // Every view but the first keeps its name; the first is hostile.
        let first = names[0].clone();
        let to = hostile.to_string();
        rename_views(&ds, &|n| (n == first).then(|| to.clone()));
        let before = contents(tmp.path());
        for layout in LAYOUTS {
            let out = tmp.path().join("exports").join(layout);
            match export(&ds, layout, &out) {
                Some(e) => {
                    assert!(NAMED_LAYOUTS.contains(&layout), "{layout} {hostile:?}: {e}");
                    assert!(
                        e.contains("field `name`") && e.contains(out.to_str().unwrap()),
                        "{layout} {hostile:?}: {e}"
                    );
                    assert!(
                        ["climbs out", "empty component", "backslash", "U+0000"]
                            .iter()
                            .any(|why| e.contains(why)),
                        "{layout} {hostile:?}: {e}"
                    );
                    assert_eq!(contents(tmp.path()), before, "{layout} {hostile:?}");
                }
                None => {
                    // Layouts of index names write the hostile name only as data, inside.
                    assert!(!NAMED_LAYOUTS.contains(&layout), "{layout} {hostile:?}");
                    let now: Vec<(String, String)> = contents(tmp.path())
                        .into_iter()
                        .filter(|(f, _)| !f.starts_with(&format!("exports/{layout}/")))
                        .collect();
                    assert_eq!(now, before, "{layout} {hostile:?}");
                    std::fs::remove_dir_all(&out).unwrap();
                }
            }
        }
        let back = first.clone();
        rename_views(&ds, &|n| (n == hostile).then(|| back.clone()));
    }
}

#[test]
fn names_one_file_apart_only_by_case_or_normalisation_are_refused_naming_both() {
    let tmp = tempfile::tempdir().unwrap();
    let (ds, names) = exportable_dataset(tmp.path());
    let (a, b) = (names[0].clone(), names[1].clone());
    for (x, y) in [
        ("Photo.jpg", "photo.JPG"),
        ("caf\u{e9}/0.jpg", "cafe\u{301}/0.jpg"),
        ("same.jpg", "same.png"),
    ] {
        rename_views(&ds, &|n| {
            (n == a)
                .then(|| x.to_string())
                .or_else(|| (n == b).then(|| y.to_string()))
        });
        for layout in LAYOUTS {
            let out = tmp.path().join("exports").join(layout);
            let before = contents(tmp.path());
            match export(&ds, layout, &out) {
                Some(e) => {
                    assert!(NAMED_LAYOUTS.contains(&layout), "{layout}: {e}");
                    // Named as Rust quotes them (a combining accent is escaped).
                    let stem = |n: &str| {
                        let s = n.split('.').next().unwrap();
                        format!("{s:?}").trim_matches('"').to_string()
                    };
                    assert!(
                        e.contains(&stem(x)) && e.contains(&stem(y)),
                        "{layout} {x:?} {y:?}: {e}"
                    );
                    assert!(
                        e.contains("letter case or Unicode normalisation")
                            || e.contains("two views would write the same file")
                            || e.contains("would both be written as"),
                        "{layout}: {e}"
                    );
                    assert_eq!(contents(tmp.path()), before, "{layout}: nothing written");
                }
                None => {
                    assert!(!NAMED_LAYOUTS.contains(&layout), "{layout} {x:?} {y:?}");
                    std::fs::remove_dir_all(&out).unwrap();
                }
            }
        }
        rename_views(&ds, &|n| {
            (n == x)
                .then(|| a.clone())
                .or_else(|| (n == y).then(|| b.clone()))
        });
    }
}

#[test]
fn a_model_naming_a_million_photos_is_read_whole_and_refused_in_a_bounded_message() {
    const N: u32 = 1_000_000;
    let tmp = tempfile::tempdir().unwrap();
    let scene = scene_with(tmp.path(), |rec, _| {
        let model = rec.images.values().next().unwrap().clone();
        let first = *rec.images.keys().max().unwrap() + 1;
        for id in first..first + N - rec.images.len() as u32 {
            let mut img = model.clone();
            img.id = id;
            img.name = format!("extra/{id:07}.jpg");
            img.points2d.clear();
            rec.images.insert(id, img);
        }
    });
    // Binary, as such a model would come.
    let model = scene.join("sparse/0");
    let rec = nrw_colmap::read_scene(&scene).unwrap();
    assert_eq!(rec.images.len(), N as usize);
    for f in std::fs::read_dir(&model).unwrap().flatten() {
        std::fs::remove_file(f.path()).unwrap();
    }
    nrw_colmap::write_model(&rec, &model, nrw_colmap::Format::Binary).unwrap();
    drop(rec);
    let summary: serde_json::Value =
        serde_json::from_str(&ok(&["inspect", scene.to_str().unwrap(), "--json"])).unwrap();
    assert_eq!(summary["images"].as_u64(), Some(N as u64), "{summary}");
    let out = tmp.path().join("out");
    let e = ingest(&scene, &out, &[]).expect("refused");
    assert!(
        e.contains(&format!("{} of {N} registered photos are missing", N - 4))
            && e.contains("extra/")
            && e.len() < 2_000,
        "{} bytes: {}",
        e.len(),
        &e[..e.len().min(2_000)]
    );
    assert!(!out.join("manifest.json").exists());
}

#[test]
fn a_name_that_is_not_utf8_is_refused_naming_the_file_and_field() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = scene_with(tmp.path(), |_, _| {});
    let model = scene.join("sparse/0");
    let rec = nrw_colmap::read_scene(&scene).unwrap();
    let first = rec.images.values().next().unwrap().name.clone();
    for f in std::fs::read_dir(&model).unwrap().flatten() {
        std::fs::remove_file(f.path()).unwrap();
    }
    nrw_colmap::write_model(&rec, &model, nrw_colmap::Format::Binary).unwrap();
    // One byte of the first name becomes 0xFF, which no UTF-8 text holds.
    let path = model.join("images.bin");
    let mut bytes = std::fs::read(&path).unwrap();
    let at = bytes
        .windows(first.len())
        .position(|w| w == first.as_bytes())
        .unwrap();
    bytes[at] = 0xFF;
    std::fs::write(&path, bytes).unwrap();
    let before = contents(tmp.path());
    let e = fails(&["inspect", scene.to_str().unwrap()]);
    assert!(
        e.contains("images.bin") && e.contains("not UTF-8") && e.contains("name"),
        "{e}"
    );
    let e = ingest(&scene, &tmp.path().join("out"), &[]).expect("refused");
    assert!(e.contains("images.bin") && e.contains("not UTF-8"), "{e}");
    assert_eq!(contents(tmp.path()), before, "nothing written");
}
