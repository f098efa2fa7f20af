//! The bad-input catalogue (docs/bad-inputs.md): each row's input, made here, and what the
//! user sees. Photos that cannot be decoded whole are dropped as `unreadable` (or stop the
//! run under --strict); a flipped payload byte stops every reader, naming file, row and
//! column; output that cannot be written is an error naming the path, and leaves nothing.

use super::*;
use nrw_dataset::reader::Dataset;

/// `scene/images.parquet` as image name → (verdict, verdict_detail).
fn verdicts(ds: &Path) -> std::collections::BTreeMap<String, (String, Option<String>)> {
    let store = nrw_dataset::Store::from(ds);
    let mut out = std::collections::BTreeMap::new();
    for b in nrw_dataset::parquet_io::read_batches(
        &store,
        nrw_dataset::IMAGES_TABLE,
        Some(&["name", "verdict", "verdict_detail"]),
    )
    .unwrap()
    {
        let names: &arrow_array::StringArray = column(&b, "name");
        let v: &arrow_array::StringArray = column(&b, "verdict");
        let d: &arrow_array::StringArray = column(&b, "verdict_detail");
        for i in 0..b.num_rows() {
            use arrow_array::Array;
            let detail = (!d.is_null(i)).then(|| d.value(i).to_string());
            out.insert(names.value(i).into(), (v.value(i).into(), detail));
        }
    }
    out
}

/// A copy of a scene folder with its own copies of the photos (the model and cloud are
/// linked), so single photos can be replaced. The photos are copied, not linked: a photo
/// linking out of the images folder is refused by ingest.
fn scene_with_own_photos(src: &Path, dst: &Path) {
    std::fs::create_dir_all(dst.join("images")).unwrap();
    for entry in std::fs::read_dir(src).unwrap() {
        let p = entry.unwrap().path();
        let name = p.file_name().unwrap();
        if name != "images" {
            std::os::unix::fs::symlink(&p, dst.join(name)).unwrap();
        }
    }
    for entry in std::fs::read_dir(src.join("images")).unwrap() {
        let p = entry.unwrap().path();
        std::fs::copy(&p, dst.join("images").join(p.file_name().unwrap())).unwrap();
    }
}

/// Replace one photo of a scene made by [`scene_with_own_photos`] with these bytes.
fn replace_photo(scene: &Path, name: &str, bytes: &[u8]) {
    let p = scene.join("images").join(name);
    std::fs::remove_file(&p).unwrap();
    std::fs::write(&p, bytes).unwrap();
}

