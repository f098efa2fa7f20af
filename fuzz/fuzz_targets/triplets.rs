//! A triplets table, as the trainer's sampler reads it.
//! The code is `nrw_dataset::fuzz_entry::triplets`, shared with the regression tests.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = nrw_dataset::fuzz_entry::triplets(data);
});
