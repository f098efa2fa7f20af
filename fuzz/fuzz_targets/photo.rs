//! Photo decoding as ingest does it: format sniffing, strict JPEG, PNG, the size limit.
//! The code is `nrw_dataset::fuzz_entry::photo`, shared with the regression tests.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = nrw_dataset::fuzz_entry::photo(data);
});
