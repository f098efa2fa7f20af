//! nrw-etl: turns a COLMAP-reconstructed photo collection into the aligned dataset that
//! "Neural Rerendering in the Wild" (Meshry et al., CVPR 2019) trains on.

mod cmd;
mod error;

use clap::{Parser, Subcommand};

/// Command line of nrw-etl.
#[derive(Debug, Parser)]
#[command(
    name = "nrw-etl",
    version,
    about = "Turn a COLMAP-reconstructed photo collection into the aligned dataset of Neural Rerendering in the Wild",
    long_about = "Turn a COLMAP-reconstructed photo collection into the aligned dataset of \
Neural Rerendering in the Wild (Meshry et al., CVPR 2019).\n\n\
A scene folder is laid out as COLMAP writes it: sparse/0/{cameras,images,points3D}.{bin,txt} \
(COLMAP 3 or 4), images/ with the photos, and optionally dense/fused.ply.\n\n\
Try `nrw-etl demo` first: it builds a synthetic scene and runs every stage on it. \
On your own data, start with `nrw-etl inspect SCENE` to check a model, then `nrw-etl ingest SCENE --out DATASET`.",
    after_help = "Examples:\n  nrw-etl demo --out /tmp/nrw-demo\n  nrw-etl synth scenes/demo.toml --out /tmp/scene --seed 3\n  nrw-etl inspect ../shared/data/sceaux_castle\n  nrw-etl inspect ../shared/data/sacre_coeur --json\n  nrw-etl ingest ../shared/data/sceaux_castle --out /tmp/sceaux"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Wait this long before each commit (rename) of an output, saying so on stderr: lets the
    /// kill tests interrupt any stage at a known point
    #[arg(long, global = true, hide = true, value_name = "MS")]
    pause_before_commit_ms: Option<u64>,
}

#[derive(Debug, Subcommand)]
enum Command {
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

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    if let Some(ms) = cli.pause_before_commit_ms {
        // Announced on stderr, so a kill test knows which commit it is at.
        nrw_dataset::atomic::set_commit_hook(Box::new(move |target| {
            eprintln!("nrw-etl: pausing {ms} ms before committing {}", target);
            std::thread::sleep(std::time::Duration::from_millis(ms));
        }));
    }
    let threads = match &cli.command {
        Command::Ingest(a) => a.threads,
        Command::Segment(a) => a.threads,
        _ => None,
    };
    if let Some(n) = threads {
        if let Err(e) = rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
        {
            eprintln!("error: --threads {n}: {e}");
            return std::process::ExitCode::FAILURE;
        }
    }
    // Each command ends in success, an error, or one of its own documented exit codes.
    let code = |fine: bool, other: u8| {
        if fine {
            std::process::ExitCode::SUCCESS
        } else {
            std::process::ExitCode::from(other)
        }
    };
    let done = |r: error::Result<()>| r.map(|()| std::process::ExitCode::SUCCESS);
    let result = match &cli.command {
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
    };
    match result {
        Ok(code) => code,
        Err(e) if e.interrupted() => {
            eprintln!("{}", error::flags(&e.to_string()));
            std::process::ExitCode::from(130)
        }
        Err(e) => {
            error::error_lines(&e)
                .iter()
                .for_each(|l| eprintln!("{}", error::flags(l)));
            std::process::ExitCode::FAILURE
        }
    }
}
