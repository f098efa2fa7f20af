//! One payload through its decoder, past the CRC-32 a mutated shard would fail: the first
//! byte picks the column (photo, colour render, depth EXR, semantics, transient, labels).
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&which, payload)) = data.split_first() else {
        return;
    };
    let p = payload.to_vec();
    let mut v = nrw_dataset::ViewRow {
        image_id: 1,
        name: "fuzz".into(),
        camera_id: 1,
        model: "PINHOLE".into(),
        width: 16,
        height: 16,
        scale_x: 1.0,
        scale_y: 1.0,
        params: vec![16.0, 16.0, 8.0, 8.0],
        qvec: [1.0, 0.0, 0.0, 0.0],
        tvec: [0.0; 3],
        empty_ratio: 0.0,
        photo_png: Vec::new(),
        color_png: Vec::new(),
        depth_exr: Vec::new(),
        normal_png: None,
        semantics_png: None,
        transient_png: None,
        labels_png: None,
    };
    match which % 6 {
        0 => {
            v.photo_png = p;
            let _ = v.photo();
        }
        1 => {
            v.color_png = p;
            let _ = v.color();
        }
        2 => {
            v.depth_exr = p;
            let _ = v.depth();
        }
        3 => {
            v.semantics_png = Some(p);
            let _ = v.semantics();
        }
        4 => {
            v.transient_png = Some(p);
            let _ = v.transient();
        }
        _ => {
            v.labels_png = Some(p);
            let _ = v.labels();
        }
    }
});
