//! The paper's published code (../shared/paper-code, run unmodified under
//! tensorflow.compat.v1 by tests/oracles/paper_oracle.py) reads our default `official` export: its
//! TFRecord converter and parser, its appearance-pretraining reader at the export's crop, its
//! triplet sampler with our `dist_NAME.pckl`, and its own style distance
//! (`compute_pairwise_style_loss_v2`) against our `--tier official`, on a synthetic scene with
//! ground-truth labels and on sceaux_castle labelled by the tiny SegFormer fixture.

use std::path::{Path, PathBuf};
use std::process::Command;

use super::{data, ok, python_has, shared};

/// What the oracle needs: TensorFlow (CPU) and the published code's own imports.
pub const PAPER_DEPS: &str = "import tensorflow, cv2, matplotlib, absl, six, PIL, pyarrow";

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// A `vgg16.npy` in tensorflow-vgg's layout made by numpy from the shared VGG16 weights.
fn test_npy(dir: &Path) -> PathBuf {
    let npy = dir.join("vgg16.npy");
    let st = shared::shared_path("weights/vgg16_imagenet.safetensors");
    let o = Command::new("python3")
        .arg(repo().join("tests/oracles/make_vgg16_npy.py"))
        .arg(&st)
        .arg(&npy)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    npy
}

/// Run tests/oracles/paper_oracle.py with `args` (after `--paper`); its JSON summary.
pub fn paper_oracle(args: &[&str]) -> serde_json::Value {
    let o = Command::new("python3")
        .arg(repo().join("tests/oracles/paper_oracle.py"))
        .arg("--paper")
        .arg(shared::shared_path("paper-code"))
        .args(args)
        .env("TF_CPP_MIN_LOG_LEVEL", "2")
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "the published code failed on our export ({args:?}):\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    serde_json::from_slice(&o.stdout).unwrap()
}

/// The oracle on an official and a tfrecord export of `dataset` at training resolution `res`.
fn oracle(
    dataset: &Path,
    official: &Path,
    tfrecord: &Path,
    npy: &Path,
    res: u32,
) -> serde_json::Value {
    let res = res.to_string();
    paper_oracle(&[
        "--official",
        official.to_str().unwrap(),
        "--tfrecord",
        tfrecord.to_str().unwrap(),
        "--dataset",
        dataset.to_str().unwrap(),
        "--name",
        "scene",
        "--resolution",
        &res,
        "--npy",
        npy.to_str().unwrap(),
    ])
}

/// split, official style, the default official export and a tfrecord export, then the oracle.
fn export_and_read(
    ds: &Path,
    tmp: &Path,
    npy: &Path,
    val: usize,
    extra: &[&str],
) -> serde_json::Value {
    let d = ds.to_str().unwrap();
    ok(&["split", d, "--val", &val.to_string()]);
    let tier = extra.first().copied().unwrap_or("official");
    ok(&[
        "style",
        d,
        "--tier",
        tier,
        "--weights",
        npy.to_str().unwrap(),
        "--overwrite",
        "--quiet",
    ]);
    let off = tmp.join("official");
    let tfr = tmp.join("tfr");
    let crop: Vec<&str> = extra.iter().skip(1).copied().collect();
    let mut a = vec![
        "export",
        d,
        "--out",
        off.to_str().unwrap(),
        "--name",
        "scene",
        "--quiet",
    ];
    a.extend(&crop);
    ok(&a);
    let mut a = vec![
        "export",
        d,
        "--layout",
        "tfrecord",
        "--out",
        tfr.to_str().unwrap(),
        "--name",
        "scene",
        "--quiet",
    ];
    a.extend(&crop);
    ok(&a);
    let res = crop.get(1).map_or(512, |c| c.parse().unwrap());
    let v = oracle(ds, &off, &tfr, npy, res);
    eprintln!("published code on {}: {v}", ds.display());
    v
}

/// The checks every export must pass in the published code's hands.
fn assert_published_reads(v: &serde_json::Value, train: u64, val: u64) {
    assert_eq!(v["splits"]["train"]["views"], train, "{v}");
    assert_eq!(v["splits"]["val"]["views"], val, "{v}");
    let d = &v["dist"];
    assert_eq!(d["n"], train, "{v}");
    assert!(d["min_off_diagonal"].as_f64().unwrap() > 0.0, "{v}");
    let worst = d["worst_relative"].as_f64().unwrap();
    assert!(
        worst <= 1e-4,
        "official tier vs compute_pairwise_style_loss_v2: {worst:e}"
    );
    assert_eq!(d["same_order"], true, "neighbour order differs: {v}");
}

