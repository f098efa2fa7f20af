//! A view shard's bytes through the dataset reader: Parquet, schema, every payload's CRC-32,
//! then every decoder of the rows that pass.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = std::path::Path::new("fuzz.parquet");
    let bytes = bytes::Bytes::copy_from_slice(data);
    let _ = nrw_dataset::views::check_shard(path, bytes.clone());
    if let Ok(views) = nrw_dataset::reader::views_in(bytes, path) {
        for v in views {
            let _ = v.photo();
            let _ = v.color();
            let _ = v.depth();
            let _ = v.semantics();
            let _ = v.transient();
            let _ = v.labels();
            let _ = v.crop_at(1, 1, 8);
        }
    }
});
