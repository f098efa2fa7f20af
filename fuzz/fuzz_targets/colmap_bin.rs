#![no_main]
use libfuzzer_sys::fuzz_target;

#[path = "split.rs"]
mod split;

fuzz_target!(|data: &[u8]| {
    let files = split::split(data, "bin");
    if let Ok(rec) = nrw_colmap::model_from_bytes(nrw_colmap::Format::Binary, &files) {
        let _ = nrw_colmap::reprojection_stats(&rec);
    }
});
