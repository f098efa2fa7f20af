//! `nrw-etl densify`: multi-view stereo and fusion on the CPU, writing COLMAP's dense
//! workspace (`SCENE/dense`) so that `ingest SCENE` renders the dense cloud.

use std::path::PathBuf;

use clap::Args;
use nrw_colmap::dense::MapPass;

use super::Bars;
use crate::error::Result;

/// Arguments of `densify`.
#[derive(Debug, Args)]
#[command(after_help = "Examples:
  nrw-etl densify ../shared/data/sacre_coeur --out /tmp/sacre_coeur_dense
  nrw-etl densify /tmp/scene                   # writes /tmp/scene/dense, then:
  nrw-etl ingest /tmp/scene --out /tmp/ds      # finds /tmp/scene/dense/fused.ply

The workspace is COLMAP's: `colmap stereo_fusion --workspace_path DIR --input_type geometric`
reads it unchanged. stereo/confidence_maps/NAME.geometric.bin (ours) holds, per pixel, the mean
NCC of the source views that agree with the kept depth and their count (0, 0 where no depth).

Work units (a cluster, a Slurm array): every unit of the photometric pass, then every unit of
the geometric pass, then finalize, which fuses and publishes. Any split gives the bytes of one
process; a rerun unit resumes. The workspace is on a shared file system, or --out is an
object-store URL and each node needs only the scene and the bucket (docs/densify.md):
  for i in 0 1 2 3; do nrw-etl densify SCENE --unit $i/4 --pass photometric; done
  for i in 0 1 2 3; do nrw-etl densify SCENE --unit $i/4 --pass geometric; done
  nrw-etl densify SCENE --finalize
  nrw-etl densify SCENE --unit 0/4 --pass photometric --out s3://bucket/scene/dense   # and so on
(units, passes and finalize take the same settings; a unit that differs is refused)")]
pub struct DensifyArgs {
    /// The scene folder (sparse model in sparse/0 or sparse/, photos in images/)
    pub scene: PathBuf,
    /// Where to write the dense workspace: a folder or an object-store URL (s3://, gs://,
    /// az://) [default: SCENE/dense]
    #[arg(long)]
    pub out: Option<nrw_dataset::Location>,
    #[command(flatten)]
    pub settings: nrw_pipeline::settings::densify::DensifySettings,
    /// The photo folder, if not the scene's images/
    #[arg(long)]
    pub images: Option<PathBuf>,
    /// Let photo names resolve through symbolic links out of the photo folder
    #[arg(long)]
    pub follow_outside_links: bool,
    #[command(flatten)]
    pub unit: super::UnitArgs,
    /// The stereo pass a work unit runs (with --unit): photometric first, then geometric
    #[arg(long, value_parser = ["photometric", "geometric"], requires = "unit")]
    pub pass: Option<String>,
    /// Fuse the maps the work units wrote and publish the workspace
    #[arg(long, conflicts_with_all = ["unit", "pass"])]
    pub finalize: bool,
    /// Stop a pass after this many views, as an interruption would (for resume tests)
    #[arg(long, hide = true)]
    pub stop_after_views: Option<usize>,
    /// Hide progress bars
    #[arg(long, short)]
    pub quiet: bool,
}

/// Run `densify`.
pub fn run(args: &DensifyArgs) -> Result<()> {
    let mut cfg = args.settings.config(&args.scene);
    cfg.out = args.out.clone();
    cfg.images = args.images.clone();
    cfg.follow_outside_links = args.follow_outside_links;
    cfg.stop_after_views = args.stop_after_views;
    let bars = Bars::new(args.quiet);
    if let Some(unit) = args.unit.unit()? {
        let pass = match args.pass.as_deref() {
            Some("geometric") => MapPass::Geometric,
            Some(_) => MapPass::Photometric,
            None => {
                return Err(crate::error::EtlError::Flag {
                    flag: "--unit".into(),
                    problem: "needs --pass photometric or --pass geometric".into(),
                })
            }
        };
        let report = nrw_pipeline::densify::densify_unit(&cfg, pass, unit, &bars)?;
        super::print_report(&nrw_pipeline::report::densify_unit(&report));
        return Ok(());
    }
    let report = if args.finalize {
        nrw_pipeline::densify::finalize_densify(&cfg, &bars)?
    } else {
        nrw_pipeline::densify::densify(&cfg, &bars)?
    };
    super::print_report(&nrw_pipeline::report::densify(&report));
    Ok(())
}
