//! The `official` tier against a float64 reference: tests/vgg_f64.py runs VGG16 in numpy
//! float64 on the published code's input (centre crop, v·2/255 − 1, then its VGG's Caffe step)
//! after checking itself against the PyTorch float64 fixtures in ../shared/fixtures/vgg16. Our
//! side reads the same weights from a `vgg16.npy` that numpy wrote in tensorflow-vgg's layout
//! (tests/oracles/make_vgg16_npy.py), so the reader, the BGR reordering and the input step are tested.

#[path = "../../../tests/support/python.rs"]
mod python;
#[path = "../../../tests/support/shared.rs"]
mod shared;

use std::path::{Path, PathBuf};
use std::process::Command;

use nrw_style::{describe, Preprocess, Tier, Vgg};

fn shared() -> PathBuf {
    shared::shared_dir()
}

#[test]
fn official_grams_match_a_float64_vgg16_that_matches_pytorch() {
    let Some(_) = shared::shared("fixtures") else {
        return;
    };
    if !python::python_has("import numpy, PIL") {
        return;
    }
    let weights = shared().join("weights/vgg16_imagenet.safetensors");
    let tmp = tempfile::tempdir().unwrap();
    let npy = tmp.path().join("vgg16.npy");
    let o = Command::new("python3")
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/oracles/make_vgg16_npy.py"))
        .arg(&weights)
        .arg(&npy)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let net = Vgg::load(&npy).unwrap();
    assert_eq!(net.convention, nrw_style::Convention::Caffe);
    // 320 × 240 takes an off-centre-parity crop; 256 × 256 a crop of the whole photo.
    for (stem, crop) in [
        ("02928139_3448003521_320x240", 96u32),
        ("100_7100_256x256", 256),
    ] {
        let png = shared().join(format!("fixtures/vgg16/{stem}.png"));
        let photo = image::open(&png).unwrap().to_rgb8();
        let tier = Tier::Official { crop };
        let d = describe(&tier, Some(&net), &photo, Preprocess::Imagenet).unwrap();
        let ours = tmp.path().join(format!("{stem}.f32"));
        std::fs::write(
            &ours,
            d.iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<u8>>(),
        )
        .unwrap();
        let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/vgg_f64.py");
        let o = Command::new("python3")
            .arg(script)
            .arg(&weights)
            .arg(shared().join("fixtures/vgg16"))
            .arg(stem)
            .arg(crop.to_string())
            .arg(&ours)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        eprintln!("{stem} crop {crop}: {v}");
        // The oracle agrees with PyTorch's float64 Grams to about 1e-8 (the fixtures' own
        // rounding), four orders below the tolerance it then judges us by.
        for (_, w) in v["self_check_vs_pytorch"].as_object().unwrap() {
            assert!(
                w.as_f64().unwrap() < 1e-6,
                "the float64 oracle is PyTorch's: {v}"
            );
        }
        let layers = v["official_vs_f64"].as_object().unwrap();
        assert_eq!(layers.len(), 5);
        for (layer, w) in layers {
            assert!(w.as_f64().unwrap() < 1e-4, "{stem} {layer}: {v}");
        }
    }
    // A photo smaller than the crop is refused with its size, as get_central_crop asserts.
    let small = image::RgbImage::new(300, 200);
    let e = describe(
        &Tier::Official { crop: 256 },
        Some(&net),
        &small,
        Preprocess::Imagenet,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("300×200") && e.contains("256×256"), "{e}");
}
