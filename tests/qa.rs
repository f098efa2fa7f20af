//! `qa`: the report's figures against the tables, a dataset with every view dropped, the report in a browser.

use super::*;

/// qa.json's counts, recomputed from the tables with the Arrow reader (not polars).
fn independent_counts(ds: &Path) -> (usize, usize, usize, usize, usize, usize) {
    let v = nrw_dataset::scene::read_verdicts(&nrw_dataset::Store::from(ds)).unwrap();
    let kept = v.iter().filter(|r| r.2 == "kept").count();
    let small = v.iter().filter(|r| r.2 == "too_small").count();
    let sparse = v.iter().filter(|r| r.2 == "too_sparse").count();
    let splits = if ds.join("splits.parquet").is_file() {
        nrw_dataset::split::read_splits(&nrw_dataset::Store::from(ds)).unwrap()
    } else {
        Vec::new()
    };
    let train = splits.iter().filter(|a| a.split == "train").count();
    let val = splits.iter().filter(|a| a.split == "val").count();
    (v.len(), kept, small, sparse, train, val)
}

fn qa_json(ds: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(ds.join("qa/qa.json")).unwrap()).unwrap()
}

#[test]
fn qa_report_figures_equal_the_tables_at_every_stage() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("scene");
    let spec = nrw_synth::SceneSpec::demo().shrunk(14, (120, 150), 60_000);
    nrw_synth::generate(&spec, &scene, &|| {}).unwrap();
    let ds = tmp.path().join("ds");
    let d = ds.to_str().unwrap();
    // A size filter inside the drawn range drops some photos as too small.
    ok(&[
        "ingest",
        scene.to_str().unwrap(),
        "--out",
        d,
        "--min-photo-side",
        "125",
        "--min-dim",
        "96",
        "--quiet",
    ]);
    let check = |stage: &str| {
        let out = ok(&["qa", d]);
        assert_eq!(out.trim(), ds.join("qa/report.html").to_str().unwrap());
        let q = qa_json(&ds);
        let (n, kept, small, sparse, train, val) = independent_counts(&ds);
        let c = &q["counts"];
        assert_eq!(c["registered"], n, "{stage}");
        assert_eq!(c["kept"], kept, "{stage}");
        assert_eq!(c["rendered"], n - small, "{stage}");
        assert_eq!(c["shard_rows"], kept, "{stage}");
        assert_eq!(c["train"], train, "{stage}");
        assert_eq!(c["val"], val, "{stage}");
        assert_eq!(
            q["drops"]["too_small"].as_u64().unwrap_or(0) as usize,
            small
        );
        assert_eq!(
            q["drops"]["too_sparse"].as_u64().unwrap_or(0) as usize,
            sparse
        );
        assert!(
            small > 0 && kept > 5,
            "the scene exercises drops: {small} small, {kept} kept"
        );
        let html = std::fs::read_to_string(ds.join("qa/report.html")).unwrap();
        // Self-contained: every image is a data URI, charts are inline SVG.
        let imgs = html.matches("<img ").count();
        assert_eq!(
            imgs,
            html.matches("<img src=\"data:image/jpeg;base64,").count()
        );
        assert!(html.matches("<svg").count() >= 4, "{stage}: charts");
        (q, html, imgs)
    };
    // Right after ingest: no split, no triplets yet.
    let (q, html, imgs) = check("ingest");
    assert!(q["triplets"].is_null());
    assert!(html.contains("No triplets yet") && html.contains("Not split yet"));
    // Contact sheet: 4 images per sampled kept view, dropped-photo thumbnails from the scene.
    assert!(imgs >= 4 * 6, "{imgs} images");
    assert!(q["timings"]["ingest"].as_f64().unwrap() > 0.0);
    ok(&["split", d, "--val", "3", "--seed", "5"]);
    ok(&["style", d, "--tier", "color-stats", "--quiet"]);
    ok(&["triplets", d, "--k", "3"]);
    let (q, html, _) = check("triplets");
    assert_eq!(q["counts"]["val"], 3);
    assert_eq!(q["triplets"]["k"], 3);
    assert_eq!(q["counts"]["descriptors"], q["counts"]["kept"]);
    // 3 val photos: the report says the validation set is small.
    let kinds: Vec<&str> = q["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| w["kind"].as_str().unwrap())
        .collect();
    assert!(kinds.contains(&"small_validation_set"), "{kinds:?}");
    // The synthetic scene's true appearances colour the descriptor map.
    assert!(html.contains("by true appearance") && html.contains("anchor "));
}

