//! `nrw-etl verify`: a good dataset (and one written by a resumed run) passes; a flipped
//! byte (with its payload's row and column), a truncated table and a missing shard are each
//! named, with exit code 4. Flips in every payload column: tests/bad_inputs.rs.

use super::*;

fn verify(ds: &Path) -> Output {
    nrw(&["verify", ds.to_str().unwrap(), "--quiet"])
}

#[test]
fn verify_passes_good_datasets_and_names_every_damaged_file() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("scene");
    small_scene(&scene, 9);
    let ds = tmp.path().join("ds");
    let d = ds.to_str().unwrap();
    let o = ingest_small(&scene, &ds, &["--rows-per-shard", "2", "--quiet"]);
    assert!(o.status.success());
    ok(&["split", d, "--val", "2"]);
    ok(&["style", d, "--tier", "color-stats", "--quiet"]);
    ok(&["triplets", d, "--k", "3"]);
    let o = verify(&ds);
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(String::from_utf8_lossy(&o.stdout).starts_with("verified"));

    // A dataset written into another folder by an interrupted, then resumed, run.
    let resumed = tmp.path().join("resumed");
    let o = ingest_small(
        &scene,
        &resumed,
        &[
            "--rows-per-shard",
            "2",
            "--quiet",
            // The flag's old name, kept as an alias (it is now --stop-after-groups).
            "--stop-after-shards",
            "2",
        ],
    );
    assert_eq!(o.status.code(), Some(130));
    assert!(
        ingest_small(&scene, &resumed, &["--rows-per-shard", "2", "--quiet"])
            .status
            .success()
    );
    assert_eq!(verify(&resumed).status.code(), Some(0));

    // One flipped byte in the middle of a shard.
    let shard = ds.join("shards/views-00001.parquet");
    let mut bytes = std::fs::read(&shard).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0x40;
    std::fs::write(&shard, &bytes).unwrap();
    // A truncated table, and a missing shard.
    let splits = ds.join("splits.parquet");
    let s = std::fs::read(&splits).unwrap();
    std::fs::write(&splits, &s[..s.len() - 10]).unwrap();
    std::fs::remove_file(ds.join("shards/views-00002.parquet")).unwrap();
    let o = verify(&ds);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(4), "{err}");
    assert!(err.contains("shards/views-00001.parquet: sha256"), "{err}");
    assert!(err.contains("splits.parquet: size"), "{err}");
    assert!(err.contains("shards/views-00002.parquet: missing"), "{err}");
    // The flipped byte lies in a payload (they are most of a shard's bytes): its row and
    // column are named too.
    assert!(
        err.contains("shards/views-00001.parquet: ") && err.contains(" at row "),
        "{err}"
    );
    assert!(String::from_utf8_lossy(&o.stdout).contains("4 mismatch(es)"));
    let o = nrw(&["verify", ds.to_str().unwrap(), "--json", "--quiet"]);
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(r["mismatches"].as_array().unwrap().len(), 4);
    // No dataset at all is an error, not a mismatch.
    assert_eq!(verify(&tmp.path().join("nothing")).status.code(), Some(1));
}
