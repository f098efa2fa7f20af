//! `cargo bench -p nrw-etl --bench reader`
//!
//! Reader throughput: decoded, aligned 256×256 crops (photo, RGBA render, depth) per second
//! through `nrw_dataset::reader`, against the time to just read the shard bytes (the I/O
//! bound) in the same run, on the demo scene's dataset; and what the CRC-32 check of every
//! payload costs (the same bytes hashed alone). Writes docs/bench/reader.md.

use std::path::Path;
use std::time::Instant;

#[path = "../../../tests/support/cpu.rs"]
mod cpu;

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
    let ds = nrw_dataset::reader::Dataset::open(&ds_dir).unwrap();
    // Every kept view, whatever split the demo gave it.
    let mut all: Vec<u32> = ds
        .splits()
        .iter()
        .flat_map(|(s, _)| ds.ids(s).unwrap().to_vec())
        .collect();
    all.sort_unstable();
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
        for v in ds.iter_ids(&all).unwrap() {
            let c = v.unwrap().random_crop(256, &mut pick).unwrap();
            std::hint::black_box(&c);
            crops += 1;
        }
    }
    let crop_s = t.elapsed().as_secs_f64() / rounds as f64;
    // Streaming rows (Parquet + the CRC-32 of every payload, no decode), and the CRC-32 of
    // the same payload bytes alone: the check's share of a read.
    let t = Instant::now();
    let mut views = Vec::new();
    for _ in 0..rounds {
        views = ds
            .iter_ids(&all)
            .unwrap()
            .map(|v| v.unwrap())
            .collect::<Vec<_>>();
        std::hint::black_box(&views);
    }
    let stream_s = t.elapsed().as_secs_f64() / rounds as f64;
    let payloads: Vec<&[u8]> = views
        .iter()
        .flat_map(|v| {
            [Some(&v.photo_png), Some(&v.color_png), Some(&v.depth_exr)]
                .into_iter()
                .chain(
                    [
                        &v.normal_png,
                        &v.semantics_png,
                        &v.transient_png,
                        &v.labels_png,
                    ]
                    .map(Option::as_ref),
                )
                .flatten()
                .map(|p| p.as_slice())
        })
        .collect();
    let payload_bytes: usize = payloads.iter().map(|p| p.len()).sum();
    let crc_rounds = 20;
    let t = Instant::now();
    for _ in 0..crc_rounds {
        for p in &payloads {
            std::hint::black_box(nrw_dataset::views::crc32(p));
        }
    }
    let crc_s = t.elapsed().as_secs_f64() / crc_rounds as f64;
    let per_view_bytes = bytes as f64 / rounds as f64 / n as f64;
    let md = format!(
        "# Reader throughput\n\nRegenerate: `cargo bench -p nrw-etl --bench reader`. Dataset: the demo scene ({n} kept views, \
         renders about 800×600, {:.2} MB per view in the shards), one thread, page cache warm. Machine: {}.\n\n\
         | what | views / s | time per view | MB/s |\n|---|---|---|---|\n\
         | read the shard bytes only (I/O bound) | {:.0} | {:.2} ms | {:.0} |\n\
         | stream the rows: Parquet (page headers checked first) + CRC-32 of every payload, no decode | {:.0} | {:.2} ms | {:.0} |\n\
         | CRC-32 of the same payload bytes alone | {:.0} | {:.3} ms | {:.0} |\n\
         | stream + decode photo, RGBA render, EXR depth + one aligned 256×256 crop | {:.1} | {:.2} ms | {:.0} |\n\n\
         Decoding costs **{:.0}×** the I/O bound: the reader is decode-bound (PNG and EXR), so a trainer should decode \
         on several threads; reading is not the limit. ({crops} crops timed.)\n\n\
         **What integrity costs.** Every payload a reader hands out is first checked against the CRC-32 written \
         beside it (a changed byte is an error naming file, row and column). Hashing the payloads takes \
         **{:.1}%** of streaming the rows and **{:.2}%** of a decoded crop's time.\n",
        per_view_bytes / 1e6,
        cpu::describe(),
        n as f64 / read_s,
        read_s / n as f64 * 1e3,
        bytes as f64 / rounds as f64 / read_s / 1e6,
        n as f64 / stream_s,
        stream_s / n as f64 * 1e3,
        bytes as f64 / rounds as f64 / stream_s / 1e6,
        n as f64 / crc_s,
        crc_s / n as f64 * 1e3,
        payload_bytes as f64 / crc_s / 1e6,
        n as f64 / crop_s,
        crop_s / n as f64 * 1e3,
        bytes as f64 / rounds as f64 / crop_s / 1e6,
        crop_s / read_s,
        crc_s / stream_s * 100.0,
        crc_s / crop_s * 100.0,
    );
    print!("{md}");
    std::fs::create_dir_all(root.join("docs/bench")).unwrap();
    std::fs::write(root.join("docs/bench/reader.md"), md).unwrap();
}
