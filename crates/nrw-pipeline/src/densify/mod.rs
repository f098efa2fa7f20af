//! The densify stage: a sparse COLMAP scene to COLMAP's dense workspace (`SCENE/dense`), so
//! that ingest finds `dense/fused.ply` and COLMAP's own tools read every file: the
//! undistorted photos and model (`images/`, `sparse/`), PatchMatch depth and normal maps per
//! view (photometric, then geometric), our confidence maps, `patch-match.cfg`, `fusion.cfg`,
//! and the fused cloud with its visibility (`fused.ply`, `fused.ply.vis`).
//!
//! Memory: stereo holds one reference view and its sources at a time (maps are written and
//! read back per view); fusion holds a cache of final maps and colours of a given size
//! (COLMAP's `cache_size`) and one bit per pixel of every view.
//!
//! In files by job: config.rs (what densify is asked, checked), plan.rs (each view's sources
//! and depth range, the passes and units), views.rs (undistorted photos in, grey views out),
//! maps.rs (the workspace's map files), record.rs (`densify.json`, the claim on the output,
//! staging and publishing), fusion.rs (fusion and the finished workspace); here, the stage's
//! three entry points and what they share.

mod config;
mod fusion;
mod maps;
mod outcome;
mod plan;
mod record;
mod views;

use std::path::PathBuf;

use nrw_colmap::dense::{MapPass, Workspace};
use nrw_colmap::UndistortOptions;

use crate::error::{PipelineError, Result, Setting};
use crate::{Progress, Unit};
use config::{check, Settings};
use fusion::finish;
use plan::{plan, run_pass, Prepared};
use record::{claim, read_record, settings_differ, staging_dir, Record};
use views::{entries, undistort_views};

pub use config::{
    DensifyConfig, DEFAULT_FUSION_CACHE_MB, DEFAULT_MAX_IMAGE_SIZE, DEFAULT_MAX_SOURCES,
};
pub use outcome::{DensifyReport, UnitReport, ViewOutcome, ViewVerdict};

/// Which part of densify an invocation does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Step {
    Whole,
    Unit,
    Finalize,
}

/// Run densify whole in one process: both stereo passes and fusion. A staging folder left by
/// an interrupted run with the same settings is resumed (its finished views kept).
pub fn densify(cfg: &DensifyConfig, progress: &dyn Progress) -> Result<DensifyReport> {
    let prep = prepare(cfg, Step::Whole, progress)?;
    let mut seconds = [prep.undistort_seconds, None, None, None];
    for (k, pass) in [MapPass::Photometric, MapPass::Geometric]
        .into_iter()
        .enumerate()
    {
        let timer = std::time::Instant::now();
        run_pass(&prep, cfg, pass, Unit::WHOLE, progress)?;
        seconds[1 + k] = Some(timer.elapsed().as_secs_f64());
    }
    let mut report = finish(&prep, cfg, progress)?;
    report.seconds = [seconds[0], seconds[1], seconds[2], report.seconds[3]];
    Ok(report)
}

/// Run one work unit of a stereo pass: the views it owns (the k-th view with sources, in
/// image-id order, belongs to unit k mod N). Every unit of the photometric pass must finish
/// before any of the geometric pass starts; `finalize_densify` then fuses. A rerun skips the
/// views an earlier run finished, and any split gives the bytes of one process.
pub fn densify_unit(
    cfg: &DensifyConfig,
    pass: MapPass,
    unit: Unit,
    progress: &dyn Progress,
) -> Result<UnitReport> {
    let timer = std::time::Instant::now();
    let prep = prepare(cfg, Step::Unit, progress)?;
    let (owned, computed, resumed) = run_pass(&prep, cfg, pass, unit, progress)?;
    Ok(UnitReport {
        staging: prep.staging,
        pass,
        unit,
        owned,
        planned: prep.plan.len(),
        computed,
        resumed,
        seconds: timer.elapsed().as_secs_f64(),
    })
}

/// Fuse the maps every unit wrote and move the finished workspace into place.
pub fn finalize_densify(cfg: &DensifyConfig, progress: &dyn Progress) -> Result<DensifyReport> {
    let prep = prepare(cfg, Step::Finalize, progress)?;
    finish(&prep, cfg, progress)
}

/// Load and undistort the model, claim the output folder, and make sure the staging
/// workspace holds the undistorted views under these settings (undistorting them if not).
fn prepare(cfg: &DensifyConfig, step: Step, progress: &dyn Progress) -> Result<Prepared> {
    check(cfg)?;
    let (scene, mut rec) = crate::model::load_model(&cfg.scene, None)?;
    let out = cfg.out.clone().unwrap_or_else(|| scene.dir.join("dense"));
    claim(&out, cfg.overwrite)?;
    let options = UndistortOptions {
        max_image_size: cfg.max_image_size,
        ..UndistortOptions::default()
    };
    let distorted = crate::model::undistort_model(&mut rec, &options, &scene.model_dir)?;
    let staging = staging_dir(&out);
    let ws = Workspace::new(&staging);
    let entries = entries(&rec);
    let settings = Settings::of(cfg);
    let record = match (read_record(&ws)?, step) {
        (Some(r), _) if r.settings == settings => Some(r),
        (Some(r), Step::Whole) => {
            drop(r);
            None
        }
        (Some(r), _) => return Err(settings_differ(&ws, &r.settings, &settings)),
        (None, Step::Finalize) => {
            return Err(PipelineError::input(
                &staging,
                "holds no densify work: run `densify --unit I/N --pass photometric`, then `--pass geometric`, before finalize",
            ))
        }
        (None, _) => None,
    };
    let mut undistort_seconds = None;
    let unreadable = match record {
        Some(r) => r.unreadable,
        None => {
            // A whole run starts over; units share the folder, so they only add to it.
            if step == Step::Whole && staging.exists() {
                std::fs::remove_dir_all(&staging).map_err(|e| PipelineError::io(&staging, e))?;
            }
            let timer = std::time::Instant::now();
            let photos = photos_dir(cfg, &scene)?;
            let unreadable =
                undistort_views(&ws, cfg, &photos, &rec, &distorted, &entries, progress)?;
            let text = serde_json::to_string_pretty(&Record {
                settings,
                unreadable: unreadable.clone(),
            })
            .expect("densify's record serialises");
            nrw_dataset::atomic::write_bytes_atomic(&ws.settings(), text.as_bytes())?;
            undistort_seconds = Some(timer.elapsed().as_secs_f64());
            unreadable
        }
    };
    let (plan, verdicts) = plan(cfg, &rec, &entries, &unreadable);
    Ok(Prepared {
        rec,
        out,
        staging,
        ws,
        entries,
        plan,
        verdicts,
        undistort_seconds,
    })
}

/// The photo folder: `--images`, else the scene's own.
fn photos_dir(cfg: &DensifyConfig, scene: &nrw_colmap::Scene) -> Result<PathBuf> {
    cfg.images
        .clone()
        .or_else(|| scene.images_dir())
        .ok_or_else(|| {
            PipelineError::config(
                Setting::Images,
                format!(
                    "no photo folder: looked for {}",
                    scene
                        .image_dir_candidates()
                        .iter()
                        .map(|p| p.display().to_string())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            )
        })
}
