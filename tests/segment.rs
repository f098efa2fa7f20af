//! `nrw-etl segment` and `ingest --segment-weights` end to end with the committed tiny
//! SegFormer: the label maps are the library's, in the format ingest reads (the synthetic
//! scene's ground-truth label folder is the template), they round-trip into the shards'
//! ids, colours and transient mask, inline segmentation writes the same shards, and an
//! interrupted run resumes to the same bytes.

use std::path::{Path, PathBuf};

use arrow_array::{BinaryArray, StringArray, UInt32Array};
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;

use super::{column, fails, files, ingest_small, ok, walk};

fn tiny_model() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/fixtures/segformer_tiny")
}

/// PNG paths under a folder, relative to it.
fn pngs(dir: &Path) -> Vec<PathBuf> {
    walk(dir)
        .into_iter()
        .filter(|p| p.extension().is_some_and(|e| e == "png"))
        .map(|p| p.strip_prefix(dir).unwrap().to_path_buf())
        .collect()
}

fn scene(tmp: &Path) -> PathBuf {
    let scene = tmp.join("scene");
    let mut spec = nrw_synth::SceneSpec::demo().shrunk(4, (120, 150), 60_000);
    spec.observations.features = 300;
    nrw_synth::generate(&spec, &scene, &|| {}).unwrap();
    scene
}

