//! Photos decode to the pixels the Python ecosystem gets: every JPEG of ../shared/data through
//! our decoder (libjpeg-turbo's, `nrw_dataset::jpeg`) equals Pillow's decode byte for byte, so
//! parity with PyTorch, transformers or the published TensorFlow code holds for JPEG inputs.

use std::process::Command;

use super::{data, python_has};

/// Pillow's RGB bytes of an image file.
fn pillow_rgb(path: &std::path::Path) -> Vec<u8> {
    let o = Command::new("python3")
        .args([
            "-c",
            "import sys, numpy as np; from PIL import Image; \
             sys.stdout.buffer.write(np.asarray(Image.open(sys.argv[1]).convert('RGB')).tobytes())",
        ])
        .arg(path)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    o.stdout
}

#[test]
fn every_real_jpeg_decodes_to_pillows_pixels() {
    let Some(_) = super::shared::shared("data") else {
        return;
    };
    if !python_has("import PIL, numpy") {
        return;
    }
    let mut photos = Vec::new();
    for dir in [
        "sacre_coeur/images",
        "sceaux_castle/images",
        "sacre_coeur/dense/images",
    ] {
        for e in std::fs::read_dir(data().join(dir)).unwrap().flatten() {
            if e.path()
                .extension()
                .is_some_and(|x| x.eq_ignore_ascii_case("jpg"))
            {
                photos.push(e.path());
            }
        }
    }
    assert!(photos.len() >= 30, "{} photos", photos.len());
    let mut pixels = 0usize;
    for p in &photos {
        let ours = nrw_dataset::codec::load_photo(p).unwrap();
        let theirs = pillow_rgb(p);
        assert_eq!(ours.len(), theirs.len(), "{}", p.display());
        let differ = ours
            .as_raw()
            .chunks(3)
            .zip(theirs.chunks(3))
            .filter(|(a, b)| a != b)
            .count();
        assert_eq!(
            differ,
            0,
            "{}: {differ} pixels differ from Pillow's",
            p.display()
        );
        pixels += ours.len() / 3;
    }
    eprintln!(
        "{} JPEGs, {pixels} pixels: all equal to Pillow's",
        photos.len()
    );
}
