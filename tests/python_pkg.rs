//! The `nrw` Python package (python/) against its oracles: this test prepares the datasets
//! (the demo and sceaux_castle), dumps the Rust `Loader`'s crops and the Rust triplet
//! sampler's draws, and runs the package's pytest suite on them. The package must be
//! installed (`pip install ./python`); without it the test says so and skips, except under
//! NRW_REQUIRE_PYTHON_PKG=1 (CI), where it fails.

use std::io::Write;
use std::path::Path;
use std::process::Command;

use super::{data, ok, shared};

/// Whether `import nrw, pytest` works; a skip that says so otherwise.
fn package_installed() -> bool {
    super::python::python_runs(
        "import nrw, pytest",
        "NRW_REQUIRE_PYTHON_PKG",
        "the nrw Python package and pytest (pip install ./python pytest)",
    )
}

/// sceaux_castle through ingest, split, style (colour statistics) and triplets.
fn sceaux(out: &Path) {
    let o = out.to_str().unwrap();
    let scene = data().join("sceaux_castle");
    ok(&[
        "ingest",
        scene.to_str().unwrap(),
        "--out",
        o,
        "--quiet",
        "--min-dim",
        "200",
        "--rows-per-shard",
        "3",
    ]);
    ok(&["split", o, "--val", "2"]);
    ok(&["style", o, "--tier", "color-stats", "--quiet"]);
    ok(&["triplets", o, "--k", "3"]);
}

/// Little-endian f32 values.
fn f32_bytes(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// What the Rust consumers draw on `ds`: the Loader's crops of two epochs (index.json plus
/// one file of photo, render and depth values per crop) and the triplet sampler's draws.
fn dump_rust_draws(ds: &Path, out: &Path) {
    use nrw_trainer::{Loader, LoaderConfig, TripletSampler};
    std::fs::create_dir_all(out).unwrap();
    let dataset = nrw_dataset::reader::Dataset::open(ds).unwrap();
    let (seed, crop) = (7u64, 64u32);
    let cfg = LoaderConfig {
        crop,
        batch: 5,
        seed,
        semantics: false,
    };
    let loader = Loader::new(&dataset, "train", cfg).unwrap();
    let mut crops = Vec::new();
    for epoch in 0..2u64 {
        for (k, batch) in loader.epoch(epoch).enumerate() {
            let b = batch.unwrap();
            let s = (crop * crop) as usize;
            for i in 0..b.len() {
                let position = k * 5 + i;
                let file = format!("crop-{epoch}-{position}.f32");
                let mut f = std::fs::File::create(out.join(&file)).unwrap();
                f.write_all(&f32_bytes(&b.photo[i * 3 * s..(i + 1) * 3 * s]))
                    .unwrap();
                f.write_all(&f32_bytes(&b.color[i * 3 * s..(i + 1) * 3 * s]))
                    .unwrap();
                f.write_all(&f32_bytes(&b.depth[i * s..(i + 1) * s]))
                    .unwrap();
                crops.push(serde_json::json!({
                    "epoch": epoch, "position": position, "image_id": b.ids[i],
                    "x": b.offsets[i].0, "y": b.offsets[i].1, "file": file,
                }));
            }
        }
    }
    let rows = nrw_dataset::triplets::read_triplets(&dataset.store)
        .unwrap()
        .unwrap();
    let mut sampler = TripletSampler::new(&rows, 3, 5, 5, 11).unwrap();
    let index = serde_json::json!({
        "split": "train", "seed": seed, "crop": crop, "crops": crops,
        "triplets": {"pos_k": 3, "neg_k": 5, "hold_out_every": 5, "seed": 11,
                     "sample": sampler.sample(40), "held_out": sampler.held_out_triplets()},
    });
    std::fs::write(
        out.join("index.json"),
        serde_json::to_vec_pretty(&index).unwrap(),
    )
    .unwrap();
}

#[test]
fn the_python_package_reads_what_pyarrow_pillow_openexr_and_the_rust_loader_read() {
    if !package_installed() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let demo = tmp.path().join("demo");
    ok(&["demo", "--out", demo.to_str().unwrap()]);
    let demo_ds = demo.join("dataset");
    dump_rust_draws(&demo_ds, &tmp.path().join("rust-draws"));
    let mut cmd = Command::new("python3");
    cmd.args(["-m", "pytest", "-q", "-rs", "-p", "no:cacheprovider"])
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("../../python/tests"))
        .current_dir(tmp.path())
        .env("NRW_TEST_DEMO", &demo_ds)
        .env("NRW_TEST_RUST_DRAWS", tmp.path().join("rust-draws"));
    if shared::shared("data/sceaux_castle").is_some() {
        let sc = tmp.path().join("sceaux");
        sceaux(&sc);
        cmd.env("NRW_TEST_SCEAUX", &sc);
    }
    let o = cmd.output().expect("python3 runs");
    let stdout = String::from_utf8_lossy(&o.stdout);
    eprintln!("{stdout}{}", String::from_utf8_lossy(&o.stderr));
    assert!(o.status.success(), "pytest failed:\n{stdout}");
    assert!(stdout.contains(" passed"), "{stdout}");
    torch_tests(&demo_ds, &tmp.path().join("rust-draws"), tmp.path());
}

