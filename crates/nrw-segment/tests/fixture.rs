//! Our SegFormer against Hugging Face transformers on the committed tiny random model
//! (tests/fixtures/segformer_tiny, made by its make.py): preprocessing bit for bit, logits
//! against the float64 reference, labels wherever the reference's top-two margin is clear.

use std::path::PathBuf;

use image::RgbImage;
use nrw_segment::{postprocess, preprocess, segment, Map, Mode, Parallelism, Segformer};

fn dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/fixtures/segformer_tiny")
}

struct Reference {
    bytes: Vec<u8>,
}

impl Reference {
    fn load() -> Reference {
        Reference {
            bytes: std::fs::read(dir().join("reference.safetensors")).unwrap(),
        }
    }
    fn tensor(&self, name: &str) -> (Vec<usize>, Vec<u8>) {
        let st = safetensors::SafeTensors::deserialize(&self.bytes).unwrap();
        let t = st.tensor(name).unwrap();
        (t.shape().to_vec(), t.data().to_vec())
    }
    fn f32s(&self, name: &str) -> (Vec<usize>, Vec<f32>) {
        let (s, b) = self.tensor(name);
        (
            s,
            b.chunks_exact(4)
                .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
                .collect(),
        )
    }
    fn f64s(&self, name: &str) -> (Vec<usize>, Vec<f64>) {
        let (s, b) = self.tensor(name);
        (
            s,
            b.chunks_exact(8)
                .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
                .collect(),
        )
    }
    fn photo(&self) -> RgbImage {
        let (s, b) = self.tensor("photo");
        RgbImage::from_raw(s[1] as u32, s[0] as u32, b).unwrap()
    }
}

fn model() -> Segformer {
    Segformer::load(&dir()).unwrap()
}

#[test]
fn preprocessing_is_the_pil_processors_bit_for_bit() {
    let r = Reference::load();
    let photo = r.photo();
    for name in ["pixel_values", "pixel_values_small"] {
        let (shape, want) = r.f32s(name);
        let got = preprocess::preprocess(&photo, shape[2] as u32, shape[1] as u32);
        let differ = got
            .iter()
            .zip(&want)
            .filter(|(a, b)| a.to_bits() != b.to_bits())
            .count();
        assert_eq!(
            differ,
            0,
            "{name}: {differ} of {} values differ from the processor's",
            want.len()
        );
    }
}

/// max |ours − reference| / max |reference|.
fn relative_error(ours: &Map, reference: &[f64]) -> f64 {
    let chw = ours.to_chw();
    let scale = reference.iter().fold(0f64, |a, b| a.max(b.abs()));
    chw.iter()
        .zip(reference)
        .map(|(a, b)| (*a as f64 - b).abs())
        .fold(0f64, f64::max)
        / scale
}

fn ours_logits() -> Map {
    let r = Reference::load();
    let (shape, pv) = r.f32s("pixel_values");
    model().logits(&pv, shape[1], shape[2], Parallelism::Rayon(0))
}

#[test]
fn logits_match_transformers_in_float64() {
    let r = Reference::load();
    let (shape, want) = r.f64s("logits");
    let got = ours_logits();
    assert_eq!((got.c, got.h, got.w), (shape[0], shape[1], shape[2]));
    let err = relative_error(&got, &want);
    println!("tiny SegFormer logits: max |ours − transformers float64| / max |logit| = {err:.2e}");
    // The issue asks for 1e-4; f32 arithmetic holds far less, so a smaller slip fails here.
    assert!(err < 1e-5, "relative error {err:e}");
}

#[test]
fn logits_do_not_depend_on_the_thread_count() {
    let r = Reference::load();
    let (shape, pv) = r.f32s("pixel_values");
    let m = model();
    let one = m.logits(&pv, shape[1], shape[2], Parallelism::None);
    let all = m.logits(&pv, shape[1], shape[2], Parallelism::Rayon(0));
    assert_eq!(one, all);
}

/// Labels equal the reference wherever its top-two margin exceeds 1e-3; returns how many
/// pixels were compared.
fn check_labels(got: &[u8], want: &[u8], margin: &[f64], what: &str) -> usize {
    assert_eq!(got.len(), want.len(), "{what}: size");
    let clear: Vec<usize> = (0..want.len()).filter(|&i| margin[i] > 1e-3).collect();
    let wrong: Vec<usize> = clear
        .iter()
        .copied()
        .filter(|&i| got[i] != want[i])
        .collect();
    assert!(
        wrong.is_empty(),
        "{what}: {} of {} clear pixels differ, first at {}: {} vs {}",
        wrong.len(),
        clear.len(),
        wrong[0],
        got[wrong[0]],
        want[wrong[0]]
    );
    assert!(
        clear.len() * 10 > want.len() * 9,
        "{what}: too few clear pixels to mean anything"
    );
    clear.len()
}

#[test]
fn labels_match_post_process_semantic_segmentation() {
    let r = Reference::load();
    let logits = ours_logits();
    for (labels, margin) in [("labels", "margin"), ("labels_big", "margin_big")] {
        let (shape, want) = r.tensor(labels);
        let (_, m) = r.f64s(margin);
        let got = postprocess::labels(&logits, shape[1], shape[0]);
        let n = check_labels(&got, &want, &m, labels);
        println!("{labels}: {n} of {} pixels compared, all equal", want.len());
        // The pruned arg-max is the full one on our own logits, exactly.
        let naive = postprocess::labels_full(&logits, shape[1], shape[0]);
        assert_eq!(got, naive, "{labels}: pruned and full arg-max differ");
    }
}

#[test]
fn segmenting_the_photo_end_to_end_matches_transformers() {
    let r = Reference::load();
    let photo = r.photo();
    let (_, want) = r.tensor("labels");
    let (_, margin) = r.f64s("margin");
    let got = segment(
        &model(),
        &photo,
        Mode::Resize {
            width: 70,
            height: 50,
        },
        "fixture photo",
        Parallelism::None,
    )
    .unwrap();
    assert_eq!((got.width(), got.height()), (photo.width(), photo.height()));
    check_labels(got.as_raw(), &want, &margin, "segment()");
}
