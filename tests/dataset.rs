//! `split` and the dataset reader: the split's reproducibility, the reader's aligned crops, the Python example.

use super::*;

fn split_of(ds: &Path) -> std::collections::BTreeMap<String, String> {
    nrw_dataset::split::read_splits(&nrw_dataset::Store::from(ds))
        .unwrap()
        .into_iter()
        .map(|a| (a.name, a.split))
        .collect()
}

#[test]
fn split_is_reproducible_exact_and_incremental() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = small_dataset(tmp.path(), 9, false);
    let copy = tmp.path().join("copy");
    std::fs::create_dir_all(&copy).unwrap();
    for f in walk(&ds) {
        let rel = f.strip_prefix(&ds).unwrap();
        std::fs::create_dir_all(copy.join(rel).parent().unwrap()).unwrap();
        std::fs::copy(&f, copy.join(rel)).unwrap();
    }
    ok(&["split", ds.to_str().unwrap(), "--val", "3", "--seed", "11"]);
    ok(&[
        "split",
        copy.to_str().unwrap(),
        "--val",
        "3",
        "--seed",
        "11",
    ]);
    assert_eq!(
        std::fs::read(ds.join("splits.parquet")).unwrap(),
        std::fs::read(copy.join("splits.parquet")).unwrap()
    );
    let first = split_of(&ds);
    assert_eq!(first.len(), 9);
    assert_eq!(first.values().filter(|s| *s == "val").count(), 3);
    let v: serde_json::Value =
        serde_json::from_str(&ok(&["inspect", ds.to_str().unwrap(), "--json"])).unwrap();
    assert_eq!(
        (v["splits"]["train"].as_u64(), v["splits"]["val"].as_u64()),
        (Some(6), Some(3))
    );

    // The same scene with three more photos (the generator draws photos in order, so the
    // first nine are identical), ingested into the same dataset, then split again.
    let bigger = small_dataset(tmp.path(), 12, false);
    std::fs::copy(ds.join("splits.parquet"), bigger.join("splits.parquet")).unwrap();
    ok(&[
        "split",
        bigger.to_str().unwrap(),
        "--val",
        "4",
        "--seed",
        "99",
    ]);
    let second = split_of(&bigger);
    assert_eq!(second.len(), 12);
    for (name, s) in &first {
        assert_eq!(&second[name], s, "{name} moved from {s}");
    }
    assert_eq!(second.values().filter(|s| *s == "val").count(), 4);
    let err = fails(&["split", bigger.to_str().unwrap(), "--val", "40"]);
    assert!(
        err.contains("--val 40") && err.contains("only 0 unassigned") && err.contains("12 kept"),
        "{err}"
    );
    let err = fails(&["split", bigger.to_str().unwrap(), "--val", "2"]);
    assert!(
        err.contains("4 validation photos already assigned"),
        "{err}"
    );
}

#[test]
fn reader_streams_a_split_and_crops_every_channel_at_one_place() {
    use nrw_dataset::reader::Dataset;
    let tmp = tempfile::tempdir().unwrap();
    let ds_dir = small_dataset(tmp.path(), 9, true);
    ok(&[
        "split",
        ds_dir.to_str().unwrap(),
        "--val",
        "2",
        "--seed",
        "5",
    ]);
    let ds = Dataset::open(&ds_dir).unwrap();
    let want: Vec<u32> = ds.ids("val").unwrap().to_vec();
    let got: Vec<u32> = ds
        .iter_split("val")
        .unwrap()
        .map(|v| v.unwrap().image_id)
        .collect();
    assert_eq!(got, want);
    let train: Vec<u32> = ds
        .iter_split("train")
        .unwrap()
        .map(|v| v.unwrap().image_id)
        .collect();
    assert_eq!(train.len(), 7);
    assert!(
        train.iter().all(|id| !want.contains(id)),
        "splits are disjoint"
    );
    let v = ds.get(train[3]).unwrap();
    assert_eq!(v.image_id, train[3]);
    let (photo, color, depth) = (v.photo().unwrap(), v.color().unwrap(), v.depth().unwrap());
    let c = v.crop_at(7, 5, 64).unwrap();
    for y in 0..64u32 {
        for x in 0..64u32 {
            assert_eq!(c.photo.get_pixel(x, y), photo.get_pixel(x + 7, y + 5));
            assert_eq!(c.color.get_pixel(x, y), color.get_pixel(x + 7, y + 5));
            let d = c.depth[(y * 64 + x) as usize];
            assert_eq!(d, depth.data[((y + 5) * v.width + x + 7) as usize]);
            assert_eq!(
                d > 0.0,
                c.color.get_pixel(x, y)[3] == 255,
                "alpha is coverage inside the crop"
            );
        }
    }
    assert!(c.semantics.is_some() && c.transient.is_some());
    let too_big = v.crop_at(0, 0, 4096).unwrap_err().to_string();
    assert!(too_big.contains("does not fit"), "{too_big}");
    assert!(ds
        .get(999_999)
        .unwrap_err()
        .to_string()
        .contains("not a kept view"));
    // Another schema version is refused with a clear message.
    let m = ds_dir.join("manifest.json");
    let text = std::fs::read_to_string(&m).unwrap().replace(
        &format!("\"schema_version\": {}", nrw_dataset::SCHEMA_VERSION),
        "\"schema_version\": 7",
    );
    std::fs::write(&m, text).unwrap();
    let e = Dataset::open(&ds_dir).unwrap_err().to_string();
    assert!(
        e.contains("schema version 7") && e.contains("re-run ingest"),
        "{e}"
    );
}

#[test]
fn the_twenty_line_python_example_yields_aligned_training_tensors() {
    if !python_has("import pyarrow, OpenEXR, PIL, numpy") {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let ds = small_dataset(tmp.path(), 5, false);
    ok(&["split", ds.to_str().unwrap(), "--val", "1"]);
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/python_reader.py");
    assert!(
        std::fs::read_to_string(&script).unwrap().lines().count() <= 20,
        "the issue asks for a 20-line example"
    );
    let o = Command::new("python3")
        .arg(&script)
        .arg(&ds)
        .arg("64")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8(o.stdout).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 4, "the 4 training views: {text}");
    for l in lines {
        assert!(l.contains("(64, 64, 3) (64, 64, 4) (64, 64, 1)"), "{l}");
    }
}
