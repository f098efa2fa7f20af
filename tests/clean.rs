//! `ingest --denoise K,SIGMA` and `--estimate-normals K` end to end: the manifest (and so the
//! QA report) records what was removed, a cloud without normals gets a normal channel only
//! when asked, and bad values are usage errors naming the flag.

use nrw_dataset::reader::Dataset;

use super::{data, nrw, ok, shared};

fn manifest(ds: &std::path::Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(ds.join("manifest.json")).unwrap()).unwrap()
}

#[test]
fn denoise_records_what_it_removed_in_the_manifest_and_the_qa_report() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("scene");
    let mut spec = nrw_synth::SceneSpec::demo().shrunk(4, (120, 160), 60_000);
    spec.observations.features = 300;
    spec.effects.outliers = Some(0.02);
    nrw_synth::generate(&spec, &scene, &|| {}).unwrap();
    let ds = tmp.path().join("ds");
    ok(&[
        "ingest",
        scene.to_str().unwrap(),
        "--out",
        ds.to_str().unwrap(),
        "--denoise",
        "16,2",
        "--min-dim",
        "96",
        "--min-photo-side",
        "100",
        "--max-empty",
        "1",
        "--quiet",
    ]);
    let m = manifest(&ds);
    let d = &m["parameters"]["denoise"];
    let removed = d["removed"].as_u64().unwrap();
    assert_eq!(d["k"], 16);
    assert_eq!(d["points"], 61_200, "{d}");
    assert!(removed > 600 && removed < 2_000, "{d}");
    assert_eq!(
        m["parameters"]["points"].as_u64().unwrap(),
        61_200 - removed
    );
    ok(&["qa", ds.to_str().unwrap()]);
    let qa = std::fs::read_to_string(ds.join("qa/qa.json")).unwrap();
    assert!(
        qa.contains("\"removed\""),
        "the QA report lists the denoise figures"
    );
}

#[test]
fn normals_are_estimated_only_when_asked_and_bad_values_are_refused() {
    let Some(_) = shared::shared("data") else {
        return;
    };
    let scene = data().join("sacre_coeur");
    let tmp = tempfile::tempdir().unwrap();
    let run = |out: &std::path::Path, extra: &[&str]| {
        let mut a = vec![
            "ingest",
            scene.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--max-empty",
            "1",
            "--min-dim",
            "200",
            "--quiet",
        ];
        a.extend(extra);
        ok(&a);
        Dataset::open(out).unwrap()
    };
    // The sparse points have no normals: no normal channel unless asked.
    let plain = run(&tmp.path().join("plain"), &[]);
    let id = plain.ids("all").unwrap()[0];
    assert!(plain.get(id).unwrap().normal_png.is_none());
    let with = run(&tmp.path().join("normals"), &["--estimate-normals", "8"]);
    assert!(
        with.get(id).unwrap().normal_png.is_some(),
        "a normal channel"
    );
    assert_eq!(
        manifest(&tmp.path().join("normals"))["parameters"]["estimated_normals_k"],
        8
    );
    for (flag, value) in [
        ("--denoise", "1,2"),
        ("--denoise", "16"),
        ("--denoise", "16,-1"),
    ] {
        let o = nrw(&["ingest", scene.to_str().unwrap(), "--out", "x", flag, value]);
        assert_eq!(o.status.code(), Some(2), "{flag} {value}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains("--denoise"), "{err}");
    }
    let o = nrw(&[
        "ingest",
        scene.to_str().unwrap(),
        "--out",
        "x",
        "--estimate-normals",
        "2",
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--estimate-normals"));
}
