//! `nrw-etl verify`: a dataset against its manifest, after a copy or before training.

use clap::Args;

use super::Bars;
use crate::error::Result;

/// Exit code when verify ran and found files that differ from the manifest.
pub const EXIT_MISMATCH: u8 = 4;

/// Arguments of `verify`.
#[derive(Debug, Args)]
#[command(
    after_help = "Checks every file manifest.json lists (size, SHA-256, Parquet rows) and
every payload of the shards and descriptor parts (photo, renders, depth, normals, semantics,
descriptors) against the CRC-32 written beside it, so a damaged file is named down to its row
and column.

Exit codes: 0 everything matches; 4 something differs or is missing (each mismatch is
printed: file, field or column and row, expected, found); 1 the dataset could not be read at
all (no manifest, unreachable store). Files the manifest does not list are reported but do
not fail the check: readers ignore them.

Example, after copying a dataset:
  rsync -a ds/ /scratch/ds/ && nrw-etl verify /scratch/ds"
)]
pub struct VerifyArgs {
    /// Dataset folder or object-store URL (s3://, gs://, az://)
    pub dataset: nrw_dataset::Location,
    /// Print the report as JSON on stdout
    #[arg(long)]
    pub json: bool,
    /// No progress bar
    #[arg(long)]
    pub quiet: bool,
}

/// Run `verify`; returns whether the dataset matched its manifest.
pub fn run(args: &VerifyArgs) -> Result<bool> {
    let store = nrw_dataset::Store::open(&args.dataset)?;
    let r = nrw_pipeline::verify::verify(&store, &Bars::new(args.quiet))?;
    for m in &r.mismatches {
        eprintln!(
            "mismatch: {}: {}: expected {}, found {}",
            m.file, m.field, m.expected, m.found
        );
    }
    if !r.unlisted.is_empty() && !args.quiet {
        eprintln!(
            "note: {} file(s) not listed in the manifest (ignored by readers): {}{}",
            r.unlisted.len(),
            r.unlisted
                .iter()
                .take(5)
                .cloned()
                .collect::<Vec<_>>()
                .join(", "),
            if r.unlisted.len() > 5 { ", …" } else { "" }
        );
    }
    if args.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&r).expect("report serialises")
        );
    } else {
        println!(
            "{} {}: {} files, {:.1} MB checked in {:.2} s ({:.0} MB/s), {} mismatch(es)",
            if r.ok() { "verified" } else { "FAILED" },
            r.dataset,
            r.files,
            r.bytes as f64 / 1e6,
            r.seconds,
            r.mb_per_s(),
            r.mismatches.len()
        );
    }
    Ok(r.ok())
}
