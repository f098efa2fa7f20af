//! `cargo bench -p nrw-etl --bench reader`
//!
//! Reader throughput: decoded, aligned 256×256 crops (photo, RGBA render, depth) per second
//! through `nrw_dataset::reader`, against the time to just read the shard bytes (the I/O
//! bound) in the same run, on the demo scene's dataset. Writes docs/bench/reader.md.

use std::path::Path;
use std::time::Instant;

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let tmp = tempfile::tempdir().unwrap();
    nrw_pipeline::runner::demo(
        tmp.path(),
        None,
        None,
        None,
        &nrw_pipeline::Silent,
        &mut |_| {},
    )
    .expect("the demo pipeline");
    let ds_dir = tmp.path().join("dataset");
    nrw_pipeline::split::split(&nrw_pipeline::split::SplitConfig {
        val: 0,
        ..nrw_pipeline::split::SplitConfig::new(&ds_dir)
    })
    .expect("split");
    let ds = nrw_dataset::reader::Dataset::open(&ds_dir).unwrap();
    let shards: Vec<_> = ds
        .manifest
        .tables
        .iter()
        .filter(|t| nrw_dataset::views::is_shard(&t.path))
        .map(|t| ds_dir.join(&t.path))
        .collect();
    let n = ds.len();
    let rounds = 5;
    // I/O bound: the bytes of every shard, read whole (page cache warm after the first round).
    let mut bytes = 0u64;
    let t = Instant::now();
    for _ in 0..rounds {
        for s in &shards {
            bytes += std::hint::black_box(std::fs::read(s).unwrap()).len() as u64;
        }
    }
    let read_s = t.elapsed().as_secs_f64() / rounds as f64;
    // Reader: stream the split, decode the three channels, take one aligned crop per view.
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut pick = |mx: u32, my: u32| {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (
            (state % (mx as u64 + 1)) as u32,
            ((state >> 32) % (my as u64 + 1)) as u32,
        )
    };
    let t = Instant::now();
    let mut crops = 0;
    for _ in 0..rounds {
        for v in ds.iter_split("train").unwrap() {
            let c = v.unwrap().random_crop(256, &mut pick).unwrap();
            std::hint::black_box(&c);
            crops += 1;
        }
    }
    let crop_s = t.elapsed().as_secs_f64() / rounds as f64;
    let per_view_bytes = bytes as f64 / rounds as f64 / n as f64;
    let md = format!(
        "# Reader throughput\n\nRegenerate: `cargo bench -p nrw-etl --bench reader`. Dataset: the demo scene ({n} kept views, \
         renders about 800×600, {:.2} MB per view in the shards), one thread, page cache warm.\n\n\
         | what | views / s | time per view |\n|---|---|---|\n\
         | read the shard bytes only (I/O bound) | {:.0} | {:.2} ms |\n\
         | stream + decode photo, RGBA render, EXR depth + one aligned 256×256 crop | {:.1} | {:.2} ms |\n\n\
         Decoding costs **{:.0}×** the I/O bound: the reader is decode-bound (PNG and EXR), so a trainer should decode \
         on several threads; reading is not the limit. ({crops} crops timed.)\n",
        per_view_bytes / 1e6,
        n as f64 / read_s,
        read_s / n as f64 * 1e3,
        n as f64 / crop_s,
        crop_s / n as f64 * 1e3,
        crop_s / read_s,
    );
    print!("{md}");
    std::fs::create_dir_all(root.join("docs/bench")).unwrap();
    std::fs::write(root.join("docs/bench/reader.md"), md).unwrap();
}
