//! Parity with PyTorch (float64) on the fixtures in ../shared/fixtures/vgg16: every Gram
//! matrix within 1e-4 relative to its largest entry, from the fixture's own preprocessed
//! input and from the fixture PNG through our preprocessing.

#[path = "../../../tests/support/shared.rs"]
mod shared;

use std::path::PathBuf;

use nrw_style::{grams, to_input, Parallelism, Preprocess, Vgg, STYLE_LAYERS};

fn shared() -> PathBuf {
    shared::shared_dir()
}

fn tensor_f32(st: &safetensors::SafeTensors, name: &str) -> (Vec<usize>, Vec<f32>) {
    let t = st.tensor(name).unwrap();
    assert_eq!(t.dtype(), safetensors::Dtype::F32, "{name}");
    (
        t.shape().to_vec(),
        t.data()
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
            .collect(),
    )
}

fn tensor_f64(st: &safetensors::SafeTensors, name: &str) -> Vec<f64> {
    let t = st.tensor(name).unwrap();
    assert_eq!(t.dtype(), safetensors::Dtype::F64, "{name}");
    t.data()
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
        .collect()
}

#[test]
fn grams_match_pytorch_float64_on_both_fixtures() {
    let Some(_) = shared::shared("fixtures") else {
        return;
    };
    let net = Vgg::load(&shared().join("weights/vgg16_imagenet.safetensors")).unwrap();
    for stem in ["100_7100_256x256", "02928139_3448003521_320x240"] {
        let bytes =
            std::fs::read(shared().join(format!("fixtures/vgg16/{stem}.safetensors"))).unwrap();
        let st = safetensors::SafeTensors::deserialize(&bytes).unwrap();
        let (shape, input) = tensor_f32(&st, "input");
        let (h, w) = (shape[2], shape[3]);
        // Our preprocessing of the fixture PNG reproduces PyTorch's input.
        let png = image::open(shared().join(format!("fixtures/vgg16/{stem}.png")))
            .unwrap()
            .to_rgb8();
        let ours_in = to_input(&png, Preprocess::Imagenet);
        let worst_in = ours_in
            .iter()
            .zip(&input)
            .map(|(a, b)| (a - b).abs())
            .fold(0f32, f32::max);
        assert!(
            worst_in <= 1e-6,
            "{stem}: preprocessing differs by {worst_in}"
        );
        for (label, x) in [("fixture input", &input), ("our preprocessing", &ours_in)] {
            let g = grams(&net, x, h, w, Parallelism::Rayon(0));
            for ((c, ours), layer) in g.iter().zip(STYLE_LAYERS) {
                let want = tensor_f64(&st, &format!("gram_{layer}"));
                assert_eq!(ours.len(), c * c);
                assert_eq!(want.len(), c * c, "{stem} {layer}");
                let scale = want.iter().fold(0f64, |m, v| m.max(v.abs()));
                let worst = ours
                    .iter()
                    .zip(&want)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0f64, f64::max)
                    / scale;
                eprintln!("{stem} {layer} ({label}): worst relative difference {worst:.2e}");
                assert!(worst < 1e-4, "{stem} {layer} ({label}): {worst:e}");
            }
        }
    }
}
