//! Numerically hard and degenerate inputs: black and one-pixel photos, ties, extreme aspect
//! ratios, inputs below what the network can take; and the three modes' relations to each
//! other (a photo one window large slides to exactly its resize; a crop's inside is the
//! crop's own segmentation).

use std::path::PathBuf;

use image::{Rgb, RgbImage};
use nrw_segment::{postprocess, preprocess, segment, Map, Mode, Parallelism, Segformer};
use rand::{Rng, SeedableRng};

#[path = "../../../tests/support/python.rs"]
mod python;

fn model() -> Segformer {
    Segformer::load(
        &PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/fixtures/segformer_tiny"),
    )
    .unwrap()
}

fn noise(w: u32, h: u32, seed: u64) -> RgbImage {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    RgbImage::from_fn(w, h, |_, _| Rgb([rng.random(), rng.random(), rng.random()]))
}

#[test]
fn a_black_photo_gives_finite_logits_and_valid_ids() {
    let m = model();
    let black = RgbImage::new(64, 48);
    let x = preprocess::preprocess(&black, 64, 64);
    let l = m.logits(&x, 64, 64, Parallelism::None);
    assert!(l.data.iter().all(|v| v.is_finite()));
    let ids = segment(
        &m,
        &black,
        Mode::Resize {
            width: 64,
            height: 64,
        },
        "black",
        Parallelism::None,
    )
    .unwrap();
    assert!(ids.as_raw().iter().all(|&v| (1..=150).contains(&v)));
}

#[test]
fn one_pixel_and_thin_photos_are_resized_like_any_other() {
    let m = model();
    for (w, h) in [(1, 1), (1, 700), (900, 2)] {
        let p = noise(w, h, 3);
        let ids = segment(
            &m,
            &p,
            Mode::Resize {
                width: 64,
                height: 64,
            },
            "thin",
            Parallelism::None,
        )
        .unwrap();
        assert_eq!((ids.width(), ids.height()), (w, h));
        assert!(ids.as_raw().iter().all(|&v| (1..=150).contains(&v)));
        let slid = segment(&m, &p, Mode::Slide { size: 64 }, "thin", Parallelism::None).unwrap();
        assert_eq!((slid.width(), slid.height()), (w, h));
    }
}

#[test]
fn ties_go_to_the_lower_class_as_argmax_does() {
    let flat = Map {
        h: 2,
        w: 3,
        c: 150,
        data: vec![0.25; 900],
    };
    assert!(postprocess::labels(&flat, 7, 5).iter().all(|&v| v == 1));
    // Two classes tied at the top in every corner: the lower wins.
    let mut m = Map::zeros(2, 2, 150);
    for px in m.data.chunks_exact_mut(150) {
        px[40] = 3.0;
        px[90] = 3.0;
    }
    assert!(postprocess::labels(&m, 9, 9).iter().all(|&v| v == 41));
}

#[test]
fn nan_logits_never_win() {
    let mut m = Map::zeros(1, 1, 150);
    m.data[0] = f32::NAN;
    m.data[7] = 1.0;
    assert_eq!(postprocess::labels(&m, 2, 2), vec![8; 4]);
}

#[test]
fn inputs_below_the_networks_reach_are_refused_by_name() {
    let m = model();
    let min = m.min_side() as u32;
    assert!(min > 1, "the tiny model's stages need {min} pixels");
    let e = segment(
        &m,
        &noise(80, 80, 1),
        Mode::Resize {
            width: min - 1,
            height: 64,
        },
        "photo P",
        Parallelism::None,
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("photo P") && e.contains(&format!("{min} pixels")),
        "{e}"
    );
    let e = segment(
        &m,
        &noise(60, 90, 1),
        Mode::CenterCrop { size: 64 },
        "photo Q",
        Parallelism::None,
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("photo Q") && e.contains("60×90") && e.contains("crop"),
        "{e}"
    );
}

#[test]
fn a_photo_one_window_large_slides_to_its_resize() {
    let m = model();
    let p = noise(64, 64, 9);
    let slid = segment(&m, &p, Mode::Slide { size: 64 }, "p", Parallelism::None).unwrap();
    let resized = segment(
        &m,
        &p,
        Mode::Resize {
            width: 64,
            height: 64,
        },
        "p",
        Parallelism::None,
    )
    .unwrap();
    assert_eq!(slid, resized);
}

#[test]
fn whole_mode_is_a_resize_to_the_aspect_kept_size() {
    let m = model();
    // mmcv's rounding: 90 × 70 with a shorter side of 64 → 82.3 → 82 × 64; a panorama is
    // capped at 4 × 64 on its longer side.
    assert_eq!(nrw_segment::segment::whole_size(90, 70, 64), (82, 64));
    assert_eq!(nrw_segment::segment::whole_size(1000, 50, 64), (256, 13));
    assert_eq!(nrw_segment::segment::whole_size(64, 64, 64), (64, 64));
    let p = noise(90, 70, 12);
    let whole = segment(&m, &p, Mode::Whole { size: 64 }, "p", Parallelism::None).unwrap();
    let resized = segment(
        &m,
        &p,
        Mode::Resize {
            width: 82,
            height: 64,
        },
        "p",
        Parallelism::None,
    )
    .unwrap();
    assert_eq!(whole, resized);
    let e = segment(
        &m,
        &noise(1000, 50, 1),
        Mode::Whole { size: 64 },
        "panorama",
        Parallelism::None,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("panorama") && e.contains("13-pixel"), "{e}");
}

