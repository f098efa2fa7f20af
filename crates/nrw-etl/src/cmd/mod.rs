//! One module per subcommand: each turns its arguments into a stage's config, calls the
//! stage in nrw-pipeline, and prints what it did.

pub mod corpus;
pub mod demo;
pub mod densify;
pub mod export;
pub mod finalize;
pub mod ingest;
pub mod inspect;
pub mod qa;
pub mod run;
pub mod segment;
pub mod split;
pub mod style;
pub mod synth;
pub mod triplets;
pub mod verify;

/// The subcommands, one per stage or tool; each arm below runs one and turns its outcome
/// into the process's exit code. Adding a stage is its variant and its arm here.
#[derive(Debug, clap::Subcommand)]
pub enum Command {
    /// Build the embedded synthetic landmark scene and run every stage on it (start here)
    Demo(demo::DemoArgs),
    /// Generate a synthetic COLMAP scene with ground truth from a spec (scenes/*.toml)
    Synth(synth::SynthArgs),
    /// Dense depth maps and a fused cloud from a sparse scene (CPU multi-view stereo), in
    /// COLMAP's dense workspace, so ingest finds SCENE/dense/fused.ply
    Densify(densify::DensifyArgs),
    /// Summarise a COLMAP model (counts, camera models, reprojection errors) or a dataset (verdicts, split)
    Inspect(inspect::InspectArgs),
    /// Render every registered photo's view, apply the filters, write shards, scene tables and manifest.json.
    ///
    /// Exit codes: 0 done; 1 error (message names file, record and field); 3 done, but every
    /// view was dropped by the filters (the dataset records each verdict); 130 interrupted
    /// (run again to resume).
    Ingest(ingest::IngestArgs),
    /// ADE20K label maps of a scene's photos from a SegFormer you give (the paper's segmentation step)
    Segment(segment::SegmentArgs),
    /// Assign kept photos to train and val (seeded, incremental: earlier assignments never change)
    Split(split::SplitArgs),
    /// Style descriptors of a dataset's kept photos, or the VGG Gram matrices of one image (--image)
    Style(style::StyleArgs),
    /// Per anchor photo, the k nearest and k furthest photos in style (exact; train split by default)
    Triplets(triplets::TripletsArgs),
    /// Write a dataset as files: the paper's official train/ val/ layout, or one folder per photo
    Export(export::ExportArgs),
    /// Write the dataset QA report (report.html, qa.json): counts, drops, distributions, alignment, split, triplets
    Qa(qa::QaArgs),
    /// Run the stages a pipeline file lists (pipelines/paper.toml: the paper's settings)
    Run(run::RunArgs),
    /// Check a dataset against its manifest: every file's size, SHA-256 and rows (exit 4 on a mismatch)
    Verify(verify::VerifyArgs),
    /// Merge the work units (`ingest --unit I/N`, `style --unit I/N`) into the dataset's tables and manifest
    Finalize(finalize::FinalizeArgs),
    /// Index a many-scene run: one row per scene (counts, verdicts, report, or its error)
    Corpus(corpus::CorpusArgs),
}

impl Command {
    /// The `--threads` the command asks for, if it takes one.
    pub fn threads(&self) -> Option<usize> {
        match self {
            Command::Ingest(a) => a.threads,
            Command::Segment(a) => a.threads,
            _ => None,
        }
    }
}

/// Run `command`: success, an error, or one of the command's own documented exit codes.
pub fn run(command: &Command) -> crate::error::Result<std::process::ExitCode> {
    let code = |fine: bool, other: u8| {
        if fine {
            std::process::ExitCode::SUCCESS
        } else {
            std::process::ExitCode::from(other)
        }
    };
    let done = |r: crate::error::Result<()>| r.map(|()| std::process::ExitCode::SUCCESS);
    match command {
        Command::Demo(a) => done(demo::run(a)),
        Command::Synth(a) => done(synth::run(a)),
        Command::Densify(a) => done(densify::run(a)),
        Command::Inspect(a) => done(inspect::run(a)),
        Command::Split(a) => done(split::run(a)),
        Command::Segment(a) => done(segment::run(a)),
        Command::Export(a) => done(export::run(a)),
        Command::Finalize(a) => done(finalize::run(a)),
        Command::Corpus(a) => done(corpus::run(a)),
        Command::Verify(a) => verify::run(a).map(|ok| code(ok, verify::EXIT_MISMATCH)),
        Command::Style(a) => done(style::run(a)),
        Command::Triplets(a) => done(triplets::run(a)),
        Command::Qa(a) => done(qa::run(a)),
        Command::Run(a) => run::run(a).map(|kept| code(kept, ingest::EXIT_NOTHING_KEPT)),
        Command::Ingest(a) => ingest::run(a).map(|kept| code(kept, ingest::EXIT_NOTHING_KEPT)),
    }
}

