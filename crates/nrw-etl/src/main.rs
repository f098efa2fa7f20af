//! nrw-etl: turns a COLMAP-reconstructed photo collection into the aligned dataset that
//! "Neural Rerendering in the Wild" (Meshry et al., CVPR 2019) trains on.

mod cmd;
mod commands;
mod error;
mod heap;

#[global_allocator]
static HEAP: heap::Counting = heap::Counting;

use clap::Parser;

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
    command: commands::Command,
    /// Wait this long before each commit (rename) of an output, saying so on stderr: lets the
    /// kill tests interrupt any stage at a known point
    #[arg(long, global = true, hide = true, value_name = "MS")]
    pause_before_commit_ms: Option<u64>,
    /// Write the most heap bytes the run held at once, and the bytes it allocated in all, to
    /// this file when it ends (the memory tests' measure of what a step allocates itself)
    #[arg(long, global = true, hide = true, value_name = "FILE")]
    heap_file: Option<std::path::PathBuf>,
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
    if let Some(n) = cli.command.threads() {
        if let Err(e) = rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
        {
            eprintln!("error: --threads {n}: {e}");
            return std::process::ExitCode::FAILURE;
        }
    }
    // NRW_ISA caps the GEMM kernels' instruction set (how one machine computes what a
    // narrower one does); a value it cannot honour stops the run before any work.
    if let Err(e) = nrw_gemm::configured() {
        eprintln!("error: {e}");
        return std::process::ExitCode::FAILURE;
    }
    let result = commands::run(&cli.command);
    if let Some(file) = &cli.heap_file {
        if let Err(e) = std::fs::write(file, heap::report()) {
            eprintln!("error: --heap-file {}: {e}", file.display());
            return std::process::ExitCode::FAILURE;
        }
    }
    match result {
        Ok(code) => code,
        Err(e) if e.interrupted() => {
            eprintln!("{}", error::flags(&e.to_string()));
            std::process::ExitCode::from(130)
        }
        Err(e) => {
            let keys = e.names_keys();
            error::error_lines(&e)
                .iter()
                .for_each(|l| eprintln!("{}", if keys { l.clone() } else { error::flags(l) }));
            std::process::ExitCode::FAILURE
        }
    }
}