/// `nrw-etl segment SCENE --weights MODEL --out OUT EXTRA…`.
fn args<'a>(scene: &'a Path, model: &'a Path, out: &'a Path, extra: &[&'a str]) -> Vec<&'a str> {
    let mut a = vec![
        "segment",
        scene.to_str().unwrap(),
        "--weights",
        model.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    a.extend(extra);
    a
}

/// A successful run with the tiny model (64-pixel inputs unless `extra` sets `--size`).
fn segment(scene: &Path, out: &Path, extra: &[&str]) -> serde_json::Value {
    let model = tiny_model();
    let mut a = args(scene, &model, out, &["--json", "--quiet"]);
    if !extra.contains(&"--size") {
        a.extend(["--size", "64"]);
    }
    a.extend(extra);
    serde_json::from_str(&ok(&a)).unwrap()
}

#[test]
fn label_maps_are_the_librarys_in_the_format_ingest_reads_and_resume_to_the_same_bytes() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = scene(tmp.path());
    let labels = tmp.path().join("labels");
    let s = segment(&scene, &labels, &[]);
    assert_eq!(
        (
            s["photos"].as_u64(),
            s["segmented"].as_u64(),
            s["resumed"].as_u64()
        ),
        (Some(4), Some(4), Some(0))
    );
    let model = nrw_segment::Segformer::load(&tiny_model()).unwrap();
    assert_eq!(s["model_sha256"], model.sha256.as_str());
    // The same files as the ground-truth label folder: name for name, size for size.
    let truth = scene.join("ground_truth/semantics");
    assert_eq!(pngs(&labels), pngs(&truth));
    for rel in pngs(&labels) {
        let ours = image::open(labels.join(&rel)).unwrap();
        assert_eq!(ours.color(), image::ColorType::L8, "{}", rel.display());
        let gt = image::open(truth.join(&rel)).unwrap();
        assert_eq!((ours.width(), ours.height()), (gt.width(), gt.height()));
        // Decoded as segment decodes it (libjpeg-turbo's pixels, Pillow's).
        let photo =
            nrw_dataset::codec::load_photo(&scene.join("images").join(rel.with_extension("jpg")))
                .or_else(|_| {
                    nrw_dataset::codec::load_photo(
                        &scene.join("images").join(rel.with_extension("png")),
                    )
                })
                .unwrap();
        let want = nrw_segment::segment(
            &model,
            &photo,
            nrw_segment::Mode::Resize {
                width: 64,
                height: 64,
            },
            "p",
            nrw_segment::Parallelism::None,
        )
        .unwrap();
        assert!(
            ours.to_luma8() == want,
            "{}: not the library's labels",
            rel.display()
        );
        assert!(want.as_raw().iter().all(|&v| (1..=150).contains(&v)));
    }
    // Resume: a deleted map is redone, byte for byte; the others are kept.
    let before = files(&labels);
    let first = labels.join(&pngs(&labels)[0]);
    std::fs::remove_file(&first).unwrap();
    let s = segment(&scene, &labels, &[]);
    assert_eq!(
        (s["segmented"].as_u64(), s["resumed"].as_u64()),
        (Some(1), Some(3))
    );
    assert!(before == files(&labels), "the resumed folder differs");
    // Two work units into one folder (one named by the old flag --shard, still taken): the
    // whole run's files, each photo done once.
    let units = labels.with_file_name("labels_units");
    let a = segment(&scene, &units, &["--shard", "0/2"]);
    let b = segment(&scene, &units, &["--unit", "1/2"]);
    assert_eq!(
        (
            a["segmented"].as_u64(),
            b["segmented"].as_u64(),
            a["unit"].as_str()
        ),
        (Some(2), Some(2), Some("0/2"))
    );
    assert!(
        before == files(&units),
        "two units wrote other files than one process"
    );
    // Another mode into the same folder is refused: maps of two modes never mix.
    let model = tiny_model();
    let e = fails(&args(
        &scene,
        &model,
        &labels,
        &["--mode", "slide", "--size", "64"],
    ));
    assert!(
        e.contains("segment.json") && e.contains("slide 64") && e.contains("resize 64x64"),
        "{e}"
    );
}

/// (name, ids, colours, mask) of every view in a dataset's shards.
type Labelled = Vec<(String, (u32, u32), Vec<u8>, Vec<u8>, Vec<u8>)>;

fn shard_labels(ds: &Path) -> Labelled {
    let mut out = Vec::new();
    for shard in walk(&ds.join("shards")) {
        let f = std::fs::File::open(&shard).unwrap();
        for b in ParquetRecordBatchReaderBuilder::try_new(f)
            .unwrap()
            .build()
            .unwrap()
        {
            let b = b.unwrap();
            for i in 0..b.num_rows() {
                let name = column::<StringArray>(&b, "name").value(i).to_string();
                let size = (
                    column::<UInt32Array>(&b, "width").value(i),
                    column::<UInt32Array>(&b, "height").value(i),
                );
                let png = |c: &str| {
                    nrw_dataset::codec::decode_png(
                        column::<BinaryArray>(&b, c).value(i),
                        Path::new(&name),
                    )
                    .unwrap()
                    .3
                };
                out.push((
                    name.clone(),
                    size,
                    png("labels_png"),
                    png("semantics_png"),
                    png("transient_png"),
                ));
            }
        }
    }
    out.sort_by(|a, b| a.0.cmp(&b.0));
    out
}

#[test]
fn label_maps_round_trip_into_the_shards_and_inline_segmentation_writes_the_same() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = scene(tmp.path());
    let labels = tmp.path().join("labels");
    segment(&scene, &labels, &[]);
    let via_files = tmp.path().join("via_files");
    let common = ["--max-empty", "1.0", "--quiet"];
    let o = ingest_small(
        &scene,
        &via_files,
        &[&common[..], &["--semantics", labels.to_str().unwrap()]].concat(),
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let inline = tmp.path().join("inline");
    let model = tiny_model();
    let o = ingest_small(
        &scene,
        &inline,
        &[
            &common[..],
            &[
                "--segment-weights",
                model.to_str().unwrap(),
                "--segment-size",
                "64",
            ],
        ]
        .concat(),
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (a, b) = (shard_labels(&via_files), shard_labels(&inline));
    assert_eq!(a.len(), 4);
    assert!(
        a == b,
        "inline segmentation stored other labels than the label folder gave"
    );
    let table = nrw_dataset::semantics::classes();
    for (name, (w, h), ids, rgb, mask) in &a {
        let map = image::open(labels.join(Path::new(name).with_extension("png")))
            .unwrap()
            .to_luma8();
        for y in 0..*h {
            for x in 0..*w {
                // Nearest resize of the map, computed here independently.
                let sx = (((x as f64 + 0.5) * map.width() as f64 / *w as f64) as u32)
                    .min(map.width() - 1);
                let sy = (((y as f64 + 0.5) * map.height() as f64 / *h as f64) as u32)
                    .min(map.height() - 1);
                let id = map.get_pixel(sx, sy)[0];
                let k = (y * w + x) as usize;
                assert_eq!(ids[k], id, "{name} ({x}, {y})");
                assert_eq!(
                    &rgb[k * 3..k * 3 + 3],
                    &table[id as usize].color,
                    "{name} ({x}, {y})"
                );
                assert_eq!(
                    mask[k] == 255,
                    table[id as usize].transient,
                    "{name} ({x}, {y})"
                );
            }
        }
    }
    let manifest = std::fs::read_to_string(inline.join("manifest.json")).unwrap();
    let sha = nrw_segment::Segformer::load(&model).unwrap().sha256;
    assert!(
        manifest.contains(&sha) && manifest.contains("resize 64x64"),
        "the manifest records the model and mode"
    );
}

#[test]
fn a_bad_model_stops_segment_and_ingest_naming_the_file() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = scene(tmp.path());
    let bad = tmp.path().join("bad");
    std::fs::create_dir_all(&bad).unwrap();
    std::fs::copy(tiny_model().join("config.json"), bad.join("config.json")).unwrap();
    std::fs::write(bad.join("model.safetensors"), b"not a model").unwrap();
    let out = tmp.path().join("labels");
    let e = fails(&args(&scene, &bad, &out, &[]));
    assert!(
        e.contains("model.safetensors") && e.contains("not a safetensors file"),
        "{e}"
    );
    assert!(
        !out.exists(),
        "nothing written for a model that cannot load"
    );
    let o = ingest_small(
        &scene,
        &tmp.path().join("ds"),
        &["--segment-weights", bad.to_str().unwrap()],
    );
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(e.contains("model.safetensors"), "{e}");
}

#[test]
fn a_folder_of_photos_segments_without_a_model_and_the_accuracy_script_scores_it() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = scene(tmp.path());
    let labels = tmp.path().join("folder_labels");
    let model = tiny_model();
    let images = scene.join("images");
    let s: serde_json::Value = serde_json::from_str(&ok(&[
        "segment",
        "--images",
        images.to_str().unwrap(),
        "--weights",
        model.to_str().unwrap(),
        "--out",
        labels.to_str().unwrap(),
        "--size",
        "64",
        "--json",
        "--quiet",
    ]))
    .unwrap();
    assert_eq!(s["photos"].as_u64(), Some(4));
    let truth = scene.join("ground_truth/semantics");
    assert_eq!(pngs(&labels), pngs(&truth));
    if !super::python_has("import numpy, PIL") {
        return;
    }
    let score = |labels: &Path| -> String {
        let o = std::process::Command::new("python3")
            .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/oracles/segment_check.py"))
            .args([
                "--labels",
                labels.to_str().unwrap(),
                "--annotations",
                truth.to_str().unwrap(),
            ])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8(o.stdout).unwrap()
    };
    // The ground truth scores itself perfectly; the random tiny model scores something valid.
    assert!(score(&truth).contains("4 photos: mIoU 100.00%, pixel accuracy 100.00%"));
    let out = score(&labels);
    assert!(
        out.starts_with("4 photos: mIoU ") && !out.contains("100.00%"),
        "{out}"
    );
}

