//! `nrw-etl synth`: generate a synthetic scene from a spec file (or the embedded demo spec).

use std::path::PathBuf;

use clap::Args;

use super::Bars;
use crate::error::Result;

/// Arguments of `synth`.
#[derive(Debug, Args)]
pub struct SynthArgs {
    /// Scene spec (TOML; see scenes/*.toml) [default: the embedded demo scene]
    pub spec: Option<PathBuf>,
    /// Folder to write the scene into (images/, sparse/0/, dense/, ground_truth/)
    #[arg(long)]
    pub out: PathBuf,
    /// Override the spec's seed
    #[arg(long)]
    pub seed: Option<u64>,
}

/// Run `synth`.
pub fn run(args: &SynthArgs) -> Result<()> {
    let spec = nrw_pipeline::synth::load_spec(args.spec.as_deref(), args.seed)?;
    let t = std::time::Instant::now();
    let report = nrw_pipeline::synth::generate(&spec, &args.out, &Bars::new(false))?;
    super::print_report(&nrw_pipeline::report::synth(&report));
    eprintln!("{:?} in {:.1} s", spec.name, t.elapsed().as_secs_f64());
    println!("{}", args.out.display());
    Ok(())
}
