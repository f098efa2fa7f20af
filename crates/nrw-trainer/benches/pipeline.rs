//! `cargo bench -p nrw-trainer --bench pipeline [-- DATASET]`
//!
//! Which one limits training: batches per second of the loader alone (decode + crop +
//! normalise, parallel over the batch) against training steps per second (forward, backward,
//! Adam) at the paper's 256² crops, 8 triplets (24 views) per batch. Without DATASET, runs
//! the demo pipeline first (through nrw-pipeline). Writes docs/bench/trainer.md.

use std::path::{Path, PathBuf};
use std::time::Instant;

use nrw_trainer::model::{input, triplet_loss, Encoder};
use nrw_trainer::{Loader, LoaderConfig};

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let arg = std::env::args().skip(1).find(|a| !a.starts_with("--"));
    let dir = match arg {
        Some(d) => PathBuf::from(d),
        None => {
            let demo = root.join("target/bench-demo");
            nrw_pipeline::runner::demo(&demo, None, None, None, &nrw_pipeline::Silent, &mut |_| {})
                .expect("the demo pipeline");
            demo.join("dataset")
        }
    };
    let ds = nrw_dataset::reader::Dataset::open(&dir).unwrap();
    let (crop, triplets) = (256u32, 8usize);
    let loader = Loader::new(
        &ds,
        "train",
        LoaderConfig {
            crop,
            batch: triplets * 3,
            seed: 0,
            semantics: false,
        },
    )
    .unwrap();
    let ids: Vec<u32> = loader
        .ids()
        .iter()
        .cycle()
        .take(triplets * 3)
        .copied()
        .collect();
    let reps = 6;
    let t = Instant::now();
    let mut last = None;
    for r in 0..reps {
        last = Some(loader.batch_of(&ids, r, 0).unwrap());
    }
    let load = t.elapsed().as_secs_f64() / reps as f64;
    let b = last.unwrap();
    let vm = candle_nn::VarMap::new();
    let enc = Encoder::new(&vm, 8).unwrap();
    let mut opt = nrw_trainer::train::Adam::new(&vm, 1e-3).unwrap();
    let x = input(&b).unwrap();
    let mut step = 0.0;
    for r in 0..reps + 1 {
        let t = Instant::now();
        let e = enc.forward(&x).unwrap();
        let n = triplets;
        let loss = triplet_loss(
            &e.narrow(0, 0, n).unwrap(),
            &e.narrow(0, n, n).unwrap(),
            &e.narrow(0, 2 * n, n).unwrap(),
            0.1,
        )
        .unwrap();
        opt.step(&loss).unwrap();
        if r > 0 {
            step += t.elapsed().as_secs_f64() / reps as f64;
        }
    }
    let threads = rayon::current_num_threads();
    let limit = if load > step {
        "the loader"
    } else {
        "the training step"
    };
    let md = format!(
        "# Trainer: loader against training step\n\nRegenerate: `cargo bench -p nrw-trainer --bench pipeline [-- DATASET]` \
         (default: the demo dataset). {triplets} triplets = {} views per batch, {crop}² crops, {threads} threads, \
         encoder of docs/trainer.md (candle, CPU).\n\n| stage | time per batch | batches / s |\n|---|---|---|\n\
         | loader alone (decode PNG/EXR, crop, normalise; parallel over the batch) | {:.3} s | {:.2} |\n\
         | training step (forward, backward, Adam) | {:.3} s | {:.2} |\n\n**{limit} limits** (the other takes {:.0}% of its time); \
         loading the next batch on another thread while the step runs would hide the shorter one.\n",
        triplets * 3,
        load,
        1.0 / load,
        step,
        1.0 / step,
        100.0 * load.min(step) / load.max(step)
    );
    std::fs::write(root.join("docs/bench/trainer.md"), md).unwrap();
    eprintln!("loader {load:.3} s/batch, step {step:.3} s/batch: {limit} limits; wrote docs/bench/trainer.md");
}