#[test]
fn the_paper_pipeline_with_segment_weights_labels_its_photos_and_exports_them() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = scene(tmp.path());
    let paper = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../pipelines/paper.toml");
    let small = tmp.path().join("small.toml");
    let text = std::fs::read_to_string(&paper).unwrap();
    assert!(text.contains("segment_size = 512") && text.contains("semantics = false"));
    std::fs::write(
        &small,
        text.replace("val = 100", "val = 1")
            .replace("min_dim = 600", "min_dim = 96")
            .replace("min_photo_side = 450", "min_photo_side = 100")
            .replace("max_empty = 0.85", "max_empty = 1.0")
            .replace("segment_size = 512", "segment_size = 64")
            .replace("semantics = false", "semantics = false\ncrop = \"none\"")
            .replace("\"vgg16-512\"", "\"color-stats\""),
    )
    .unwrap();
    let out = tmp.path().join("run");
    let model = tiny_model();
    let o = super::nrw(&[
        "run",
        small.to_str().unwrap(),
        scene.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--segment-weights",
        model.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let seg = walk(&out.join("export"))
        .into_iter()
        .filter(|p| p.to_string_lossy().ends_with("_seg_rgb.png"))
        .count();
    assert_eq!(seg, 4, "every exported photo has its semantic map");
    let manifest = std::fs::read_to_string(out.join("manifest.json")).unwrap();
    assert!(manifest.contains("segment_model_sha256") && manifest.contains("resize 64x64"));
}

#[test]
fn an_unreadable_photo_is_a_warning_without_a_map_and_an_error_with_strict() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = scene(tmp.path());
    let mut photos = walk(&scene.join("images"));
    photos.sort();
    let bad = &photos[1];
    let bytes = std::fs::read(bad).unwrap();
    std::fs::write(bad, &bytes[..bytes.len() / 2]).unwrap();
    let labels = tmp.path().join("labels");
    let s = segment(&scene, &labels, &[]);
    assert_eq!(
        (
            s["segmented"].as_u64(),
            s["unreadable"].as_array().map(|a| a.len())
        ),
        (Some(3), Some(1))
    );
    let name = bad.file_name().unwrap().to_string_lossy().to_string();
    assert!(s["unreadable"][0].as_str().unwrap().contains(&name), "{s}");
    assert_eq!(pngs(&labels).len(), 3, "no map for the unreadable photo");
    let model = tiny_model();
    let strict = tmp.path().join("strict");
    let e = fails(&args(
        &scene,
        &model,
        &strict,
        &["--size", "64", "--strict"],
    ));
    assert!(e.contains(&name), "{e}");
}