#[test]
fn overlapping_windows_average_their_logits() {
    // A photo 164 × 64 at window 64 (no rescale): windows every 40 pixels (two thirds of 64,
    // on the grid of 4), the last flush with the right edge: x = 0, 40, 80, 100.
    use nrw_segment::segment::{slide_logits, slide_windows};
    assert_eq!(slide_windows(164, 64), [0, 40, 80, 100]);
    assert_eq!(slide_windows(64, 64), [0]);
    assert_eq!(slide_windows(100, 64), [0, 36]);
    let m = model();
    let p = noise(164, 64, 10);
    let slid = slide_logits(&m, &p, 64, "p", Parallelism::None).unwrap();
    assert_eq!((slid.w, slid.h), (41, 16));
    // Each window's logits by hand, summed and averaged where windows overlap.
    let starts = [0u32, 40, 80, 100];
    let wins: Vec<Map> = starts
        .iter()
        .map(|&x0| {
            let w = image::imageops::crop_imm(&p, x0, 0, 64, 64).to_image();
            m.logits(&preprocess::normalize(&w), 64, 64, Parallelism::None)
        })
        .collect();
    let mut overlapped = 0;
    for gy in 0..16 {
        for gx in 0..41usize {
            let cover: Vec<(usize, usize)> = starts
                .iter()
                .enumerate()
                .filter(|(_, &x0)| (x0 as usize / 4..x0 as usize / 4 + 16).contains(&gx))
                .map(|(k, &x0)| (k, gx - x0 as usize / 4))
                .collect();
            assert!(!cover.is_empty(), "cell {gx} is covered");
            if cover.len() > 1 {
                overlapped += 1;
            }
            for c in 0..slid.c {
                let mut sum = 0f32;
                for &(k, lx) in &cover {
                    sum += wins[k].data[(gy * 16 + lx) * slid.c + c];
                }
                let want = sum * (1.0 / cover.len() as f32);
                let got = slid.data[(gy * 41 + gx) * slid.c + c];
                assert!(
                    (got - want).abs() <= 1e-5 * want.abs().max(1.0),
                    "cell ({gx}, {gy}) class {c}: {got} vs {want} from windows {cover:?}"
                );
            }
        }
    }
    // Grid columns 10–15 lie under two windows, 20–35 under two or three (25 under three).
    assert_eq!(overlapped, 16 * (6 + 16));
    // The label map covers the whole photo.
    let labels = segment(&m, &p, Mode::Slide { size: 64 }, "p", Parallelism::None).unwrap();
    assert_eq!((labels.width(), labels.height()), (164, 64));
}

#[test]
fn a_centre_crop_is_the_crops_own_segmentation_with_zeros_around() {
    let m = model();
    let p = noise(90, 70, 11);
    let got = segment(
        &m,
        &p,
        Mode::CenterCrop { size: 64 },
        "p",
        Parallelism::None,
    )
    .unwrap();
    let crop = image::imageops::crop_imm(&p, 13, 3, 64, 64).to_image();
    let inner = segment(
        &m,
        &crop,
        Mode::Resize {
            width: 64,
            height: 64,
        },
        "crop",
        Parallelism::None,
    )
    .unwrap();
    for y in 0..70 {
        for x in 0..90 {
            let v = got.get_pixel(x, y)[0];
            if (13..77).contains(&x) && (3..67).contains(&y) {
                assert_eq!(v, inner.get_pixel(x - 13, y - 3)[0]);
            } else {
                assert_eq!(v, 0, "outside the crop at ({x}, {y})");
            }
        }
    }
}

#[test]
fn pil_bilinear_resize_equals_pillow_byte_for_byte() {
    if !python::python_has("import PIL, numpy") {
        return;
    }
    let src = noise(37, 23, 5);
    let dir = tempfile::tempdir().unwrap();
    let raw = dir.path().join("src.raw");
    std::fs::write(&raw, src.as_raw()).unwrap();
    // Every combination of growing, shrinking and keeping each axis, including the one where
    // Pillow runs the vertical pass first (wider and shorter).
    let sizes = [
        (512u32, 512u32),
        (5, 3),
        (1, 1),
        (37, 9),
        (100, 23),
        (36, 24),
        (74, 11),
        (38, 22),
        (300, 40),
        (20, 5),
        (40, 100),
        (37, 60),
        (10, 23),
    ];
    let script = format!(
        "import sys, numpy as np\nfrom PIL import Image\nsrc = Image.fromarray(np.fromfile('{}', np.uint8).reshape(23, 37, 3))\nfor w, h in {:?}:\n    sys.stdout.buffer.write(np.asarray(src.resize((w, h), Image.BILINEAR)).tobytes())\n",
        raw.display(),
        sizes
    );
    let out = std::process::Command::new("python3")
        .args(["-c", &script])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut at = 0;
    for (w, h) in sizes {
        let n = (w * h * 3) as usize;
        let ours = preprocess::pil_bilinear(&src, w, h);
        assert_eq!(ours.as_raw().as_slice(), &out.stdout[at..at + n], "{w}×{h}");
        at += n;
    }
}
