//! A model that is missing, truncated or not what its config says is refused with a message
//! naming the file and what was expected; nothing is guessed.

use std::path::{Path, PathBuf};

use nrw_segment::Segformer;

fn fixture() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/fixtures/segformer_tiny")
}

/// A copy of the fixture model in a temporary folder.
fn copy() -> tempfile::TempDir {
    let d = tempfile::tempdir().unwrap();
    for f in ["config.json", "model.safetensors"] {
        std::fs::copy(fixture().join(f), d.path().join(f)).unwrap();
    }
    d
}

fn err(dir: &Path) -> String {
    Segformer::load(dir).unwrap_err().to_string()
}

fn edit_config(dir: &Path, f: impl FnOnce(&mut serde_json::Value)) {
    let p = dir.join("config.json");
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&p).unwrap()).unwrap();
    f(&mut v);
    std::fs::write(&p, serde_json::to_string(&v).unwrap()).unwrap();
}

/// Rewrite model.safetensors with `f` applied to (name, shape, f32 values).
fn edit_weights(dir: &Path, f: impl Fn(&mut Vec<(String, Vec<usize>, Vec<f32>)>)) {
    let p = dir.join("model.safetensors");
    let bytes = std::fs::read(&p).unwrap();
    let st = safetensors::SafeTensors::deserialize(&bytes).unwrap();
    let mut ts: Vec<(String, Vec<usize>, Vec<f32>)> = st
        .tensors()
        .into_iter()
        .filter(|(_, t)| t.dtype() == safetensors::Dtype::F32)
        .map(|(n, t)| {
            let v = t
                .data()
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
                .collect();
            (n, t.shape().to_vec(), v)
        })
        .collect();
    f(&mut ts);
    let raw: Vec<(String, Vec<usize>, Vec<u8>)> = ts
        .iter()
        .map(|(n, s, v)| {
            (
                n.clone(),
                s.clone(),
                v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            )
        })
        .collect();
    let views: Vec<(String, safetensors::tensor::TensorView)> = raw
        .iter()
        .map(|(n, s, b)| {
            (
                n.clone(),
                safetensors::tensor::TensorView::new(safetensors::Dtype::F32, s.clone(), b)
                    .unwrap(),
            )
        })
        .collect();
    std::fs::write(&p, safetensors::serialize(views, None).unwrap()).unwrap();
}

#[test]
fn the_fixture_loads_and_a_rewritten_copy_too() {
    let d = copy();
    edit_weights(d.path(), |_| {});
    Segformer::load(d.path()).unwrap();
}

#[test]
fn a_missing_file_is_named() {
    let d = copy();
    std::fs::remove_file(d.path().join("config.json")).unwrap();
    let e = err(d.path());
    assert!(
        e.contains("config.json") && e.contains("Hugging Face layout"),
        "{e}"
    );
    let d = copy();
    std::fs::remove_file(d.path().join("model.safetensors")).unwrap();
    assert!(err(d.path()).contains("model.safetensors"));
}

#[test]
fn a_truncated_weights_file_is_refused() {
    let d = copy();
    let p = d.path().join("model.safetensors");
    let bytes = std::fs::read(&p).unwrap();
    std::fs::write(&p, &bytes[..bytes.len() / 2]).unwrap();
    let e = err(d.path());
    assert!(
        e.contains("model.safetensors") && e.contains("truncated or damaged"),
        "{e}"
    );
}

#[test]
fn another_class_count_is_refused() {
    let d = copy();
    edit_config(d.path(), |v| {
        let m: serde_json::Map<String, serde_json::Value> = (0..19)
            .map(|i| (i.to_string(), format!("LABEL_{i}").into()))
            .collect();
        v["id2label"] = m.into();
    });
    let e = err(d.path());
    assert!(
        e.contains("config.json") && e.contains("19 classes") && e.contains("150"),
        "{e}"
    );
}

#[test]
fn a_class_list_that_is_not_ade20k_in_order_is_refused() {
    let d = copy();
    edit_config(d.path(), |v| {
        // ADE20K with `other` first: every id shifted by one.
        let names: Vec<String> = (0..150)
            .map(|i| {
                v["id2label"][((i + 149) % 150).to_string()]
                    .as_str()
                    .unwrap()
                    .to_string()
            })
            .collect();
        v["id2label"] = names
            .iter()
            .enumerate()
            .map(|(i, n)| (i.to_string(), serde_json::Value::from(n.clone())))
            .collect::<serde_json::Map<_, _>>()
            .into();
    });
    let e = err(d.path());
    assert!(
        e.contains("not ADE20K-150 in order") && e.contains("`wall`"),
        "{e}"
    );
}

#[test]
fn a_missing_tensor_is_named_with_its_expected_shape() {
    let d = copy();
    edit_weights(d.path(), |ts| {
        ts.retain(|(n, _, _)| n != "decode_head.linear_fuse.weight")
    });
    let e = err(d.path());
    assert!(
        e.contains("`decode_head.linear_fuse.weight` is missing") && e.contains("[16, 64, 1, 1]"),
        "{e}"
    );
}

#[test]
fn a_classifier_of_another_size_is_refused() {
    let d = copy();
    edit_weights(d.path(), |ts| {
        for (n, s, v) in ts.iter_mut() {
            if n.starts_with("decode_head.classifier.") {
                s[0] = 151;
                v.resize(v.len() / 150 * 151, 0.0);
            }
        }
    });
    let e = err(d.path());
    assert!(
        e.contains("decode_head.classifier.weight") && e.contains("[150, 16, 1, 1]"),
        "{e}"
    );
}

#[test]
fn a_config_of_another_model_is_refused() {
    // Weights with two blocks in stage 2, a config that says one: the extra block is unused.
    let d = copy();
    edit_config(d.path(), |v| v["depths"] = serde_json::json!([1, 1, 2, 1]));
    let e = err(d.path());
    assert!(e.contains("not used by") && e.contains("block.1.1"), "{e}");
}

#[test]
fn non_finite_weights_are_refused_by_tensor() {
    let d = copy();
    edit_weights(d.path(), |ts| {
        for (n, _, v) in ts.iter_mut() {
            if n == "segformer.encoder.block.2.0.mlp.dense1.weight" {
                v[5] = f32::NAN;
            }
        }
    });
    let e = err(d.path());
    assert!(
        e.contains("block.2.0.mlp.dense1.weight") && e.contains("NaN at index 5"),
        "{e}"
    );
}

#[test]
fn configs_outside_segformer_are_refused_before_any_weight_is_read() {
    for (key, value, says) in [
        ("hidden_act", serde_json::json!("relu"), "gelu"),
        (
            "depths",
            serde_json::json!([1, 2, 2]),
            "depths lists 3 stages",
        ),
        (
            "num_attention_heads",
            serde_json::json!([1, 3, 3, 4]),
            "multiple of its 3 attention heads",
        ),
        ("model_type", serde_json::json!("vit"), "segformer"),
    ] {
        let d = copy();
        edit_config(d.path(), |v| v[key] = value.clone());
        let e = err(d.path());
        assert!(e.contains("config.json") && e.contains(says), "{key}: {e}");
    }
}
