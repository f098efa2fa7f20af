//! The commands of nrw-etl: one variant each, and the arm that runs it and turns its outcome
//! into the process's exit code. Adding a stage is its variant and its arm here (with its
//! module in nrw-pipeline); a command with its own printing adds a file in `cmd/`.

use crate::cmd;

/// The subcommands, one per stage or tool.
#[derive(Debug, clap::Subcommand)]
pub enum Command {
    /// Build the embedded synthetic landmark scene and run every stage on it (start here)
    Demo(cmd::demo::DemoArgs),
    /// Generate a synthetic COLMAP scene with ground truth from a spec (scenes/*.toml)
    Synth(cmd::synth::SynthArgs),
    /// Dense depth maps and a fused cloud from a sparse scene (CPU multi-view stereo), in
    /// COLMAP's dense workspace, so ingest finds SCENE/dense/fused.ply
    Densify(cmd::densify::DensifyArgs),
    /// Summarise a COLMAP model (counts, camera models, reprojection errors) or a dataset (verdicts, split)
    Inspect(cmd::inspect::InspectArgs),
    /// Render every registered photo's view, apply the filters, write shards, scene tables and manifest.json.
    ///
    /// Exit codes: 0 done; 1 error (message names file, record and field); 3 done, but every
    /// view was dropped by the filters (the dataset records each verdict); 130 interrupted
    /// (run again to resume).
    Ingest(cmd::ingest::IngestArgs),
    /// ADE20K label maps of a scene's photos from a SegFormer you give (the paper's segmentation step)
    Segment(cmd::segment::SegmentArgs),
    /// Assign kept photos to train and val (seeded, incremental: earlier assignments never change)
    Split(cmd::split::SplitArgs),
    /// Style descriptors of a dataset's kept photos, or the VGG Gram matrices of one image (--image)
    Style(cmd::style::StyleArgs),
    /// Per anchor photo, the k nearest and k furthest photos in style (exact; train split by default)
    Triplets(cmd::triplets::TripletsArgs),
    /// Write a dataset as files: the paper's official train/ val/ layout, or one folder per photo
    Export(cmd::export::ExportArgs),
    /// Write the dataset QA report (report.html, qa.json): counts, drops, distributions, alignment, split, triplets
    Qa(cmd::qa::QaArgs),
    /// Run the stages a pipeline file lists (pipelines/paper.toml: the paper's settings)
    Run(cmd::run::RunArgs),
    /// Check a dataset against its manifest: every file's size, SHA-256 and rows (exit 4 on a mismatch)
    Verify(cmd::verify::VerifyArgs),
    /// Merge the work units (`ingest --unit I/N`, `style --unit I/N`) into the dataset's tables and manifest
    Finalize(cmd::finalize::FinalizeArgs),
    /// Index a many-scene run: one row per scene (counts, verdicts, report, or its error)
    Corpus(cmd::corpus::CorpusArgs),
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
        Command::Demo(a) => done(cmd::demo::run(a)),
        Command::Synth(a) => done(cmd::synth::run(a)),
        Command::Densify(a) => done(cmd::densify::run(a)),
        Command::Inspect(a) => done(cmd::inspect::run(a)),
        Command::Split(a) => done(cmd::split::run(a)),
        Command::Segment(a) => done(cmd::segment::run(a)),
        Command::Export(a) => done(cmd::export::run(a)),
        Command::Finalize(a) => done(cmd::finalize::run(a)),
        Command::Corpus(a) => done(cmd::corpus::run(a)),
        Command::Verify(a) => cmd::verify::run(a).map(|ok| code(ok, cmd::verify::EXIT_MISMATCH)),
        Command::Style(a) => done(cmd::style::run(a)),
        Command::Triplets(a) => done(cmd::triplets::run(a)),
        Command::Qa(a) => done(cmd::qa::run(a)),
        Command::Run(a) => cmd::run::run(a).map(|kept| code(kept, cmd::ingest::EXIT_NOTHING_KEPT)),
        Command::Ingest(a) => {
            cmd::ingest::run(a).map(|kept| code(kept, cmd::ingest::EXIT_NOTHING_KEPT))
        }
    }
}
