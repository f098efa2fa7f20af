#![no_main]
use libfuzzer_sys::fuzz_target;

// A pickled .npy of any bytes: an error or layers, never a panic, a call or a huge allocation.
fuzz_target!(|data: &[u8]| {
    let _ = nrw_npy::read::read_layers(data);
});
