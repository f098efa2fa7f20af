//! A descriptor part's bytes: its rows and kind, each descriptor checked against its CRC-32.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = std::path::Path::new("part.parquet");
    let bytes = bytes::Bytes::copy_from_slice(data);
    let _ = nrw_dataset::descriptors::check_part(path, bytes.clone());
    let _ = nrw_dataset::descriptors::part_in(bytes, path);
});
