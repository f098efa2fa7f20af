//! Inputs that must not break the descriptor: black and constant photos, grey and 16-bit
//! files, sizes the network cannot take.

#[path = "../../../tests/support/shared.rs"]
mod shared;

use std::path::{Path, PathBuf};

use image::{GrayImage, ImageBuffer, Rgb, RgbImage};
use nrw_style::{grams, load_rgb01, to_input_01, Parallelism, Preprocess, Vgg};

fn net() -> Vgg {
    Vgg::load(&shared::shared_path("weights/vgg16_imagenet.safetensors")).unwrap()
}

fn grams_of(net: &Vgg, path: &Path) -> Vec<(usize, Vec<f64>)> {
    let img = load_rgb01(path).unwrap();
    grams(
        net,
        &to_input_01(&img, Preprocess::Imagenet),
        img.height() as usize,
        img.width() as usize,
        Parallelism::None,
    )
}

fn save(dir: &Path, name: &str, img: impl FnOnce(&Path)) -> PathBuf {
    let p = dir.join(name);
    img(&p);
    p
}

#[test]
fn black_and_constant_photos_give_finite_grams() {
    let Some(_) = shared::shared("data") else {
        return;
    };
    let net = net();
    let dir = tempfile::tempdir().unwrap();
    for (name, rgb) in [
        ("black.png", [0u8, 0, 0]),
        ("grey.png", [128, 128, 128]),
        ("white.png", [255, 255, 255]),
    ] {
        let p = save(dir.path(), name, |p| {
            RgbImage::from_pixel(48, 40, Rgb(rgb)).save(p).unwrap()
        });
        for (c, g) in grams_of(&net, &p) {
            assert_eq!(g.len(), c * c);
            assert!(
                g.iter().all(|v| v.is_finite() && *v >= -1e-9),
                "{name}: Gram entries finite, diagonal non-negative"
            );
        }
    }
}

#[test]
fn grey_and_16_bit_files_equal_their_8_bit_rgb_versions() {
    let Some(_) = shared::shared("data") else {
        return;
    };
    let net = net();
    let dir = tempfile::tempdir().unwrap();
    let g8 = GrayImage::from_fn(40, 32, |x, y| image::Luma([((x * 7 + y * 3) % 256) as u8]));
    let grey = save(dir.path(), "grey.png", |p| g8.save(p).unwrap());
    let rgb = save(dir.path(), "rgb.png", |p| {
        RgbImage::from_fn(40, 32, |x, y| {
            let v = g8.get_pixel(x, y)[0];
            Rgb([v, v, v])
        })
        .save(p)
        .unwrap()
    });
    let sixteen = save(dir.path(), "rgb16.png", |p| {
        ImageBuffer::<Rgb<u16>, Vec<u16>>::from_fn(40, 32, |x, y| {
            let v = g8.get_pixel(x, y)[0] as u16 * 257;
            Rgb([v, v, v])
        })
        .save(p)
        .unwrap()
    });
    let (a, b, c) = (
        grams_of(&net, &grey),
        grams_of(&net, &rgb),
        grams_of(&net, &sixteen),
    );
    for ((ga, gb), gc) in a.iter().zip(&b).zip(&c) {
        let scale = gb.1.iter().fold(0f64, |m, v| m.max(v.abs())).max(1e-30);
        for ((x, y), z) in ga.1.iter().zip(&gb.1).zip(&gc.1) {
            // Not bit-equal: the two decoders' inputs differ in the last bit, and the f32
            // rounding of twelve Winograd convolutions (several times the direct method's)
            // turns that into up to a few 1e-6 of the deep Grams.
            let (d_grey, d_16) = ((x - y).abs() / scale, (y - z).abs() / scale);
            assert!(d_grey < 1e-5, "grey equals its RGB: {d_grey:e}");
            assert!(d_16 < 1e-5, "16-bit v·257 equals 8-bit v: {d_16:e}");
        }
    }
}

#[test]
fn sizes_the_network_cannot_take_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let strip = save(dir.path(), "strip.png", |p| {
        RgbImage::new(1, 300).save(p).unwrap()
    });
    let e = load_rgb01(&strip).unwrap_err().to_string();
    assert!(
        e.contains("strip.png") && e.contains("1×300") && e.contains("at least 16×16"),
        "{e}"
    );
    let huge = save(dir.path(), "huge.png", |p| {
        RgbImage::new(2000, 1100).save(p).unwrap()
    });
    let e = load_rgb01(&huge).unwrap_err().to_string();
    assert!(
        e.contains("huge.png") && e.contains("2000×1100") && e.contains("pixels"),
        "{e}"
    );
    let e = Vgg::load(&strip).unwrap_err().to_string();
    assert!(
        e.contains("strip.png") && e.contains("not a safetensors file"),
        "{e}"
    );
}

#[test]
fn strips_are_described_through_tiers_or_refused_by_name() {
    let Some(_) = shared::shared("data") else {
        return;
    };
    use nrw_style::{describe, Tier};
    let net = net();
    // A 1×300 strip: a fixed-size tier's centre crop is its middle pixel, resized to a
    // constant square, so the descriptor equals that of a constant photo of that colour.
    let strip = RgbImage::from_fn(1, 300, |_, y| Rgb([(y % 200) as u8, 90, 30]));
    let middle = *strip.get_pixel(0, 149);
    let tier = Tier::parse("vgg16-128").unwrap();
    let d = |img: &RgbImage, t: &Tier| describe(t, Some(&net), img, Preprocess::Imagenet);
    let got = d(&strip, &tier).unwrap();
    assert!(got.iter().all(|v| v.is_finite()));
    assert_eq!(
        got,
        d(&RgbImage::from_pixel(128, 128, middle), &tier).unwrap()
    );
    // The full-image tier cannot take it: a clear error, not NaN Grams.
    let e = d(&strip, &Tier::parse("vgg16-full").unwrap())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("1×300") && e.contains("vgg16-full") && e.contains("16×16"),
        "{e}"
    );
}

#[test]
fn a_batch_gives_the_bits_of_its_inputs_one_by_one_and_refuses_a_short_input() {
    let Some(_) = shared::shared("data") else {
        return;
    };
    use nrw_style::{Backend, NetInput, StyleError};
    let net = net();
    let inputs: Vec<NetInput> = (0..3)
        .map(|k| {
            let img = RgbImage::from_fn(40 + 8 * k, 48, |x, y| {
                Rgb([(x * 5 + k) as u8, (y * 3) as u8, ((x ^ y) * 7) as u8])
            });
            NetInput {
                chw: nrw_style::to_input(&img, Preprocess::Imagenet),
                height: 48,
                width: 40 + 8 * k as usize,
            }
        })
        .collect();
    let taps = [0, 2, 4];
    // One input runs with threads inside its kernels, a batch one input per thread.
    let batch = net.style_grams(&inputs, &taps).unwrap();
    for (x, got) in inputs.iter().zip(&batch) {
        let alone = net.style_grams(std::slice::from_ref(x), &taps).unwrap();
        assert_eq!(&alone[0], got, "{}×{}", x.width, x.height);
    }
    let mut short = inputs[1].clone();
    short.chw.pop();
    let e = net
        .style_grams(&[inputs[0].clone(), short], &taps)
        .unwrap_err();
    assert!(matches!(e, StyleError::Input { index: 1, .. }), "{e}");
    assert_eq!(
        e.to_string(),
        "network input 1 of the batch: 6911 values for a 3 × 48 × 48 input"
    );
}
