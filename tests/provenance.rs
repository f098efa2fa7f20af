//! Photos from the wild: `ingest --photo-info` (CSV and JSON Lines) carries each photo's
//! licence, author and source into `scene/photos.parquet`; every export writes
//! `attribution.csv` listing exactly the photos it exported, and `--licences` leaves out
//! exactly the others; bad rows are errors naming file, line and column.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::{fails, nrw, ok};

/// Every layout: the scene is PINHOLE (NeRF-W's loaders take it), its ground-truth label
/// maps are ingested (the published code's layouts need them) and it has colour-statistics
/// descriptors and triplets (the official layout's distance pickle).
const LAYOUTS: [&str; 8] = [
    "files",
    "gsplat",
    "nerfbaselines",
    "nerfstudio",
    "megadepth",
    "nerfw",
    "official",
    "tfrecord",
];

/// A PINHOLE scene of 6 photos, stored unscaled: (scene, image names by id order).
fn scene(dir: &Path) -> (PathBuf, Vec<String>) {
    let scene = dir.join("scene");
    let mut spec = nrw_synth::SceneSpec::demo().shrunk(6, (121, 121), 60_000);
    spec.cameras.model = "PINHOLE".into();
    spec.cameras.distortion = 0.0;
    nrw_synth::generate(&spec, &scene, &|| {}).unwrap();
    let rec = nrw_colmap::read_scene(&scene).unwrap();
    let names = rec.images.values().map(|i| i.name.clone()).collect();
    (scene, names)
}

/// The photo-info rows of the test: one licence spelling of each kind, an author with a
/// comma, a name the model does not have, and the last image left without a row.
fn rows(names: &[String]) -> Vec<(String, &'static str, &'static str, String)> {
    let licences = [
        "4",
        "http://creativecommons.org/licenses/by-nc/2.0/",
        "CC0-1.0",
        "Attribution-ShareAlike License",
        "All Rights Reserved",
    ];
    let mut r: Vec<_> = names[..5]
        .iter()
        .zip(licences)
        .enumerate()
        .map(|(i, (n, l))| {
            (
                n.clone(),
                l,
                if i == 0 { "Doe, J." } else { "someone" },
                format!("https://www.flickr.com/photos/x/{i}"),
            )
        })
        .collect();
    r.push((
        "not_in_the_model.jpg".into(),
        "CC-BY-2.0",
        "nobody",
        String::new(),
    ));
    r
}

/// The licence each image should end with, by name.
fn expected(names: &[String]) -> BTreeMap<String, String> {
    let spdx = [
        "CC-BY-2.0",
        "CC-BY-NC-2.0",
        "CC0-1.0",
        "CC-BY-SA-2.0",
        "LicenseRef-All-Rights-Reserved",
        "unknown",
    ];
    names.iter().cloned().zip(spdx.map(String::from)).collect()
}

fn write_csv(path: &Path, names: &[String]) {
    let mut s = String::from("name,license,ownername,url,camera_club\n");
    for (n, l, a, u) in rows(names) {
        let quote = |v: &str| {
            if v.contains(',') {
                format!("\"{v}\"")
            } else {
                v.to_string()
            }
        };
        s.push_str(&format!("{},{},{},{},yes\n", n, quote(l), quote(a), u));
    }
    std::fs::write(path, s).unwrap();
}

fn write_jsonl(path: &Path, names: &[String]) {
    let lines: Vec<String> = rows(names)
        .into_iter()
        .map(|(n, l, a, u)| serde_json::json!({"image": n, "licence": l, "author": a, "source_url": u, "camera_club": "yes"}).to_string())
        .collect();
    std::fs::write(path, lines.join("\n") + "\n").unwrap();
}

