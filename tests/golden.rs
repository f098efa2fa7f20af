//! The bytes the tool writes, pinned: the demo's dataset and each export layout hash to the
//! list in tests/golden/demo.sha256, recorded from the commit before a refactor so that a
//! change of structure cannot change a byte unseen. Paths of the run's folder inside JSON are
//! written as `$OUT`; stage timings and the QA report (which shows them) are left out.
//!
//! Record anew only when a change of bytes is intended (and say so in the commit):
//! `NRW_RECORD_GOLDEN=1 cargo test -p nrw-etl --test cli -- golden`.

use std::collections::BTreeMap;
use std::path::Path;

use super::{ok, walk};

const LIST: &str = "tests/golden/demo.sha256";

/// SHA-256 of every file under `root` (relative path → hex), JSON with `root` as `$OUT`.
fn hashes(root: &Path) -> BTreeMap<String, String> {
    let prefix = root.display().to_string();
    walk(root)
        .into_iter()
        .filter_map(|p| {
            let rel = p.strip_prefix(root).unwrap().to_string_lossy().into_owned();
            let skip = rel.ends_with("timings.json") || rel.starts_with("demo/dataset/qa/");
            if skip {
                return None;
            }
            let mut bytes = std::fs::read(&p).unwrap();
            if rel.ends_with(".json") {
                bytes = String::from_utf8(bytes)
                    .unwrap()
                    .replace(&prefix, "$OUT")
                    .into_bytes();
            }
            let sha = nrw_dataset::FileEntry::of_bytes(&rel, &bytes).sha256;
            Some((rel, sha))
        })
        .collect()
}

#[test]
fn the_demo_dataset_and_every_export_layout_keep_their_bytes() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path();
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let demo = root.join("demo");
    ok(&["demo", "--out", &s(&demo)]);
    let ds = s(&demo.join("dataset"));
    // NeRF-W takes pinhole cameras only: the demo scene undistorted.
    let pinhole = s(&root.join("undistorted"));
    let scene = s(&demo.join("scene"));
    ok(&[
        "ingest",
        &scene,
        "--out",
        &pinhole,
        "--undistort",
        "--quiet",
    ]);
    ok(&["split", &pinhole, "--val", "3"]);
    // Every layout the tool has, so a new one is pinned the day it is added.
    for layout in nrw_export::Layout::ALL {
        let from = if layout == nrw_export::Layout::Nerfw {
            &pinhole
        } else {
            &ds
        };
        let out = s(&root.join(format!("export-{layout}")));
        ok(&[
            "export",
            from,
            "--layout",
            layout.name(),
            "--out",
            &out,
            "--quiet",
        ]);
    }

    let found = hashes(root);
    let list = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .join(LIST);
    // Only `1` records: any other value (`0` included) compares.
    if std::env::var("NRW_RECORD_GOLDEN").as_deref() == Ok("1") {
        let text: String = found.iter().map(|(p, h)| format!("{h}  {p}\n")).collect();
        std::fs::write(&list, text).unwrap();
        return;
    }
    let want: BTreeMap<String, String> = std::fs::read_to_string(&list)
        .unwrap_or_else(|e| panic!("{LIST}: {e}"))
        .lines()
        .map(|l| {
            let (h, p) = l.split_once("  ").expect("HASH  PATH");
            (p.to_string(), h.to_string())
        })
        .collect();
    let changed: Vec<&String> = want
        .keys()
        .chain(found.keys())
        .filter(|p| want.get(*p) != found.get(*p))
        .collect::<std::collections::BTreeSet<_>>()
        .into_iter()
        .collect();
    assert!(
        changed.is_empty(),
        "{} of {} files differ from {LIST} (missing, new or other bytes): {changed:?}",
        changed.len(),
        want.len()
    );
}
