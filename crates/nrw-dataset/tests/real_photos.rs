//! Strict photo decoding on real internet photos (../shared/data): every one decodes, to
//! exactly the pixels the lenient `image` decoder gives, so strictness costs no real photo.

#[path = "../../../tests/support/shared.rs"]
mod shared;

#[test]
fn every_real_photo_decodes_strictly_to_the_lenient_decoders_pixels() {
    let mut n = 0;
    for scene in ["data/sacre_coeur/images", "data/sceaux_castle/images"] {
        let Some(dir) = shared::shared(scene) else {
            return;
        };
        for e in std::fs::read_dir(&dir).unwrap() {
            let p = e.unwrap().path();
            let ours = nrw_dataset::codec::load_photo(&p)
                .unwrap_or_else(|e| panic!("{} is a good photo: {e}", p.display()));
            let theirs = image::open(&p).unwrap().into_rgb8();
            assert!(ours == theirs, "{}: other pixels", p.display());
            n += 1;
        }
    }
    assert_eq!(n, 21, "10 + 11 photos");
}
