//! `nrw-train`: pretrain the appearance encoder on a dataset's style triplets.

use std::path::PathBuf;

use clap::Parser;
use indicatif::{ProgressBar, ProgressStyle};
use nrw_trainer::{train, TrainConfig};

/// Pretrain the paper's appearance encoder (photo + deep buffer → 8-D) with the triplet loss
/// max(‖e_a − e_p‖² − ‖e_a − e_n‖² + α, 0) on a dataset's triplets.
///
/// Needs a dataset that went through `nrw-etl ingest`, `split`, `style` and `triplets`. Prints
/// held-out triplet accuracy before and after (photos held out are never trained on) and, on
/// synthetic scenes, how well the embedding separates the true appearances. Checkpoints (weights
/// and optimiser state) go to --out; running again with the same settings resumes.
#[derive(Debug, Parser)]
#[command(name = "nrw-train", version)]
struct Args {
    /// Dataset folder
    dataset: PathBuf,
    /// Training steps
    #[arg(long, default_value_t = 1000)]
    steps: u64,
    /// Triplets per step
    #[arg(long, default_value_t = 8)]
    batch: usize,
    /// Crop side in pixels (the paper: 256)
    #[arg(long, default_value_t = 256)]
    crop: u32,
    /// Adam learning rate
    #[arg(long, default_value_t = 1e-3)]
    lr: f64,
    /// Triplet margin α
    #[arg(long, default_value_t = 0.1)]
    margin: f64,
    /// Positive drawn among this many nearest
    #[arg(long, default_value_t = 5)]
    pos_k: usize,
    /// Negative drawn among this many furthest
    #[arg(long, default_value_t = 13)]
    neg_k: usize,
    /// Split to train on
    #[arg(long, default_value = "train")]
    split: String,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Checkpoint folder [default: DATASET/appearance]
    #[arg(long)]
    out: Option<PathBuf>,
    /// Steps between checkpoints
    #[arg(long, default_value_t = 100)]
    checkpoint_every: u64,
    /// No progress bar
    #[arg(long)]
    quiet: bool,
}

fn main() -> std::process::ExitCode {
    let a = Args::parse();
    let cfg = TrainConfig {
        steps: a.steps,
        batch: a.batch,
        crop: a.crop,
        lr: a.lr,
        margin: a.margin,
        dim: 8,
        pos_k: a.pos_k,
        neg_k: a.neg_k,
        hold_out_every: 5,
        seed: a.seed,
        checkpoint_every: a.checkpoint_every.max(1),
    };
    let out = a
        .out
        .clone()
        .unwrap_or_else(|| a.dataset.join("appearance"));
    let run = || -> nrw_trainer::Result<nrw_trainer::Report> {
        let ds = nrw_dataset::reader::Dataset::open(nrw_dataset::Store::open(
            &a.dataset.as_path().into(),
        )?)?;
        let bar = if a.quiet {
            ProgressBar::hidden()
        } else {
            ProgressBar::new(a.steps).with_style(
                ProgressStyle::with_template(
                    "train [{bar:30}] {pos}/{len} steps, loss {msg} {elapsed} (eta {eta})",
                )
                .expect("template")
                .progress_chars("=> "),
            )
        };
        let r = train(&ds, &a.split, &cfg, &out, &mut |step, loss| {
            bar.set_position(step);
            bar.set_message(format!("{loss:.4}"));
        })?;
        bar.finish_and_clear();
        Ok(r)
    };
    match run() {
        Ok(r) => {
            if let Some(s) = r.resumed_from {
                eprintln!("resumed from step {s}");
            }
            println!(
                "held-out triplet accuracy {:.3} → {:.3} ({} triplets; chance 0.5)",
                r.accuracy_before, r.accuracy_after, r.held_out_triplets
            );
            if let Some((b, f)) = r.class_agreement {
                println!("true appearance shared by 3 nearest embeddings: {b:.3} → {f:.3}");
            }
            println!(
                "checkpoint: {}",
                out.join("checkpoint.safetensors").display()
            );
            std::process::ExitCode::SUCCESS
        }
        Err(nrw_trainer::TrainError::Setting { setting, problem }) => {
            // The library names its config field; the user typed a flag.
            eprintln!("error: --{}: {problem}", setting.replace('_', "-"));
            std::process::ExitCode::FAILURE
        }
        Err(e) => {
            eprintln!("error: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}
