//! A view shard through the dataset reader: Parquet, schema, every payload's CRC-32, then
//! every decoder of the rows that pass.
//! The code is `nrw_dataset::fuzz_entry::shard`, shared with the regression tests.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = nrw_dataset::fuzz_entry::shard(data);
});