/// The suite's files that need torch (nrw.torch under a real DataLoader, docs/python.md's
/// training loop), run by the Python `NRW_TORCH_PYTHON` names when it imports torch, nrw and
/// pytest: none may skip there. Under NRW_REQUIRE_TORCH=1 (CI) that Python is required.
fn torch_tests(demo: &Path, rust_draws: &Path, cwd: &Path) {
    let Some(py) =
        super::python::torch_python("nrw, pytest", "the nrw package's torch tests", true)
    else {
        return;
    };
    let tests = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../python/tests");
    let o = Command::new(py)
        .args(["-m", "pytest", "-q", "-rs", "-p", "no:cacheprovider"])
        .arg(tests.join("test_torch.py"))
        .arg(tests.join("test_docs.py"))
        .current_dir(cwd)
        .env("NRW_TEST_DEMO", demo)
        .env("NRW_TEST_RUST_DRAWS", rust_draws)
        .output()
        .expect("NRW_TORCH_PYTHON runs");
    let stdout = String::from_utf8_lossy(&o.stdout);
    eprintln!("{stdout}{}", String::from_utf8_lossy(&o.stderr));
    assert!(o.status.success(), "pytest (torch) failed:\n{stdout}");
    assert!(
        stdout.contains(" passed") && !stdout.contains("skipped"),
        "with torch installed, no torch test may skip:\n{stdout}"
    );
}

/// Each package with its enabled features, one line each, as `cargo tree` resolves `scope`.
fn resolved_features(scope: &[&str]) -> std::collections::BTreeMap<String, Vec<String>> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = Command::new(cargo)
        .current_dir(&root)
        .args([
            "tree",
            "--locked",
            "--offline",
            "--prefix",
            "none",
            "-f",
            "{p}|{f}",
        ])
        .args(scope)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut by_package = std::collections::BTreeMap::<String, Vec<String>>::new();
    for line in String::from_utf8(out.stdout).unwrap().lines() {
        let line = line.replace(" (*)", "").replace(" (proc-macro)", "");
        if let Some((package, features)) = line.split_once('|') {
            let sets = by_package.entry(package.to_string()).or_default();
            if !sets.iter().any(|s| s == features) {
                sets.push(features.to_string());
            }
        }
    }
    by_package
}

/// python/Cargo.toml's feature pins keep every crate of the package's graph at the features
/// the workspace's build gives it, so CI's `pip install ./python` builds what the tests reuse.
#[test]
fn the_package_builds_its_dependencies_with_the_workspace_s_features() {
    let package = resolved_features(&["-p", "nrw-py", "-e", "normal,build"]);
    let workspace = resolved_features(&["--workspace"]);
    let mut differ = Vec::new();
    for (name, sets) in &package {
        let Some(theirs) = workspace.get(name) else {
            continue;
        };
        for set in sets.iter().filter(|s| !theirs.contains(s)) {
            differ.push(format!(
                "{name}: the package [{set}], the workspace {theirs:?}"
            ));
        }
    }
    assert!(
        package.len() > 100 && differ.is_empty(),
        "pin these in python/Cargo.toml ({} packages compared):\n{}",
        package.len(),
        differ.join("\n")
    );
}