/// A temporary folder with a test `vgg16.npy` in it, when the published code, the weights
/// and TensorFlow are here (a skip that says so otherwise; CI requires them).
fn published_code_here() -> Option<(tempfile::TempDir, PathBuf)> {
    shared::shared("paper-code")?;
    shared::shared("weights")?;
    if !python_has(PAPER_DEPS) {
        return None;
    }
    let tmp = tempfile::tempdir().unwrap();
    let npy = test_npy(tmp.path());
    Some((tmp, npy))
}

#[test]
fn the_published_code_reads_the_default_official_export_of_a_synthetic_scene() {
    let Some((tmp, npy)) = published_code_here() else {
        return;
    };
    let scene = tmp.path().join("scene");
    // 8 photos, 6 for training: the published sampler draws positives at sorted index 1…5.
    let mut spec = nrw_synth::SceneSpec::demo().shrunk(8, (600, 700), 60_000);
    spec.observations.features = 300;
    nrw_synth::generate(&spec, &scene, &|| {}).unwrap();
    let ds = tmp.path().join("ds");
    let labels = scene.join("ground_truth/semantics");
    ok(&[
        "ingest",
        scene.to_str().unwrap(),
        "--out",
        ds.to_str().unwrap(),
        "--semantics",
        labels.to_str().unwrap(),
        "--max-empty",
        "1.0",
        "--quiet",
    ]);
    let v = export_and_read(&ds, tmp.path(), &npy, 2, &[]);
    assert_published_reads(&v, 6, 2);
    // The ground-truth labels use more than the one colour of unchosen classes.
    assert!(
        v["splits"]["train"]["colours"].as_u64().unwrap() >= 2,
        "{v}"
    );
    // --crop 256 is what --train_resolution=256 reads (every channel, seg_rgb included).
    let t256 = tmp.path().join("t256");
    std::fs::create_dir_all(&t256).unwrap();
    let v = export_and_read(&ds, &t256, &npy, 2, &["official-256", "--crop", "256"]);
    assert_published_reads(&v, 6, 2);
}

#[test]
fn the_published_code_reads_the_default_official_export_of_sceaux_castle() {
    let Some((tmp, npy)) = published_code_here() else {
        return;
    };
    let ds = tmp.path().join("ds");
    let seg = repo().join("tests/fixtures/segformer_tiny");
    ok(&[
        "ingest",
        data().join("sceaux_castle").to_str().unwrap(),
        "--out",
        ds.to_str().unwrap(),
        "--segment-weights",
        seg.to_str().unwrap(),
        "--quiet",
    ]);
    let v = export_and_read(&ds, tmp.path(), &npy, 2, &[]);
    let kept = nrw_dataset::reader::Dataset::open(&ds).unwrap().len() as u64;
    assert_published_reads(&v, kept - 2, 2);
}

#[test]
fn each_tier_refuses_weights_of_the_other_convention_by_name() {
    let Some(st) = shared::shared("weights/vgg16_imagenet.safetensors") else {
        return;
    };
    if !python_has("import numpy") {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let npy = test_npy(tmp.path());
    let ds = tmp.path().join("ds");
    let scene = tmp.path().join("scene");
    let mut spec = nrw_synth::SceneSpec::demo().shrunk(3, (120, 150), 20_000);
    spec.observations.features = 300;
    nrw_synth::generate(&spec, &scene, &|| {}).unwrap();
    ok(&[
        "ingest",
        scene.to_str().unwrap(),
        "--out",
        ds.to_str().unwrap(),
        "--min-dim",
        "96",
        "--min-photo-side",
        "100",
        "--max-empty",
        "1.0",
        "--quiet",
    ]);
    let d = ds.to_str().unwrap();
    let e = super::fails(&[
        "style",
        d,
        "--tier",
        "official-64",
        "--weights",
        st.to_str().unwrap(),
    ]);
    assert!(
        e.contains("vgg16_imagenet.safetensors")
            && e.contains("tensorflow-vgg's Caffe-trained vgg16.npy")
            && e.contains("torchvision weights"),
        "{e}"
    );
    let e = super::fails(&[
        "style",
        d,
        "--tier",
        "vgg16-64",
        "--weights",
        npy.to_str().unwrap(),
    ]);
    assert!(
        e.contains("vgg16.npy") && e.contains("only the official tiers run"),
        "{e}"
    );
    // A pickle that names anything but NumPy's array globals is refused, nothing run.
    let evil = tmp.path().join("evil.npy");
    let mut bytes = std::fs::read(&npy).unwrap();
    let at = bytes.windows(7).position(|w| w == b"ndarray").unwrap();
    bytes[at..at + 7].copy_from_slice(b"getattr");
    std::fs::write(&evil, &bytes).unwrap();
    let e = super::fails(&[
        "style",
        d,
        "--tier",
        "official-64",
        "--weights",
        evil.to_str().unwrap(),
    ]);
    assert!(
        e.contains("evil.npy") && e.contains("`numpy.getattr`") && e.contains("refused"),
        "{e}"
    );
}
