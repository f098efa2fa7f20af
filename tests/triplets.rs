//! `triplets`: exact triplets against the published loop, approximate ones with their recall.

use super::*;

#[test]
fn triplets_come_from_the_training_split_in_exact_order() {
    use arrow_array::{Array, ListArray, UInt32Array};
    let tmp = tempfile::tempdir().unwrap();
    let ds = small_dataset(tmp.path(), 9, false);
    let d = ds.to_str().unwrap();
    let err = fails(&["triplets", d, "--k", "3"]);
    assert!(err.contains("run `nrw-etl style"), "{err}");
    ok(&["split", d, "--val", "2", "--seed", "4"]);
    ok(&["style", d, "--tier", "color-stats", "--quiet"]);
    let err = fails(&["triplets", d, "--k", "7"]);
    assert!(
        err.contains("--k 7 needs at least 8 photos in scope train, found 7")
            && err.contains("--k 6"),
        "{err}"
    );
    ok(&["triplets", d, "--k", "6"]);
    let val: Vec<u32> = nrw_dataset::split::read_splits(&nrw_dataset::Store::from(&ds))
        .unwrap()
        .iter()
        .filter(|a| a.split == "val")
        .map(|a| a.image_id)
        .collect();
    let (_, desc) = nrw_dataset::descriptors::read_all(&nrw_dataset::Store::from(&ds))
        .unwrap()
        .unwrap();
    let by_id: std::collections::BTreeMap<u32, Vec<f32>> = desc
        .into_iter()
        .map(|r| (r.image_id, r.descriptor))
        .collect();
    let batches = nrw_dataset::parquet_io::read_batches(
        &nrw_dataset::Store::from(&ds),
        "triplets.parquet",
        None,
    )
    .unwrap();
    let mut anchors = 0;
    for b in &batches {
        let a = column::<UInt32Array>(b, "anchor_id");
        let near = column::<ListArray>(b, "nearest_ids");
        let far = column::<ListArray>(b, "furthest_ids");
        for i in 0..b.num_rows() {
            anchors += 1;
            let anchor = a.value(i);
            let ids = |l: &ListArray| {
                l.value(i)
                    .as_any()
                    .downcast_ref::<UInt32Array>()
                    .unwrap()
                    .values()
                    .to_vec()
            };
            let (n, f) = (ids(near), ids(far));
            assert!(
                !val.contains(&anchor)
                    && n.iter().chain(&f).all(|x| !val.contains(x) && *x != anchor),
                "validation photos never appear"
            );
            // Independent check: a naive f64 sort of the training photos by distance.
            let mut all: Vec<(f64, u32)> = by_id
                .iter()
                .filter(|(id, _)| **id != anchor && !val.contains(id))
                .map(|(id, v)| {
                    let d: f64 = by_id[&anchor]
                        .iter()
                        .zip(v)
                        .map(|(x, y)| (*x as f64 - *y as f64).powi(2))
                        .sum();
                    (d, *id)
                })
                .collect();
            all.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
            assert_eq!(n, all.iter().take(6).map(|p| p.1).collect::<Vec<_>>());
            all.sort_by(|x, y| y.0.total_cmp(&x.0).then(x.1.cmp(&y.1)));
            assert_eq!(f, all.iter().take(6).map(|p| p.1).collect::<Vec<_>>());
        }
    }
    assert_eq!(anchors, 7);
    // And numpy's own all-pairs distances over the Parquet files, none of our code.
    if python::python_has("import numpy, pyarrow") {
        let oracle =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/oracles/triplets_oracle.py");
        let o = Command::new("python3")
            .args([oracle.to_str().unwrap(), d, "6"])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(ds.join("manifest.json")).unwrap()).unwrap();
    assert!(v["tables"]
        .as_array()
        .unwrap()
        .iter()
        .any(|t| t["path"] == "triplets.parquet"));
}

#[test]
fn approximate_triplets_store_their_measured_recall() {
    use arrow_array::{Float64Array, StringArray};
    let tmp = tempfile::tempdir().unwrap();
    let ds = small_dataset(tmp.path(), 8, false);
    let d = ds.to_str().unwrap();
    ok(&["split", d, "--val", "0"]);
    ok(&["style", d, "--tier", "color-stats", "--quiet"]);
    ok(&["triplets", d, "--k", "3", "--pca", "9"]);
    let b = &nrw_dataset::parquet_io::read_batches(
        &nrw_dataset::Store::from(&ds),
        "triplets.parquet",
        None,
    )
    .unwrap()[0];
    assert_eq!(column::<StringArray>(b, "method").value(0), "pca-9");
    // PCA to the full 9 dimensions loses nothing: recall is exactly 1 and was stored.
    assert_eq!(column::<Float64Array>(b, "recall_nearest").value(0), 1.0);
    assert_eq!(column::<Float64Array>(b, "recall_furthest").value(0), 1.0);
    ok(&["triplets", d, "--k", "3"]);
    let b = &nrw_dataset::parquet_io::read_batches(
        &nrw_dataset::Store::from(&ds),
        "triplets.parquet",
        None,
    )
    .unwrap()[0];
    assert_eq!(column::<StringArray>(b, "method").value(0), "exact");
    assert!(arrow_array::Array::is_null(
        column::<Float64Array>(b, "recall_nearest"),
        0
    ));
}
