//! The paper's own layouts (`export --layout official|tfrecord`): what the published code reads, and what the export refuses.

use super::*;

/// Run tests/oracles/paper_oracle.py (the published code itself) in its records mode: the official
/// folders through `AlignedRenderedDataset` → `_generate_tfrecord_dataset` →
/// `_parser_rendered_dataset`, our TFRecords through the same parser, compared. None when
/// TensorFlow is not installed here (a skip that says so; CI requires it).
fn published_records(args: &[&str]) -> Option<serde_json::Value> {
    if !python_has(paper_code::PAPER_DEPS) {
        return None;
    }
    shared::shared("paper-code")?;
    Some(paper_code::paper_oracle(args))
}

/// Files under `dir`, relative, sorted.
fn listing(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = walk(dir)
        .iter()
        .map(|p| p.strip_prefix(dir).unwrap().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

fn export_json(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("export.json")).unwrap()).unwrap()
}

#[test]
fn official_and_tfrecord_exports_are_what_the_published_code_reads() {
    use nrw_dataset::reader::Dataset;
    if !python_has("import numpy, PIL, pyarrow") {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let ds_dir = small_dataset(tmp.path(), 6, true);
    let d = ds_dir.to_str().unwrap();
    let off = tmp.path().join("official");
    let tfr = tmp.path().join("tfr");
    let err = fails(&["export", d, "--out", off.to_str().unwrap()]);
    assert!(
        err.contains("needs a train split") && err.contains("split it first (--val N"),
        "{err}"
    );
    ok(&["split", d, "--val", "2"]);
    let stdout = ok(&[
        "export",
        d,
        "--out",
        off.to_str().unwrap(),
        "--name",
        "tiny",
        "--crop",
        "none",
    ]);
    assert!(
        stdout.contains("exported 6 views (train 4, val 2)"),
        "{stdout}"
    );
    ok(&[
        "export",
        d,
        "--layout",
        "tfrecord",
        "--shards", // the old name of --tfrecord-files, still taken
        "2",
        "--out",
        tfr.to_str().unwrap(),
        "--name",
        "tiny",
        "--crop",
        "none",
        "--quiet",
    ]);
    // The published converter and parser read both exports, to the same tensors.
    if let Some(v) = published_records(&[
        "--official",
        off.to_str().unwrap(),
        "--tfrecord",
        tfr.to_str().unwrap(),
        "--name",
        "tiny",
    ]) {
        eprintln!("paper_oracle.py: {v}");
        for (split, n) in [("train", 4), ("val", 2)] {
            assert_eq!(v["splits"][split]["views"], n, "{v}");
            assert_eq!(v["splits"][split]["records"], n, "{v}");
        }
    }
    // Exactly the paper's files, TFRecords named for the published glob.
    let files = listing(&off);
    assert_eq!(
        files.iter().filter(|f| f.starts_with("train/")).count(),
        16,
        "{files:?}"
    );
    assert_eq!(
        files.iter().filter(|f| f.starts_with("val/")).count(),
        8,
        "{files:?}"
    );
    assert!(!files.iter().any(|f| f.ends_with(".pckl")), "{files:?}");
    assert_eq!(
        listing(&tfr),
        [
            "attribution.csv",
            "export.json",
            "tiny-00000-of-00002_train.tfrecord",
            "tiny-00000-of-00002_val.tfrecord",
            "tiny-00001-of-00002_train.tfrecord",
            "tiny-00001-of-00002_val.tfrecord",
        ]
    );
    // Depth: levels 1-255 by the formula export.json records (linear by default), 0 exactly
    // where empty; the recorded inverse gives back the depth within half a level's spacing.
    let ds = Dataset::open(&ds_dir).unwrap();
    let meta = export_json(&off);
    let (near, far) = (
        meta["depth"]["near"].as_f64().unwrap(),
        meta["depth"]["far"].as_f64().unwrap(),
    );
    assert_eq!(meta["depth"]["mapping"], "linear");
    assert_eq!(
        Some((near, far)),
        nrw_dataset::scene::read_depth_range(&nrw_dataset::Store::from(&ds_dir)).unwrap()
    );
    let step = (far - near) / 254.0;
    let mut levels = std::collections::BTreeSet::new();
    for split in ["train", "val"] {
        let ids = meta["splits"]
            .as_array()
            .unwrap()
            .iter()
            .find(|s| s["split"] == split)
            .unwrap()["image_ids"]
            .clone();
        for (k, view) in ds.iter_split(split).unwrap().enumerate() {
            let view = view.unwrap();
            assert_eq!(
                ids[k], view.image_id,
                "export.json maps index {k} to the image id"
            );
            let png = image::open(off.join(split).join(format!("{k:04}_depth.png"))).unwrap();
            assert_eq!(png.color(), image::ColorType::L8);
            let truth = view.depth().unwrap();
            for (p, &t) in png.to_luma8().pixels().zip(&truth.data) {
                let l = p[0];
                assert_eq!(l == 0, t == 0.0, "0 = empty");
                if l > 0 {
                    levels.insert(l);
                    // The recorded formula: d = near + (level - 1) / 254 * (far - near).
                    let back = near + (l - 1) as f64 / 254.0 * (far - near);
                    assert!(
                        (back - t as f64).abs() <= step / 2.0 * (1.0 + 1e-9),
                        "level {l} for depth {t}"
                    );
                }
            }
            // The photo and the render are the stored ones, pixel for pixel.
            let rgb = image::open(off.join(split).join(format!("{k:04}_reference.png"))).unwrap();
            assert_eq!(rgb.to_rgb8(), view.photo().unwrap());
            let rgba = image::open(off.join(split).join(format!("{k:04}_color.png"))).unwrap();
            assert_eq!(rgba.to_rgba8(), view.color().unwrap());
        }
    }
    assert!(
        levels.len() > 20,
        "depth uses more than a few levels: {}",
        levels.len()
    );
    // The files layout keeps ADE20K ids and colour150.
    let files_out = tmp.path().join("files");
    ok(&[
        "export",
        d,
        "--layout",
        "files",
        "--out",
        files_out.to_str().unwrap(),
        "--quiet",
    ]);
    let v = ds.iter_split("val").unwrap().next().unwrap().unwrap();
    let dir = files_out
        .join("val")
        .join(Path::new(&v.name).with_extension(""));
    for f in [
        "photo.png",
        "color.png",
        "depth.exr",
        "normal.png",
        "semantics.png",
        "labels.png",
        "transient.png",
        "meta.json",
    ] {
        assert!(dir.join(f).is_file(), "{f}");
    }
    assert_eq!(
        image::open(dir.join("labels.png")).unwrap().to_luma8(),
        v.labels().unwrap().unwrap()
    );
    assert_eq!(
        image::open(dir.join("semantics.png")).unwrap().to_rgb8(),
        v.semantics().unwrap().unwrap()
    );
    assert_eq!(
        nrw_dataset::depth::read_exr(&dir.join("depth.exr")).unwrap(),
        v.depth().unwrap()
    );
}

#[test]
fn official_export_refuses_bad_requests_and_never_leaves_stale_files() {
    let tmp = tempfile::tempdir().unwrap();
    let plain = small_dataset(tmp.path(), 5, false);
    let p = plain.to_str().unwrap();
    ok(&["split", p, "--val", "0"]);
    let out = tmp.path().join("out");
    let o = out.to_str().unwrap();
    let leftovers = || {
        std::fs::read_dir(tmp.path())
            .unwrap()
            .flatten()
            .filter(|e| e.file_name().to_string_lossy().contains(".export-"))
            .count()
    };
    // No semantics: refused with what to do, nothing written.
    let e = fails(&["export", p, "--out", o]);
    assert!(
        e.contains("--semantics")
            && e.contains("--no-semantics")
            && e.contains("--use_semantic=False"),
        "{e}"
    );
    assert!(!out.exists() && leftovers() == 0);
    // --no-semantics: the loader's files without *_seg_rgb.png; the empty val split is named.
    let run = nrw(&["export", p, "--out", o, "--no-semantics", "--crop", "none"]);
    assert!(run.status.success());
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(err.contains("split val has no view: not written"), "{err}");
    let files = listing(&out);
    // Three files a view, export.json and attribution.csv.
    assert_eq!(files.len(), 5 * 3 + 2, "{files:?}");
    assert!(files.iter().all(|f| !f.contains("seg_rgb")));
    assert_eq!(export_json(&out)["semantics"], serde_json::Value::Null);
    // No published converter reads a folder without *_seg_rgb.png (AlignedRenderedDataset
    // raises NameError on img_seg); what trains with --use_semantic=False is the TFRecords,
    // which the published parser reads with use_semantics=False.
    let tfr = tmp.path().join("tfr_plain");
    ok(&[
        "export",
        p,
        "--layout",
        "tfrecord",
        "--out",
        tfr.to_str().unwrap(),
        "--name",
        "plain",
        "--no-semantics",
        "--crop",
        "none",
        "--quiet",
    ]);
    if let Some(v) = published_records(&[
        "--tfrecord",
        tfr.to_str().unwrap(),
        "--name",
        "plain",
        "--no-semantics",
    ]) {
        assert_eq!(v["splits"]["train"]["records"], 5, "{v}");
    }
    // A crop larger than every view: refused, naming a view and its size.
    let e = fails(&["export", p, "--out", o, "--no-semantics", "--crop", "4000"]);
    assert!(
        e.contains("no train view is left") && e.contains("photo_") && e.contains('×'),
        "{e}"
    );
    // ... and the earlier export is still there, whole.
    assert_eq!(listing(&out), files);
    // The files layout keeps views whole: a crop is refused, not ignored.
    let e = fails(&["export", p, "--out", o, "--layout", "files", "--crop", "64"]);
    assert!(
        e.contains("--crop applies to the official and tfrecord layouts"),
        "{e}"
    );
    assert_eq!(listing(&out), files);
    // A crop that fits: every channel cropped, export.json says so.
    ok(&[
        "export",
        p,
        "--out",
        o,
        "--no-semantics",
        "--crop",
        "64",
        "--quiet",
    ]);
    assert_eq!(export_json(&out)["crop"], 64);
    // Every channel of every view is the same 64 × 64 window of the uncropped export, at the
    // published start ((side − 64) // 2 in x and y): offsets and alignment, not only sizes.
    let whole = tmp.path().join("whole");
    ok(&[
        "export",
        p,
        "--out",
        whole.to_str().unwrap(),
        "--no-semantics",
        "--crop",
        "none",
        "--quiet",
    ]);
    let mut checked = 0;
    for f in listing(&whole).iter().filter(|f| f.ends_with(".png")) {
        let full = image::open(whole.join(f)).unwrap();
        let cut = image::open(out.join(f)).unwrap();
        assert_eq!((cut.width(), cut.height()), (64, 64), "{f}");
        assert_eq!(cut.color(), full.color(), "{f}");
        let (x, y) = ((full.width() - 64) / 2, (full.height() - 64) / 2);
        assert!(
            cut.as_bytes() == full.crop_imm(x, y, 64, 64).as_bytes(),
            "{f}: not the centre window at ({x}, {y})"
        );
        checked += 1;
    }
    assert_eq!(checked, 5 * 3, "reference, color and depth of 5 views");
    // Replacing an export with a smaller one leaves none of the earlier files.
    let smaller = small_dataset(tmp.path(), 3, false);
    ok(&["split", smaller.to_str().unwrap(), "--val", "1"]);
    ok(&[
        "export",
        smaller.to_str().unwrap(),
        "--out",
        o,
        "--no-semantics",
        "--crop",
        "none",
        "--quiet",
    ]);
    let now = listing(&out);
    assert_eq!(now.len(), 3 * 3 + 2, "{now:?}");
    let json = export_json(&out);
    let listed: usize = json["splits"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["files"].as_array().unwrap().len())
        .sum();
    assert_eq!(
        listed + 2,
        now.len(),
        "every file is the new export's (and export.json, attribution.csv)"
    );
    assert_eq!(leftovers(), 0, "no staging folder left behind");
    // A folder of someone else's files is not replaced; a file is not a folder.
    let foreign = tmp.path().join("foreign");
    std::fs::create_dir_all(&foreign).unwrap();
    std::fs::write(foreign.join("notes.txt"), "mine").unwrap();
    let e = fails(&[
        "export",
        p,
        "--out",
        foreign.to_str().unwrap(),
        "--no-semantics",
    ]);
    assert!(e.contains("not an nrw-etl export"), "{e}");
    assert_eq!(
        std::fs::read_to_string(foreign.join("notes.txt")).unwrap(),
        "mine"
    );
    let file = tmp.path().join("file");
    std::fs::write(&file, "x").unwrap();
    let e = fails(&[
        "export",
        p,
        "--out",
        file.to_str().unwrap(),
        "--no-semantics",
    ]);
    assert!(e.contains("is a file"), "{e}");
}
