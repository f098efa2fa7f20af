//! A dataset's manifest.json.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = nrw_dataset::Manifest::parse(data, "manifest.json".into());
});
