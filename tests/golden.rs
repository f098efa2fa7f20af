//! The bytes the tool writes, pinned: the demo's dataset and each export layout hash to the
//! list in tests/golden/demo.sha256, recorded from the commit before a refactor so that a
//! change of structure cannot change a byte unseen. Paths of the run's folder inside JSON are
//! written as `$OUT`; stage timings are left out (qa.json is pinned without its `timings`), and
//! so is the QA report's HTML, which shows them.
//!
//! A real scene with the paper's VGG descriptors and `--pca` triplets is pinned too
//! (tests/golden/sceaux_castle.json): every file byte for byte but those whose values come
//! from GEMM kernels, whose sums depend on the instruction set (AVX-512 or AVX2); those are
//! compared value by value within the tolerance docs/style.md states (descriptor sums and
//! distances to 1e-4 relative, neighbour ids exactly).
//!
//! Record anew only when a change of bytes is intended (and say so in the commit):
//! `NRW_RECORD_GOLDEN=1 cargo test -p nrw-etl --test cli -- golden`.

use std::collections::BTreeMap;
use std::path::Path;

use super::{data, ok, shared, walk};

const LIST: &str = "tests/golden/demo.sha256";

/// Whether the golden files are to be recorded instead of compared (`NRW_RECORD_GOLDEN=1`).
fn recording() -> bool {
    std::env::var("NRW_RECORD_GOLDEN").as_deref() == Ok("1")
}