/// Ingest with `extra` and the scene's label maps, split with one val view, colour-statistics
/// descriptors and triplets: ingest's stderr.
fn ingest(scene: &Path, out: &Path, extra: &[&str]) -> String {
    let labels = scene.join(nrw_synth::truth::SEMANTICS);
    let mut args = vec![
        "ingest",
        scene.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--semantics",
        labels.to_str().unwrap(),
        "--min-photo-side",
        "100",
        "--min-dim",
        "121",
        "--max-empty",
        "1.0",
    ];
    args.extend(extra);
    let o = nrw(&args);
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    assert!(o.status.success(), "{err}");
    let d = out.to_str().unwrap();
    ok(&["split", d, "--val", "1"]);
    ok(&["style", d, "--tier", "color-stats"]);
    ok(&["triplets", d, "--k", "2"]);
    err
}

/// `export DATASET --layout LAYOUT --out OUT EXTRA…`: what it printed. The published code's
/// layouts crop to 96 px (the test's photos are 121 px high; the paper's crop is 256).
fn export(ds: &Path, layout: &str, out: &Path, extra: &[&str]) -> String {
    let mut args = vec![
        "export",
        ds.to_str().unwrap(),
        "--layout",
        layout,
        "--out",
        out.to_str().unwrap(),
    ];
    if ["official", "tfrecord"].contains(&layout) {
        args.extend(["--crop", "96"]);
    }
    args.extend(extra);
    ok(&args)
}

/// attribution.csv's rows as image → licence, checked against export.json's views.
fn attribution(export: &Path) -> BTreeMap<String, String> {
    let text = std::fs::read_to_string(export.join("attribution.csv")).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("image,licence,author,url"));
    let mut reader = ::csv::Reader::from_reader(text.as_bytes());
    let rows: BTreeMap<String, String> = reader
        .records()
        .map(|r| {
            let r = r.unwrap();
            (r[0].to_string(), r[1].to_string())
        })
        .collect();
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(export.join("export.json")).unwrap()).unwrap();
    let exported: std::collections::BTreeSet<String> = summary["splits"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|s| {
            s["names"]
                .as_array()
                .unwrap()
                .iter()
                .map(|n| n.as_str().unwrap().to_string())
        })
        .collect();
    assert_eq!(
        rows.keys()
            .cloned()
            .collect::<std::collections::BTreeSet<_>>(),
        exported,
        "{}",
        export.display()
    );
    rows
}

