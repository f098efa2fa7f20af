//! A descriptor part: every row's CRC-32, then its kind and rows.
//! The code is `nrw_dataset::fuzz_entry::descriptors`, shared with the regression tests.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = nrw_dataset::fuzz_entry::descriptors(data);
});