/// SHA-256 of every file under `root` (relative path → hex), JSON with `root` as `$OUT`.
fn hashes(root: &Path) -> BTreeMap<String, String> {
    let prefix = root.display().to_string();
    walk(root)
        .into_iter()
        .filter_map(|p| {
            let rel = p.strip_prefix(root).unwrap().to_string_lossy().into_owned();
            let skip = rel.ends_with("timings.json") || rel == "demo/dataset/qa/report.html";
            if skip {
                return None;
            }
            let mut bytes = std::fs::read(&p).unwrap();
            if rel == "demo/dataset/qa/qa.json" {
                bytes = qa_without_timings(&bytes);
            }
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

/// The QA summary with its stage timings (which vary run to run) taken out; every count,
/// distribution, warning and parameter stays, so a change to what QA reports shows here.
fn qa_without_timings(bytes: &[u8]) -> Vec<u8> {
    let mut qa: serde_json::Value = serde_json::from_slice(bytes).unwrap();
    let removed = qa.as_object_mut().unwrap().remove("timings");
    assert!(
        removed.is_some(),
        "qa.json has no `timings`: this filter is stale"
    );
    serde_json::to_vec_pretty(&qa).unwrap()
}

#[test]
fn the_demo_dataset_and_every_export_layout_keep_their_bytes() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path();
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let demo = root.join("demo");
    ok(&["demo", "--out", &s(&demo)]);
    let ds = s(&demo.join("dataset"));
    // NeRF-W takes pinhole cameras only: the demo scene undistorted, with its label maps
    // undistorted beside the photos (so gsplat's mask pyramid is pinned too).
    let pinhole = s(&root.join("undistorted"));
    let scene = s(&demo.join("scene"));
    let labels = s(&demo.join("scene").join(nrw_synth::truth::SEMANTICS));
    ok(&[
        "ingest",
        &scene,
        "--out",
        &pinhole,
        "--undistort",
        "--semantics",
        &labels,
        "--quiet",
    ]);
    ok(&["split", &pinhole, "--val", "3"]);
    // Every layout the tool has, so a new one is pinned the day it is added.
    for layout in nrw_export::Layout::ALL {
        // The layouts that take PINHOLE cameras only read the undistorted dataset.
        let pinhole_only = [
            nrw_export::Layout::Nerfw,
            nrw_export::Layout::Gsplat,
            nrw_export::Layout::Nerfbaselines,
            nrw_export::Layout::Megadepth,
        ];
        let from = if pinhole_only.contains(&layout) {
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
    if recording() {
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

const SCEAUX: &str = "tests/golden/sceaux_castle.json";

/// Relative tolerance of values computed through GEMM kernels across instruction sets: the
/// parity bar each build meets against PyTorch float64 (docs/style.md). A distance moves by
/// about 2‖δ‖/‖a − b‖ of itself for a change δ of the descriptors, several 1e-6 here.
const ACROSS_ISAS: f64 = 1e-4;

/// One anchor's (nearest ids, their d², furthest ids, their d²).
type Lists = (Vec<u32>, Vec<f64>, Vec<u32>, Vec<f64>);

/// What the sceaux_castle run pins: hashes of the files whose bytes no GEMM touches, and
/// the values of those it does.
#[derive(Debug, serde::Serialize, serde::Deserialize)]
struct Pinned {
    files: BTreeMap<String, String>,
    /// image id → (values, Σv, Σv², Σ(i+1)·vᵢ / values) of its descriptor, summed in f64: the
    /// last moves when values trade places, which the first three do not see.
    descriptors: BTreeMap<u32, (usize, f64, f64, f64)>,
    /// anchor id → (nearest ids, their d², furthest ids, their d²).
    triplets: BTreeMap<u32, Lists>,
}

/// Files whose bytes hold GEMM-computed values (compared by value instead), and the
/// manifest, which lists their hashes and the instruction sets (compared without those).
fn gemm_valued(rel: &str) -> bool {
    rel.starts_with("dataset/descriptors/") || rel == "dataset/triplets.parquet"
}

/// The manifest as JSON without the entries that depend on the instruction set.
fn manifest_without_isa_values(path: &Path) -> String {
    let mut m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    m["parameters"]
        .as_object_mut()
        .unwrap()
        .remove("style_instruction_sets");
    m["tables"]
        .as_array_mut()
        .unwrap()
        .retain(|t| !gemm_valued(&format!("dataset/{}", t["path"].as_str().unwrap())));
    serde_json::to_string_pretty(&m).unwrap()
}

fn pinned(root: &Path) -> Pinned {
    let ds = root.join("dataset");
    let mut files: BTreeMap<String, String> = hashes(root)
        .into_iter()
        .filter(|(rel, _)| !gemm_valued(rel) && !rel.starts_with("dataset/qa/"))
        .collect();
    // The scene's paths are the clone's (../shared/data beside it): written as $DATA, in
    // the form the manifest holds them and canonical.
    let mut manifest = manifest_without_isa_values(&ds.join("manifest.json"))
        .replace(&root.display().to_string(), "$OUT");
    for d in [data(), data().canonicalize().unwrap()] {
        manifest = manifest.replace(&d.display().to_string(), "$DATA");
    }
    files.insert(
        "dataset/manifest.json".into(),
        nrw_dataset::FileEntry::of_bytes("m", manifest.as_bytes()).sha256,
    );
    let store = nrw_dataset::Store::from(ds.as_path());
    let (_, rows) = nrw_dataset::descriptors::read_all(&store).unwrap().unwrap();
    let descriptors = rows
        .iter()
        .map(|r| {
            let sum: f64 = r.descriptor.iter().map(|v| *v as f64).sum();
            let sq: f64 = r.descriptor.iter().map(|v| (*v as f64).powi(2)).sum();
            (
                r.image_id,
                (r.descriptor.len(), sum, sq, placed(&r.descriptor)),
            )
        })
        .collect();
    let t = nrw_dataset::triplets::read_triplets(&store)
        .unwrap()
        .unwrap();
    let triplets = t
        .into_iter()
        .map(|r| {
            (
                r.anchor_id,
                (r.nearest_ids, r.nearest_d2, r.furthest_ids, r.furthest_d2),
            )
        })
        .collect();
    Pinned {
        files,
        descriptors,
        triplets,
    }
}

/// Σ(i+1)·vᵢ / n of a descriptor of n values: a sum that weighs each value by its place.
fn placed(v: &[f32]) -> f64 {
    let s: f64 = v
        .iter()
        .enumerate()
        .map(|(i, x)| (i + 1) as f64 * *x as f64)
        .sum();
    s / v.len() as f64
}

/// Where `NRW_EXPECT_STYLE_ISA` names an instruction set (.ci/run's forced-AVX2 run on an
/// AVX-512 machine), the descriptors were computed with it and no other.
fn assert_instruction_set(manifest: &Path) {
    let Ok(want) = std::env::var("NRW_EXPECT_STYLE_ISA") else {
        return;
    };
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(manifest).unwrap()).unwrap();
    assert_eq!(
        m["parameters"]["style_instruction_sets"],
        serde_json::json!([want]),
        "{}: the instruction sets the descriptors ran on",
        manifest.display()
    );
}

/// `a` within [`ACROSS_ISAS`] of `b`, relative.
fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= ACROSS_ISAS * a.abs().max(b.abs())
}

#[test]
fn the_placed_sum_sees_two_values_trade_places() {
    assert_eq!(placed(&[1.0, 2.0, 3.0]), (1.0 + 4.0 + 9.0) / 3.0);
    assert_ne!(placed(&[1.0, 2.0, 3.0]), placed(&[2.0, 1.0, 3.0]));
}

#[test]
fn sceaux_castle_with_vgg_descriptors_and_pca_triplets_keeps_its_bytes_and_values() {
    let (Some(_), Some(weights)) = (
        shared::shared("data"),
        shared::shared("weights/vgg16_imagenet.safetensors"),
    ) else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path();
    let ds = root.join("dataset");
    let d = ds.to_str().unwrap();
    let scene = data().join("sceaux_castle");
    ok(&[
        "ingest",
        scene.to_str().unwrap(),
        "--out",
        d,
        "--min-dim",
        "200",
        "--quiet",
    ]);
    ok(&["split", d, "--val", "2"]);
    ok(&[
        "style",
        d,
        "--tier",
        "vgg16-512",
        "--weights",
        weights.to_str().unwrap(),
        "--quiet",
    ]);
    ok(&["triplets", d, "--k", "3", "--pca", "4"]);
    let out = root.join("export-files");
    ok(&[
        "export",
        d,
        "--layout",
        "files",
        "--out",
        out.to_str().unwrap(),
        "--quiet",
    ]);
    assert_instruction_set(&ds.join("manifest.json"));
    let got = pinned(root);
    let list = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .join(SCEAUX);
    if recording() {
        std::fs::write(&list, serde_json::to_string_pretty(&got).unwrap() + "\n").unwrap();
        return;
    }
    let want: Pinned = serde_json::from_str(
        &std::fs::read_to_string(&list).unwrap_or_else(|e| panic!("{SCEAUX}: {e}")),
    )
    .unwrap();
    let changed: Vec<&String> = want
        .files
        .keys()
        .chain(got.files.keys())
        .filter(|p| want.files.get(*p) != got.files.get(*p))
        .collect::<std::collections::BTreeSet<_>>()
        .into_iter()
        .collect();
    assert!(changed.is_empty(), "{SCEAUX}: files differ: {changed:?}");
    assert_eq!(
        want.descriptors.keys().collect::<Vec<_>>(),
        got.descriptors.keys().collect::<Vec<_>>()
    );
    for (id, w) in &want.descriptors {
        let g = got.descriptors[id];
        assert!(
            w.0 == g.0 && close(w.1, g.1) && close(w.2, g.2) && close(w.3, g.3),
            "{SCEAUX}: descriptor of image {id}: {g:?}, pinned {w:?}"
        );
    }
    assert_eq!(
        want.triplets.keys().collect::<Vec<_>>(),
        got.triplets.keys().collect::<Vec<_>>()
    );
    for (anchor, w) in &want.triplets {
        let g = &got.triplets[anchor];
        assert_eq!(
            (&w.0, &w.2),
            (&g.0, &g.2),
            "{SCEAUX}: anchor {anchor}'s ids"
        );
        for (a, b) in w.1.iter().chain(&w.3).zip(g.1.iter().chain(&g.3)) {
            assert!(
                close(*a, *b),
                "{SCEAUX}: anchor {anchor}: d² {b}, pinned {a}"
            );
        }
    }
}