#[test]
fn every_export_attributes_exactly_the_photos_it_wrote_and_licences_leave_out_exactly_the_others() {
    let tmp = tempfile::tempdir().unwrap();
    let (scene, names) = scene(tmp.path());
    let want = expected(&names);
    let (csv, jsonl) = (tmp.path().join("info.csv"), tmp.path().join("info.jsonl"));
    write_csv(&csv, &names);
    write_jsonl(&jsonl, &names);
    let mut tables = Vec::new();
    for (form, file, line) in [("csv", &csv, 7), ("jsonl", &jsonl, 6)] {
        let ds = tmp.path().join(format!("ds-{form}"));
        let err = ingest(&scene, &ds, &["--photo-info", file.to_str().unwrap()]);
        // A name not in the model is a warning naming it and its line; a photo without a row is unknown.
        assert!(
            err.contains(&format!("not_in_the_model.jpg (line {line})"))
                && err.contains("1 of 6 registered images have no row"),
            "{err}"
        );
        tables.push(std::fs::read(ds.join("scene/photos.parquet")).unwrap());
        let inspected: serde_json::Value =
            serde_json::from_str(&ok(&["inspect", ds.to_str().unwrap(), "--json"])).unwrap();
        assert_eq!(inspected["licences"]["unknown"], 1, "{inspected}");
        assert_eq!(inspected["licences"]["CC-BY-2.0"], 1, "{inspected}");
        // QA counts them too and names the photo without a licence.
        ok(&["qa", ds.to_str().unwrap()]);
        let qa: serde_json::Value =
            serde_json::from_slice(&std::fs::read(ds.join("qa/qa.json")).unwrap()).unwrap();
        assert_eq!(qa["licences"]["CC-BY-NC-2.0"], 1, "{qa}");
        let unknown = qa["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .find(|w| w["kind"] == "licence_unknown")
            .unwrap_or_else(|| panic!("{qa}"));
        assert_eq!(unknown["photos"], serde_json::json!([names[5]]), "{qa}");
        for layout in LAYOUTS {
            let out = tmp.path().join(format!("{form}-{layout}"));
            export(&ds, layout, &out, &["--quiet"]);
            let rows = attribution(&out);
            assert_eq!(rows.len(), 6, "{layout}");
            assert_eq!(rows, want, "{form} {layout}");
            let text = std::fs::read_to_string(out.join("attribution.csv")).unwrap();
            assert!(text.contains("\"Doe, J.\""), "{text}");
            // --licences: exactly the photos under those licences, the rest counted as left out.
            let only = tmp.path().join(format!("{form}-{layout}-open"));
            let said = export(
                &ds,
                layout,
                &only,
                &["--licences", "CC BY 2.0,cc0-1.0,unknown"],
            );
            assert!(said.contains("3 views under other licences"), "{said}");
            let rows = attribution(&only);
            let open: BTreeMap<String, String> = want
                .iter()
                .filter(|(_, l)| ["CC-BY-2.0", "CC0-1.0", "unknown"].contains(&l.as_str()))
                .map(|(n, l)| (n.clone(), l.clone()))
                .collect();
            assert_eq!(rows, open, "{form} {layout}");
            let summary: serde_json::Value =
                serde_json::from_slice(&std::fs::read(only.join("export.json")).unwrap()).unwrap();
            assert_eq!(summary["licences"]["left_out"], 3, "{summary}");
        }
    }
    // Both forms of the file give the same table, byte for byte.
    assert_eq!(tables[0], tables[1]);
    // The files layout writes no photo of a licence left out.
    let files: Vec<String> = super::walk(&tmp.path().join("csv-files-open"))
        .iter()
        .map(|p| p.display().to_string())
        .collect();
    assert!(
        !files
            .iter()
            .any(|f| f.contains(names[1].trim_end_matches(".jpg"))),
        "{files:?}"
    );
}

#[test]
fn a_bad_photo_info_row_is_named_by_file_line_and_column() {
    let tmp = tempfile::tempdir().unwrap();
    let (scene, names) = scene(tmp.path());
    let bad = tmp.path().join("bad.csv");
    let out = tmp.path().join("ds");
    let run = |text: String| {
        std::fs::write(&bad, text).unwrap();
        fails(&[
            "ingest",
            scene.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--photo-info",
            bad.to_str().unwrap(),
        ])
    };
    let err = run(format!(
        "name,licence,author\n{},CC-BY-2.0,a\n{},GPL-3.0,b\n",
        names[0], names[1]
    ));
    assert!(
        err.contains("bad.csv")
            && err.contains("line 3")
            && err.contains("licence")
            && err.contains("GPL-3.0"),
        "{err}"
    );
    let err = run(format!("name,licence,author\n{},CC-BY-2.0\n", names[0]));
    assert!(err.contains("bad.csv") && err.contains("line 2"), "{err}");
    let err = run(format!("name,licence\n{0},4\n{0},5\n", names[0]));
    assert!(
        err.contains("line 3") && err.contains("line 2 already"),
        "{err}"
    );
    let jsonl = tmp.path().join("bad.jsonl");
    std::fs::write(
        &jsonl,
        format!(
            "{{\"name\": \"{}\", \"licence\": \"4\"}}\n{{\"name\": oops}}\n",
            names[0]
        ),
    )
    .unwrap();
    let err = fails(&[
        "ingest",
        scene.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--photo-info",
        jsonl.to_str().unwrap(),
    ]);
    assert!(
        err.contains("bad.jsonl") && err.contains("line 2") && err.contains("column"),
        "{err}"
    );
    assert!(!out.join("manifest.json").exists());
}
