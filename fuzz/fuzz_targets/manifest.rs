//! A dataset's manifest.json.
//! The code is `nrw_dataset::fuzz_entry::manifest`, shared with the regression tests.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = nrw_dataset::fuzz_entry::manifest(data);
});