#[test]
fn qa_report_of_a_dataset_where_every_view_was_dropped() {
    let Some(_) = shared::shared("data") else {
        return;
    };
    let out = tempfile::tempdir().unwrap();
    let d = out.path().to_str().unwrap();
    let o = nrw(&[
        "ingest",
        data().join("sacre_coeur").to_str().unwrap(),
        "--out",
        d,
    ]);
    assert_eq!(o.status.code(), Some(3));
    ok(&["qa", d]);
    let q = qa_json(out.path());
    assert_eq!(q["counts"]["registered"], 10);
    assert_eq!(q["counts"]["kept"], 0);
    assert_eq!(q["drops"]["too_sparse"], 10);
    assert!(q["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .any(|w| w["kind"] == "nothing_kept"));
    let html = std::fs::read_to_string(out.path().join("qa/report.html")).unwrap();
    // The dropped photos are shown with the value that dropped them.
    assert!(
        html.contains("% empty)") && html.contains("No kept views to show"),
        "report"
    );
}

/// Headless Chromium renders the report with no console error and every image decoded. Needs
/// Debian's `chromium` (installed by .ci/run); skipped elsewhere unless NRW_REQUIRE_CHROMIUM=1.
/// NRW_QA_SCREENSHOT=FILE keeps a screenshot to look at.
#[test]
fn qa_report_renders_in_headless_chromium() {
    let chromium = Path::new("/usr/bin/chromium");
    if !chromium.exists() {
        assert!(
            std::env::var("NRW_REQUIRE_CHROMIUM").map_or(true, |v| v != "1"),
            "NRW_REQUIRE_CHROMIUM=1 but /usr/bin/chromium is missing"
        );
        eprintln!("skipped: no /usr/bin/chromium");
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let demo = tmp.path().join("demo");
    let out = ok(&["demo", "--out", demo.to_str().unwrap()]);
    let report = demo.join("dataset/qa/report.html");
    assert!(
        out.contains(report.to_str().unwrap()),
        "demo prints the report: {out}"
    );
    let shot = std::env::var("NRW_QA_SCREENSHOT")
        .map(PathBuf::from)
        .unwrap_or_else(|_| tmp.path().join("shot.png"));
    let profile = tmp.path().join("profile");
    let run = |extra: &[&str]| {
        let o = std::process::Command::new(chromium)
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--disable-quic",
                "--no-first-run",
                "--disable-background-networking",
                "--disable-component-update",
                "--disable-sync",
                "--enable-logging=stderr",
                "--v=0",
                "--virtual-time-budget=5000",
                "--window-size=1200,5000",
            ])
            .arg(format!("--user-data-dir={}", profile.display()))
            .args(extra)
            .arg(format!("file://{}", report.display()))
            .output()
            .unwrap();
        (
            String::from_utf8_lossy(&o.stdout).to_string(),
            String::from_utf8_lossy(&o.stderr).to_string(),
        )
    };
    let (dom, log) = run(&["--dump-dom"]);
    assert!(
        dom.contains("data-qa-images=\"ok\""),
        "images failed to load:\n{log}"
    );
    let count: usize = number_after(&dom, "data-qa-image-count=\"").unwrap_or(0);
    assert!(count >= 24, "{count} images in the page");
    let console: Vec<&str> = log
        .lines()
        .filter(|l| l.contains("CONSOLE") || l.contains("Uncaught"))
        .collect();
    assert!(console.is_empty(), "console messages: {console:?}");
    let (_, log) = run(&[&format!("--screenshot={}", shot.display())]);
    let png = std::fs::read(&shot).unwrap_or_else(|e| panic!("no screenshot ({e}):\n{log}"));
    assert!(
        png.starts_with(b"\x89PNG") && png.len() > 50_000,
        "screenshot"
    );
}