#[test]
fn real_photos_of_every_size_segment_in_every_mode() {
    let Some(_) = super::shared::shared("data") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let scene = super::data().join("sacre_coeur");
    for (mode, size) in [
        ("resize", "512"),
        ("whole", "256"),
        ("slide", "128"),
        ("crop", "512"),
    ] {
        let out = tmp.path().join(mode);
        let s = segment(&scene, &out, &["--mode", mode, "--size", size]);
        assert_eq!(s["segmented"].as_u64(), Some(10), "{mode}");
        for rel in pngs(&out) {
            let map = image::open(out.join(&rel)).unwrap().to_luma8();
            let photo = walk(&scene.join("images"))
                .into_iter()
                .find(|p| p.file_stem() == rel.file_stem())
                .unwrap();
            let (w, h) = image::image_dimensions(&photo).unwrap();
            assert_eq!(map.dimensions(), (w, h), "{mode} {}", rel.display());
            let (x0, y0) = ((w - 512) / 2, (h - 512) / 2);
            for (x, y, v) in map.enumerate_pixels() {
                let inside = (x0..x0 + 512).contains(&x) && (y0..y0 + 512).contains(&y);
                let want_label = mode != "crop" || inside;
                assert_eq!(v[0] > 0, want_label, "{mode} {} ({x}, {y})", rel.display());
            }
        }
    }
}
