//! The fuzz target's seeds (`fuzz/seeds/npy/`, written by numpy's own `np.save` of a dict of
//! layers, as tensorflow-vgg's `vgg16.npy` is) read back, and every truncation of them and
//! every single flipped byte is an error or a read, never a panic.

use std::path::Path;

fn seeds() -> Vec<Vec<u8>> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz/seeds/npy");
    let mut out: Vec<Vec<u8>> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| std::fs::read(e.unwrap().path()).unwrap())
        .collect();
    out.sort();
    assert!(!out.is_empty(), "no seed in {}", dir.display());
    out
}

#[test]
fn numpys_own_file_reads_and_no_truncation_or_flipped_byte_panics() {
    for bytes in seeds() {
        let layers = nrw_npy::read::read_layers(&bytes).expect("numpy's file reads");
        assert_eq!(
            layers.keys().map(String::as_str).collect::<Vec<_>>(),
            ["conv1_1", "fc8"]
        );
        assert_eq!(layers["conv1_1"][0].shape, vec![3, 3, 3, 2]);
        assert_eq!(layers["conv1_1"][1].data, vec![0.0, 1.0]);
        for n in 0..bytes.len() {
            assert!(
                nrw_npy::read::read_layers(&bytes[..n]).is_err(),
                "a file cut at {n} of {} bytes read",
                bytes.len()
            );
        }
        for i in 0..bytes.len() {
            let mut b = bytes.clone();
            b[i] ^= 0xff;
            let _ = nrw_npy::read::read_layers(&b);
        }
    }
}
