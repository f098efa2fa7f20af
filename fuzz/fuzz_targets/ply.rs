#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = nrw_colmap::read_ply_from(data, data.len() as u64, std::path::Path::new("fuzz.ply"));
});
