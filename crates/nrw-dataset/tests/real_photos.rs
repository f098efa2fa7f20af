//! Strict photo decoding on real internet photos (../shared/data): every one decodes, to
//! exactly the pixels the lenient decode (libjpeg's warnings allowed) gives, so strictness
//! costs no real photo.

#[path = "../../../tests/support/shared.rs"]
mod shared;

#[test]
fn every_real_photo_decodes_strictly_to_the_lenient_decoders_pixels() {
    use nrw_dataset::jpeg::{decode, Decoded};
    let mut n = 0;
    for scene in ["data/sacre_coeur/images", "data/sceaux_castle/images"] {
        let Some(dir) = shared::shared(scene) else {
            return;
        };
        for e in std::fs::read_dir(&dir).unwrap() {
            let p = e.unwrap().path();
            let ours = nrw_dataset::codec::load_photo(&p)
                .unwrap_or_else(|e| panic!("{} is a good photo: {e}", p.display()));
            // Strictness refuses nothing real: libjpeg warned of nothing, so the lenient decode
            // (warnings allowed) is the same pixels. (Pillow's equality: tests/jpeg.rs.)
            let bytes = std::fs::read(&p).unwrap();
            let Ok(Decoded::Rgb { data, .. }) = decode(&bytes, u64::MAX, false) else {
                panic!("{}: an RGB JPEG", p.display())
            };
            assert!(ours.as_raw() == &data, "{}: other pixels", p.display());
            let other = image::open(&p).unwrap();
            assert_eq!(ours.dimensions(), (other.width(), other.height()));
            n += 1;
        }
    }
    assert_eq!(n, 21, "10 + 11 photos");
}