#[test]
fn a_truncated_jpeg_is_dropped_as_unreadable_and_every_other_view_stays_intact() {
    let Some(src) = shared::shared("data/sceaux_castle") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let good = tmp.path().join("good");
    let o = nrw(&[
        "ingest",
        src.to_str().unwrap(),
        "--out",
        good.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let before = verdicts(&good);
    let kept: Vec<String> = before
        .iter()
        .filter(|(_, (v, _))| v == "kept")
        .map(|(n, _)| n.clone())
        .collect();
    // The measured case, the JPEG cut to its first 5,000 bytes (inside its EXIF header
    // here), and one cut in the middle of its pixel data.
    let (victim, halved) = (kept[0].clone(), kept[1].clone());
    let scene = tmp.path().join("scene");
    scene_with_own_photos(&src, &scene);
    let whole = std::fs::read(src.join("images").join(&victim)).unwrap();
    replace_photo(&scene, &victim, &whole[..5000]);
    let whole = std::fs::read(src.join("images").join(&halved)).unwrap();
    replace_photo(&scene, &halved, &whole[..whole.len() / 2]);
    let bad = tmp.path().join("bad");
    let o = nrw(&[
        "ingest",
        scene.to_str().unwrap(),
        "--out",
        bad.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let after = verdicts(&bad);
    for (name, says) in [(&victim, "Not enough bytes"), (&halved, "JPEG data")] {
        let (verdict, detail) = &after[name];
        assert_eq!(verdict, "unreadable", "{name}");
        assert!(
            detail.as_deref().is_some_and(|d| d.contains(says)),
            "{name}: {detail:?}"
        );
    }
    // Every other view: same verdict, and the same bytes in every column of its row.
    let (g, b) = (
        Dataset::open(good.as_path()).unwrap(),
        Dataset::open(bad.as_path()).unwrap(),
    );
    assert_eq!(b.len() + 2, g.len());
    for (name, v) in &before {
        if name == &victim || name == &halved {
            continue;
        }
        assert_eq!(&after[name], v, "{name}");
    }
    for id in g.ids("all").unwrap() {
        let view = g.get(*id).unwrap();
        if view.name != victim && view.name != halved {
            assert!(b.get(*id).unwrap() == view, "{} changed", view.name);
        }
    }
    // QA names the file and the decoder's message.
    let d = bad.to_str().unwrap();
    ok(&["qa", d]);
    let html = std::fs::read_to_string(bad.join("qa/report.html")).unwrap();
    assert!(html.contains(&halved) && html.contains("JPEG data: "), "QA");

    // --strict: exit 1 naming the file, and no dataset.
    let strict = tmp.path().join("strict");
    let o = nrw(&[
        "ingest",
        scene.to_str().unwrap(),
        "--out",
        strict.to_str().unwrap(),
        "--quiet",
        "--strict",
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains(&victim) && err.contains("unreadable"), "{err}");
    assert!(!strict.join("manifest.json").exists());
}

/// Encode an image in a format (the test's own photo variants).
fn encoded(img: &image::DynamicImage, format: image::ImageFormat) -> Vec<u8> {
    let mut out = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut out), format)
        .unwrap();
    out
}

/// A JPEG written by Pillow (CMYK, or with an EXIF orientation tag), when Pillow is there.
fn pillow_jpeg(photo: &Path, out: &Path, script: &str) -> bool {
    if !python_has("import PIL") {
        return false;
    }
    let code = format!(
        "from PIL import Image\nimport sys\nim = Image.open(sys.argv[1]).convert('RGB')\n{script}"
    );
    let o = Command::new("python3")
        .args(["-c", &code, photo.to_str().unwrap(), out.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    true
}

#[test]
fn photo_variants_are_kept_converted_or_dropped_with_their_reason() {
    let tmp = tempfile::tempdir().unwrap();
    let src = tmp.path().join("src");
    small_scene(&src, 9);
    let scene = tmp.path().join("scene");
    scene_with_own_photos(&src, &scene);
    let mut names: Vec<String> = std::fs::read_dir(src.join("images"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    let photo = |n: &str| image::open(src.join("images").join(n)).unwrap();
    let rgb = |n: &str| photo(n).into_rgb8();
    let png = encoded(&photo(&names[1]), image::ImageFormat::Png);
    // Unreadable: empty, not an image, truncated PNG.
    replace_photo(&scene, &names[0], b"");
    replace_photo(&scene, &names[1], &png[..png.len() / 2]);
    replace_photo(&scene, &names[2], b"<html>404 Not Found</html>");
    // Kept, converted to RGB8: 16-bit, grey, with alpha.
    let p3 = photo(&names[3]);
    replace_photo(
        &scene,
        &names[3],
        &encoded(
            &image::DynamicImage::ImageRgb16(p3.to_rgb16()),
            image::ImageFormat::Png,
        ),
    );
    let grey = image::DynamicImage::ImageLuma8(photo(&names[4]).into_luma8());
    replace_photo(&scene, &names[4], &encoded(&grey, image::ImageFormat::Png));
    let mut rgba = photo(&names[5]).into_rgba8();
    rgba.pixels_mut().for_each(|p| p[3] = 7);
    replace_photo(
        &scene,
        &names[5],
        &encoded(
            &image::DynamicImage::ImageRgba8(rgba),
            image::ImageFormat::Png,
        ),
    );
    // CMYK and EXIF-rotated JPEGs (Pillow writes both; CI has it).
    let tagged = tmp.path().join("tagged.jpg");
    let cmyk = tmp.path().join("cmyk.jpg");
    let have_pillow = pillow_jpeg(
        &src.join("images").join(&names[6]),
        &cmyk,
        "im.convert('CMYK').save(sys.argv[2], quality=95)",
    ) && pillow_jpeg(
        &src.join("images").join(&names[7]),
        &tagged,
        "ex = Image.Exif(); ex[0x0112] = 6\nim.save(sys.argv[2], quality=95, exif=ex)",
    );
    if have_pillow {
        replace_photo(&scene, &names[6], &std::fs::read(&cmyk).unwrap());
        replace_photo(&scene, &names[7], &std::fs::read(&tagged).unwrap());
    } else {
        assert!(
            std::env::var("CI").is_err(),
            "CI must have Pillow for the CMYK and EXIF rows"
        );
        eprintln!("skipped the CMYK and EXIF rows: no Pillow");
    }
    // Larger than its camera with the same aspect ratio: rescaled, with a warning.
    let p8 = photo(&names[8]);
    let big = p8.resize_exact(
        p8.width() * 3 / 2,
        p8.height() * 3 / 2,
        image::imageops::FilterType::Triangle,
    );
    replace_photo(&scene, &names[8], &encoded(&big, image::ImageFormat::Png));
    let ds = tmp.path().join("ds");
    let o = ingest_small(&scene, &ds, &["--max-empty", "1.0", "--quiet", "--json"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(summary["unreadable"], 3, "{summary}");
    let warnings = summary["warnings"].to_string();
    for n in &names[..3] {
        assert!(
            warnings.contains(&format!("{n}: unreadable, left out")),
            "{warnings}"
        );
    }
    assert!(
        warnings.contains(&names[8]) && warnings.contains("same aspect ratio, rescaled"),
        "{warnings}"
    );
    let v = verdicts(&ds);
    assert_eq!(v[&names[8]].0, "kept");
    let reason = |n: &str| {
        let (verdict, detail) = &v[n];
        assert_eq!(verdict, "unreadable", "{n}");
        detail.clone().unwrap()
    };
    assert!(reason(&names[0]).contains("empty"));
    assert!(
        reason(&names[1]).contains("Png data"),
        "{}",
        reason(&names[1])
    );
    assert!(reason(&names[2]).contains("not a JPEG or PNG"));
    let data = Dataset::open(ds.as_path()).unwrap();
    let stored = |n: &str| {
        let id = data
            .ids("all")
            .unwrap()
            .iter()
            .copied()
            .find(|id| data.get(*id).unwrap().name == n)
            .unwrap_or_else(|| panic!("{n} not kept"));
        data.get(id).unwrap().photo().unwrap()
    };
    // 16-bit: the 8-bit values the photo had (the render size equals the photo size here
    // only when no resize happens, so compare through the same resize).
    let same_size = |img: &image::RgbImage, n: &str| {
        let s = stored(n);
        nrw_dataset::codec::resize_photo(img, s.width(), s.height())
    };
    assert_eq!(stored(&names[3]), same_size(&rgb(&names[3]), &names[3]));
    let g = stored(&names[4]);
    assert!(g.pixels().all(|p| p[0] == p[1] && p[1] == p[2]), "grey");
    assert_eq!(
        stored(&names[5]),
        same_size(&rgb(&names[5]), &names[5]),
        "alpha dropped"
    );
    if have_pillow {
        // CMYK decodes to RGB close to the original; the EXIF tag is ignored as COLMAP
        // ignores it (the stored photo has the file's own orientation and size).
        let c = stored(&names[6]);
        let o = same_size(&rgb(&names[6]), &names[6]);
        let mean: f64 = c
            .as_raw()
            .iter()
            .zip(o.as_raw())
            .map(|(a, b)| (*a as f64 - *b as f64).abs())
            .sum::<f64>()
            / c.as_raw().len() as f64;
        assert!(mean < 12.0, "CMYK photo off by {mean:.1} levels on average");
        let t = stored(&names[7]);
        assert_eq!(
            t.dimensions(),
            same_size(&rgb(&names[7]), &names[7]).dimensions()
        );
    }
    // --strict stops at the first unreadable photo, naming it.
    let o = ingest_small(
        &scene,
        &tmp.path().join("strict"),
        &["--max-empty", "1.0", "--quiet", "--strict"],
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains(&names[0]) && err.contains("empty"), "{err}");
    // Another aspect ratio than its camera: the model does not describe this photo.
    let cropped = p8.crop_imm(0, 0, p8.width(), p8.height() / 2);
    replace_photo(
        &scene,
        &names[8],
        &encoded(&cropped, image::ImageFormat::Png),
    );
    let o = ingest_small(&scene, &tmp.path().join("aspect"), &["--quiet"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains(&names[8]) && err.contains("another aspect ratio"),
        "{err}"
    );
}

/// Offset of `needle` in `hay` (payloads are stored uncompressed, so their bytes are there).
fn find(hay: &[u8], needle: &[u8]) -> usize {
    hay.windows(needle.len())
        .position(|w| w == needle)
        .expect("payload bytes are stored as they are")
}

/// A copy of `ds` with one byte flipped in the middle of `payload` inside `rel`.
fn flipped(ds: &Path, to: &Path, rel: &str, payload: &[u8]) {
    let _ = std::fs::remove_dir_all(to);
    for f in walk(ds) {
        let dst = to.join(f.strip_prefix(ds).unwrap());
        std::fs::create_dir_all(dst.parent().unwrap()).unwrap();
        std::fs::copy(&f, &dst).unwrap();
    }
    let file = to.join(rel);
    let mut bytes = std::fs::read(&file).unwrap();
    let at = find(&bytes, payload) + payload.len() / 2;
    bytes[at] ^= 0x10;
    std::fs::write(&file, bytes).unwrap();
}

/// The error every reader must give: file, row and column.
fn assert_named(err: &str, rel: &str, column: &str, who: &str) {
    assert!(
        err.contains(rel) && err.contains("row 0 (image") && err.contains(&format!("`{column}`")),
        "{who} did not name {rel}, row 0 and {column}: {err}"
    );
}

#[test]
fn a_flipped_byte_in_any_payload_column_stops_verify_and_every_reader() {
    use nrw_trainer::{Loader, LoaderConfig};
    let tmp = tempfile::tempdir().unwrap();
    let ds = small_dataset(tmp.path(), 6, true);
    let d = ds.to_str().unwrap();
    ok(&["split", d, "--val", "2"]);
    let data = Dataset::open(ds.as_path()).unwrap();
    // Shard rows are in image-id order: row 0 holds the smallest id of either split.
    let all: Vec<u32> = ["train", "val"]
        .iter()
        .flat_map(|s| data.ids(s).unwrap().to_vec())
        .collect();
    let first = data.get(*all.iter().min().unwrap()).unwrap();
    let split = ["train", "val"]
        .into_iter()
        .find(|s| data.ids(s).unwrap().contains(&first.image_id))
        .unwrap();
    let shard = "shards/views-00000.parquet";
    let mut columns = vec![
        ("photo_png", first.photo_png.clone()),
        ("color_png", first.color_png.clone()),
        ("depth_exr", first.depth_exr.clone()),
        ("semantics_png", first.semantics_png.clone().unwrap()),
        ("transient_png", first.transient_png.clone().unwrap()),
        ("labels_png", first.labels_png.clone().unwrap()),
    ];
    if let Some(n) = &first.normal_png {
        columns.push(("normal_png", n.clone()));
    }
    let bad = tmp.path().join("bad");
    let b = bad.to_str().unwrap();
    let exp = tmp.path().join("exp");
    let e = exp.to_str().unwrap();
    for (column, payload) in &columns {
        flipped(&ds, &bad, shard, payload);
        let o = nrw(&["verify", b, "--quiet"]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(4), "{err}");
        assert!(
            err.contains(shard) && err.contains(&format!("{column} at row 0 (image")),
            "verify: {err}"
        );
        for (who, args) in [
            (
                "style",
                vec!["style", b, "--tier", "color-stats", "--quiet"],
            ),
            (
                "export files",
                vec!["export", b, "--layout", "files", "--out", e, "--quiet"],
            ),
            (
                "export official",
                vec!["export", b, "--out", e, "--crop", "none", "--quiet"],
            ),
            ("qa", vec!["qa", b]),
        ] {
            assert_named(&fails(&args), shard, column, who);
        }
        let opened = Dataset::open(bad.as_path()).unwrap();
        let cfg = LoaderConfig {
            crop: 32,
            batch: 2,
            seed: 1,
            semantics: true,
        };
        let err = Loader::new(&opened, split, cfg)
            .unwrap()
            .epoch(0)
            .find_map(|b| b.err())
            .expect("the trainer's loader fails")
            .to_string();
        assert_named(&err, shard, column, "trainer loader");
    }

    // Descriptors: verify, triplets and qa.
    ok(&["style", d, "--tier", "color-stats", "--quiet"]);
    let (_, rows) = nrw_dataset::descriptors::read_all(&nrw_dataset::Store::from(ds.as_path()))
        .unwrap()
        .unwrap();
    let values: Vec<u8> = rows[0]
        .descriptor
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let part = "descriptors/part-00000.parquet";
    flipped(&ds, &bad, part, &values);
    let o = nrw(&["verify", b, "--quiet"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(4), "{err}");
    assert!(
        err.contains(part) && err.contains("descriptor at row 0"),
        "{err}"
    );
    assert_named(
        &fails(&["triplets", b, "--k", "2"]),
        part,
        "descriptor",
        "triplets",
    );
    assert_named(&fails(&["qa", b]), part, "descriptor", "qa");

    // Whole small tables (triplets, scene tables) are checked against the manifest's SHA-256
    // by the readers that read them whole: QA and the trainer's triplet sampler.
    ok(&["triplets", d, "--k", "2"]);
    for rel in ["triplets.parquet", "scene/images.parquet"] {
        let whole = std::fs::read(ds.join(rel)).unwrap();
        flipped(&ds, &bad, rel, &whole[whole.len() / 3..whole.len() / 3 + 8]);
        let err = fails(&["qa", b]);
        assert!(err.contains(rel) && err.contains("sha256"), "qa: {err}");
    }
    let err = nrw_dataset::triplets::read_triplets(&nrw_dataset::Store::from(bad.as_path()));
    assert!(err.is_ok(), "the last copy damaged only the images table");
    flipped(
        &ds,
        &bad,
        "triplets.parquet",
        &std::fs::read(ds.join("triplets.parquet")).unwrap()[100..108],
    );
    let err = nrw_dataset::triplets::read_triplets(&nrw_dataset::Store::from(bad.as_path()))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("triplets.parquet") && err.contains("sha256"),
        "{err}"
    );
}

/// Mount a small tmpfs at `at` (root only; the CI machine runs as root).
fn tmpfs(at: &Path, options: &str) -> bool {
    std::fs::create_dir_all(at).unwrap();
    let o = Command::new("mount")
        .args(["-t", "tmpfs", "-o", options, "tmpfs", at.to_str().unwrap()])
        .output();
    let mounted = o.is_ok_and(|o| o.status.success());
    if !mounted {
        // .ci/run sets NRW_REQUIRE_TMPFS=1 itself, so CI cannot skip these rows whatever
        // its environment says.
        assert!(
            std::env::var("NRW_REQUIRE_TMPFS").map_or(true, |v| v != "1")
                && std::env::var("CI").is_err(),
            "NRW_REQUIRE_TMPFS=1 (or CI): this machine runs as root and must be able to mount a tmpfs"
        );
        eprintln!("skipped: cannot mount a tmpfs here (not root; CI requires it)");
    }
    mounted
}

fn umount(at: &Path) {
    let _ = Command::new("umount").arg(at).status();
}

#[test]
fn output_that_cannot_be_written_is_an_error_naming_the_path_and_leaves_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("scene");
    small_scene(&scene, 4);
    // --out is a file.
    let file = tmp.path().join("a-file");
    std::fs::write(&file, b"x").unwrap();
    let o = ingest_small(&scene, &file, &["--quiet"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("a-file"), "{err}");
    // A read-only file system.
    let ro = tmp.path().join("ro");
    if tmpfs(&ro, "size=1m,ro") {
        let o = ingest_small(&scene, &ro.join("ds"), &["--quiet"]);
        umount(&ro);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{err}");
        assert!(err.contains("ro/ds") && err.contains("Read-only"), "{err}");
    }
    // A disk that fills up part-way: the write error names the file, no temporary file or
    // manifest is left behind, and the same command on a disk with room finishes.
    let full = tmp.path().join("full");
    if tmpfs(&full, "size=160k") {
        let out = full.join("ds");
        let o = ingest_small(&scene, &out, &["--quiet", "--rows-per-shard", "1"]);
        let err = String::from_utf8_lossy(&o.stderr);
        let left: Vec<PathBuf> = walk(&full)
            .into_iter()
            .filter(|p| p.to_string_lossy().ends_with(".tmp") || p.ends_with("manifest.json"))
            .collect();
        umount(&full);
        assert_eq!(o.status.code(), Some(1), "{err}");
        assert!(
            err.contains("No space left on device") && err.contains("ds/"),
            "{err}"
        );
        assert!(left.is_empty(), "left behind: {left:?}");
    }
}

/// Run a command, SIGKILL it once `ready` sees its output begin, then return; `ready` must
/// see it before the command ends on its own.
fn kill_when(mut cmd: Command, ready: &dyn Fn() -> bool) {
    let mut child = cmd
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let t0 = std::time::Instant::now();
    while !ready() {
        assert!(t0.elapsed().as_secs() < 120, "{cmd:?}: never ready");
        assert!(
            child.try_wait().unwrap().is_none(),
            "{cmd:?} ended before it was killed"
        );
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    assert!(child.try_wait().unwrap().is_none(), "{cmd:?} still running");
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
}

/// Run a command that pauses before each commit (the hidden `--pause-before-commit-ms`),
/// and SIGKILL it during its `n`th pause: its output of that commit is written but not yet
/// in place. Returns the target it was about to commit.
fn kill_at_commit(mut cmd: Command, n: usize) -> String {
    use std::io::BufRead;
    let mut child = cmd
        // Every commit pauses, so a short pause: long enough to kill in, short enough for
        // the commits before the `n`th.
        .args(["--pause-before-commit-ms", "2000"])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let lines = std::io::BufReader::new(child.stderr.take().unwrap()).lines();
    let mut seen = 0;
    for line in lines {
        let line = line.unwrap();
        let Some((_, target)) = line.split_once(" before committing ") else {
            continue;
        };
        seen += 1;
        if seen == n {
            assert!(
                child.try_wait().unwrap().is_none(),
                "{cmd:?} still running at commit {n}"
            );
            child.kill().unwrap(); // SIGKILL
            child.wait().unwrap();
            return target.to_string();
        }
    }
    panic!(
        "{cmd:?} ended after {seen} commits, before commit {n}: {:?}",
        child.wait()
    );
}

/// `(written, already there)` from a style run's summary line.
fn style_parts(stderr: &str) -> (usize, usize) {
    let tail = stderr.rsplit_once('(').expect("summary").1;
    let n: Vec<usize> = tail
        .split(|c: char| !c.is_ascii_digit())
        .filter(|t| !t.is_empty())
        .map(|t| t.parse().unwrap())
        .collect();
    (n[0], n[1])
}

#[test]
fn stages_killed_with_sigkill_then_rerun_write_the_same_bytes() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("scene");
    small_scene(&scene, 8);
    let run_all = |ds: &Path, kill: bool| {
        let d = ds.to_str().unwrap();
        let exp = format!("{d}-export");
        let s = scene.to_str().unwrap();
        let ingest = [
            "ingest",
            s,
            "--out",
            d,
            "--min-dim",
            "96",
            "--min-photo-side",
            "100",
            "--max-empty",
            "1.0",
            "--rows-per-shard",
            "2",
            "--quiet",
        ];
        let style = [
            "style",
            d,
            "--tier",
            "color-stats",
            "--photos-per-part",
            "2",
        ];
        // Each stage with the commits it is killed at (1 = during its first).
        let stages: Vec<(Vec<&str>, &[usize])> = vec![
            (vec!["split", d, "--val", "2"], &[1, 2]),
            (style.to_vec(), &[1, 3]),
            (vec!["triplets", d, "--k", "2"], &[1, 2]),
            (
                vec!["export", d, "--layout", "files", "--out", &exp, "--quiet"],
                &[1],
            ),
        ];
        if kill {
            // Ingest is killed once its first group is recorded (it pauses after each).
            let mut cmd = Command::new(env!("CARGO_BIN_EXE_nrw-etl"));
            cmd.args(ingest).args(["--pause-after-group-ms", "1000"]);
            let records = ds.join(".units/ingest");
            kill_when(cmd, &|| {
                records.read_dir().is_ok_and(|d| {
                    d.flatten()
                        .any(|e| e.file_name().to_string_lossy().starts_with("group-"))
                })
            });
            let o = nrw(&[&ingest[..ingest.len() - 1], &["--json"]].concat());
            assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
            let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
            assert!(j["resumed_groups"].as_u64().unwrap() >= 1, "{j}");
        } else {
            ok(&ingest);
        }
        for (args, commits) in stages {
            if kill {
                for &n in commits {
                    let mut cmd = Command::new(env!("CARGO_BIN_EXE_nrw-etl"));
                    cmd.args(&args);
                    let target = kill_at_commit(cmd, n);
                    assert!(
                        target.starts_with(d),
                        "{args:?} commits inside its output: {target}"
                    );
                }
            }
            let o = nrw(&args);
            assert!(
                o.status.success(),
                "{args:?}: {}",
                String::from_utf8_lossy(&o.stderr)
            );
            if kill && args[0] == "style" {
                // Killed during its third commit, two parts were in place: the rerun
                // describes only the rest.
                let (written, there) = style_parts(&String::from_utf8_lossy(&o.stderr));
                assert!(there >= 2 && written + there == 4, "{written} {there}");
            }
        }
    };
    let (clean, killed) = (tmp.path().join("clean"), tmp.path().join("killed"));
    run_all(&clean, false);
    run_all(&killed, true);
    let strip = |m: std::collections::BTreeMap<PathBuf, Vec<u8>>| {
        m.into_iter()
            .filter(|(k, _)| !k.starts_with(".units"))
            .collect::<std::collections::BTreeMap<_, _>>()
    };
    assert_same_files(
        &strip(files(&clean)),
        &strip(files(&killed)),
        "killed and rerun",
    );
    // The export names its dataset's folder; otherwise the bytes are the same.
    let mut clean_export = files(&tmp.path().join("clean-export"));
    let mut killed_export = files(&tmp.path().join("killed-export"));
    let record = Path::new(nrw_export::EXPORT_JSON);
    let text = |b: Vec<u8>| String::from_utf8(b).unwrap();
    assert_eq!(
        text(clean_export.remove(record).expect("export.json")),
        text(killed_export.remove(record).expect("export.json")).replace("killed", "clean"),
    );
    assert_same_files(&clean_export, &killed_export, "export killed and rerun");
    assert_eq!(verify_code(&killed), Some(0));
}

fn verify_code(ds: &Path) -> Option<i32> {
    nrw(&["verify", ds.to_str().unwrap(), "--quiet"])
        .status
        .code()
}

#[test]
fn label_maps_of_the_wrong_size_or_classes_are_errors_and_corrupt_ones_unreadable() {
    let tmp = tempfile::tempdir().unwrap();
    let src = tmp.path().join("src");
    small_scene(&src, 4);
    let labels = src.join("ground_truth/semantics");
    let mut maps: Vec<PathBuf> = std::fs::read_dir(&labels)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    maps.sort();
    let copy = |to: &Path| {
        std::fs::create_dir_all(to).unwrap();
        for m in &maps {
            std::fs::copy(m, to.join(m.file_name().unwrap())).unwrap();
        }
    };
    let run = |dir: &Path| {
        let d = dir.to_str().unwrap();
        let out = tmp
            .path()
            .join(format!("ds-{}", dir.file_name().unwrap().to_string_lossy()));
        ingest_small(
            &src,
            &out,
            &["--max-empty", "1.0", "--quiet", "--semantics", d],
        )
    };
    let first = maps[0].file_name().unwrap().to_string_lossy().into_owned();
    let grey = image::open(&maps[0]).unwrap().into_luma8();
    // Another size than its photo.
    let wrong = tmp.path().join("wrong-size");
    copy(&wrong);
    image::imageops::resize(&grey, 17, 13, image::imageops::FilterType::Nearest)
        .save(wrong.join(&first))
        .unwrap();
    let o = run(&wrong);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains(&first) && err.contains("17x13"), "{err}");
    // A class id beyond ADE20K's 150.
    let ids = tmp.path().join("ids");
    copy(&ids);
    let mut high = grey.clone();
    high.put_pixel(3, 2, image::Luma([200]));
    high.save(ids.join(&first)).unwrap();
    let o = run(&ids);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains(&first) && err.contains("class id 200"),
        "{err}"
    );
    // Colour instead of class ids.
    let rgb = tmp.path().join("rgb");
    copy(&rgb);
    image::DynamicImage::ImageLuma8(grey.clone())
        .into_rgb8()
        .save(rgb.join(&first))
        .unwrap();
    let o = run(&rgb);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains(&first) && err.contains("8-bit single-channel"),
        "{err}"
    );
    // A truncated label map: its view is unreadable, the others are kept.
    let cut = tmp.path().join("cut");
    copy(&cut);
    let bytes = std::fs::read(&maps[0]).unwrap();
    std::fs::write(cut.join(&first), &bytes[..bytes.len() / 2]).unwrap();
    let o = run(&cut);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v = verdicts(&tmp.path().join("ds-cut"));
    let unreadable: Vec<_> = v.values().filter(|(v, _)| v == "unreadable").collect();
    assert_eq!(unreadable.len(), 1, "{v:?}");
    assert!(unreadable[0]
        .1
        .as_deref()
        .unwrap()
        .contains("label map (PNG)"));
    assert_eq!(v.values().filter(|(v, _)| v == "kept").count(), 3);
}

/// A safetensors file of the given F32 tensors (name, shape), zero-filled.
fn safetensors(tensors: &[(&str, Vec<usize>)]) -> Vec<u8> {
    let mut header = serde_json::Map::new();
    let mut at = 0usize;
    for (name, shape) in tensors {
        let n = shape.iter().product::<usize>() * 4;
        header.insert(
            name.to_string(),
            serde_json::json!({"dtype": "F32", "shape": shape, "data_offsets": [at, at + n]}),
        );
        at += n;
    }
    let h = serde_json::to_vec(&header).unwrap();
    let mut out = (h.len() as u64).to_le_bytes().to_vec();
    out.extend(h);
    out.resize(out.len() + at, 0);
    out
}

#[test]
fn weights_of_the_wrong_shape_or_cut_short_are_refused_naming_file_and_tensor() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = small_dataset(tmp.path(), 4, false);
    let d = ds.to_str().unwrap();
    let style = |w: &Path| {
        fails(&[
            "style",
            d,
            "--tier",
            "vgg16-128",
            "--weights",
            w.to_str().unwrap(),
            "--quiet",
        ])
    };
    let shaped = tmp.path().join("shaped.safetensors");
    std::fs::write(
        &shaped,
        safetensors(&[
            ("features.0.weight", vec![8, 3, 3, 3]),
            ("features.0.bias", vec![8]),
        ]),
    )
    .unwrap();
    let err = style(&shaped);
    assert!(
        err.contains("shaped.safetensors")
            && err.contains("features.0.weight")
            && err.contains("expected F32 [64, 3, 3, 3]"),
        "{err}"
    );
    let good = safetensors(&[
        ("features.0.weight", vec![64, 3, 3, 3]),
        ("features.0.bias", vec![64]),
    ]);
    let cut = tmp.path().join("cut.safetensors");
    std::fs::write(&cut, &good[..good.len() - 100]).unwrap();
    let err = style(&cut);
    assert!(
        err.contains("cut.safetensors") && err.contains("not a safetensors file"),
        "{err}"
    );
    // Whole but without the later layers: the first missing tensor is named.
    let short = tmp.path().join("short.safetensors");
    std::fs::write(&short, &good).unwrap();
    let err = style(&short);
    assert!(
        err.contains("features.2.weight") && err.contains("missing"),
        "{err}"
    );
    assert!(
        !ds.join("descriptors").exists(),
        "nothing written on refused weights"
    );
}

#[test]
fn an_edited_or_broken_manifest_is_named_by_verify_and_every_reader() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = small_dataset(tmp.path(), 4, false);
    let d = ds.to_str().unwrap();
    let m = ds.join("manifest.json");
    let text = std::fs::read_to_string(&m).unwrap();
    let manifest: serde_json::Value = serde_json::from_str(&text).unwrap();
    let sha = manifest["tables"][0]["sha256"]
        .as_str()
        .unwrap()
        .to_string();
    let file = manifest["tables"][0]["path"].as_str().unwrap().to_string();
    // A hash edited by hand: verify names the file whose bytes no longer match.
    std::fs::write(&m, text.replace(&sha, &"0".repeat(64))).unwrap();
    let o = nrw(&["verify", d, "--quiet"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(4), "{err}");
    assert!(err.contains(&format!("{file}: sha256")), "{err}");
    // Broken JSON: every command that opens the dataset names manifest.json and the place.
    std::fs::write(&m, &text[..text.len() / 2]).unwrap();
    for args in [
        vec!["verify", d, "--quiet"],
        vec!["split", d],
        vec!["qa", d],
        vec!["style", d, "--tier", "color-stats", "--quiet"],
    ] {
        let err = fails(&args);
        assert!(
            err.contains("manifest.json") && err.contains("line"),
            "{args:?}: {err}"
        );
    }
}
