//! A triplets table's bytes, as the trainer's sampler reads them.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = std::path::Path::new("triplets.parquet");
    let _ = nrw_dataset::triplets::triplets_in(bytes::Bytes::copy_from_slice(data), path);
});
