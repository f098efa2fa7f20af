//! `nrw-etl corpus`: the index of a many-scene run (what the Ray driver's `--scenes` calls).

use clap::Args;

use crate::error::Result;

/// Arguments of `corpus`.
#[derive(Debug, Args)]
#[command(
    after_help = "Writes OUT/corpus.parquet (schemas/corpus.toml), one row per scene:
nrw-etl corpus /data/corpus --entries '[{\"scene\": \"/s/a\", \"name\": \"a\", \"dataset\": \"/data/corpus/a\"}]'"
)]
pub struct CorpusArgs {
    /// Corpus prefix: a folder or an object-store URL (s3://, gs://, az://)
    pub out: String,
    /// The scenes as a JSON array of {scene, name, dataset, error (if the scene failed)}
    #[arg(long)]
    pub entries: String,
}

/// Run `corpus`: write the index and print one line per scene.
pub fn run(args: &CorpusArgs) -> Result<()> {
    let entries = nrw_pipeline::corpus::parse_entries(&args.entries)?;
    for r in nrw_pipeline::corpus::index(&args.out, &entries)? {
        println!("{}", corpus_line(&r));
    }
    Ok(())
}

/// One scene of a corpus index, as `nrw-etl corpus` prints it.
fn corpus_line(r: &nrw_dataset::corpus::CorpusRow) -> String {
    match &r.error {
        Some(e) => format!("{}: {} ({}): {e}", r.name, r.status, r.scene),
        None => format!(
            "{}: {}, {} registered, {} kept, {} train / {} val; report {}",
            r.name,
            r.status,
            r.registered.unwrap_or(0),
            r.kept.unwrap_or(0),
            r.train.unwrap_or(0),
            r.val.unwrap_or(0),
            r.report.as_deref().unwrap_or("-")
        ),
    }
}