use std::sync::Mutex;

use clap::Args;
use nrw_pipeline::{Progress, Unit};

/// Print a stage's report: each line on its stream (results on stdout, the rest on stderr).
pub fn print_report(report: &nrw_pipeline::report::Report) {
    for line in &report.0 {
        match line {
            nrw_pipeline::report::Line::Out(s) => println!("{}", crate::error::flags(s)),
            nrw_pipeline::report::Line::Err(s) => eprintln!("{}", crate::error::flags(s)),
        }
    }
}

/// A clap parser over a library enum's names ([`nrw_pipeline::settings::names`]).
pub use nrw_pipeline::settings::names;

/// `--unit`/`--unit-count`: run one work unit of a stage instead of the whole stage.
#[derive(Debug, Clone, Default, Args)]
pub struct UnitArgs {
    /// Do only work unit I of N (0-based), e.g. 2/8, then `nrw-etl finalize DATASET` once
    /// every unit has run. `auto` reads Slurm array (SLURM_ARRAY_TASK_ID/COUNT) or Kubernetes
    /// Indexed Job (JOB_COMPLETION_INDEX, with --unit-count) variables. `--shard` is its old
    /// name, still taken
    #[arg(long = "unit", alias = "shard", value_name = "I/N|auto")]
    pub unit: Option<String>,
    /// Unit count for --unit auto when the scheduler does not export it (Kubernetes;
    /// `--shard-count` is its old name)
    #[arg(long, alias = "shard-count", value_name = "N")]
    pub unit_count: Option<usize>,
}

impl UnitArgs {
    /// The unit asked for, or `None` for the whole stage.
    pub fn unit(&self) -> crate::error::Result<Option<Unit>> {
        let Some(text) = &self.unit else {
            return Ok(None);
        };
        Ok(Some(Unit::parse(text, self.unit_count, &|k| {
            std::env::var(k).ok()
        })?))
    }
}

/// A stage's progress as a terminal bar with its ETA (hidden with `--quiet`), and its
/// warnings on stderr.
pub struct Bars {
    quiet: bool,
    bar: Mutex<Option<indicatif::ProgressBar>>,
}

impl Bars {
    /// Bars that draw unless `quiet`.
    pub fn new(quiet: bool) -> Bars {
        Bars {
            quiet,
            bar: Mutex::new(None),
        }
    }

    fn with(&self, f: impl FnOnce(&indicatif::ProgressBar)) {
        if let Some(b) = self.bar.lock().expect("bar lock").as_ref() {
            f(b)
        }
    }
}

impl Progress for Bars {
    fn start(&self, what: &str, len: u64, unit: &str) {
        if self.quiet {
            return;
        }
        let b = indicatif::ProgressBar::new(len).with_style(
            indicatif::ProgressStyle::with_template(&format!(
                "{{msg:>10}} [{{bar:30}}] {{pos}}/{{len}} {unit} {{elapsed}} (eta {{eta}})"
            ))
            .expect("valid template")
            .progress_chars("=> "),
        );
        b.set_message(what.to_string());
        *self.bar.lock().expect("bar lock") = Some(b);
    }

    fn inc(&self, n: u64) {
        self.with(|b| b.inc(n));
    }

    fn finish(&self) {
        if let Some(b) = self.bar.lock().expect("bar lock").take() {
            b.finish_and_clear();
        }
    }

    fn warn(&self, message: &str) {
        if !self.quiet {
            eprintln!("warning: {}", crate::error::flags(message));
        }
    }
}
