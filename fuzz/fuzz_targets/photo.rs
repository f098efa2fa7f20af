//! Photo decoding as ingest does it: format sniffing, strict JPEG, PNG, the size limit
//! (lowered here to 2^24 pixels so the fuzzer's 512 MB allocation limit holds).
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = nrw_dataset::codec::decode_photo(data, 1 << 24);
});
