//! One payload past its CRC-32 into its decoder (the first byte picks the column).
//! The code is `nrw_dataset::fuzz_entry::payload`, shared with the regression tests.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = nrw_dataset::fuzz_entry::payload(data);
});
