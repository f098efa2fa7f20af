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
mod remote;
mod views;

use std::path::PathBuf;

use nrw_colmap::dense::{MapPass, Workspace};
use nrw_colmap::UndistortOptions;

use crate::error::{PipelineError, Result, Setting};
use crate::{Progress, Unit};
use config::Settings;
use fusion::finish;
use nrw_dataset::resume::{agree, record_bytes, Agreement};
use nrw_dataset::{Location, Store};
use plan::{plan, run_pass, Prepared};
use record::{claim, settings_differ, settings_of, staging_dir, Record, RECORD};
use remote::Remote;
use views::{entries, undistort_views};

pub(crate) use config::check;
pub use config::{
    DensifyConfig, DEFAULT_FUSION_CACHE_MB, DEFAULT_MAX_IMAGE_SIZE, DEFAULT_MAX_SOURCES,
};
pub use outcome::{DensifyReport, DensifyVerdict, UnitReport, ViewOutcome};

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
        undistort_seconds: prep.undistort_seconds,
        seconds: timer.elapsed().as_secs_f64(),
    })
}

/// Fuse the maps every unit wrote and move the finished workspace into place.
pub fn finalize_densify(cfg: &DensifyConfig, progress: &dyn Progress) -> Result<DensifyReport> {
    let prep = prepare(cfg, Step::Finalize, progress)?;
    finish(&prep, cfg, progress)
}

/// Load and undistort the model, claim the output, and make sure the workspace being built
/// holds the undistorted views under these settings (undistorting them if not).
fn prepare(cfg: &DensifyConfig, step: Step, progress: &dyn Progress) -> Result<Prepared> {
    check(cfg)?;
    let (scene, mut rec) = crate::model::load_model(&cfg.scene, None, None)?;
    crate::model::refuse_panoramas(&scene, &rec)?;
    let out = cfg
        .out
        .clone()
        .unwrap_or_else(|| scene.dir.join("dense").into());
    let options = UndistortOptions {
        max_image_size: cfg.settings.max_image_size(),
        ..UndistortOptions::default()
    };
    let distorted = crate::model::undistort_model(&mut rec, &options, &scene.model_dir)?;
    let (ws, remote) = workspace(cfg, &out)?;
    // The record lives where the units share the workspace: the staging folder or prefix.
    let shared = match &remote {
        Some(r) => r.staging.clone(),
        None => Store::local(&ws.root),
    };
    let settings = Settings::of(cfg);
    let record = earlier_record(&shared, &settings, step)?;
    if record.is_none() && step == Step::Whole {
        // A whole run starts over; units share the folder, so they only add to it.
        shared.delete_dir("")?;
    }
    let entries = entries(&rec);
    let mut undistort_seconds = None;
    // A local workspace with a record holds its views; a scratch folder never does.
    let unreadable = if record.is_none() || remote.is_some() {
        let timer = std::time::Instant::now();
        let photos = photos_dir(cfg, &scene)?;
        let here = undistort_views(&ws, cfg, &photos, &rec, &distorted, &entries, progress)?;
        let record = match record {
            Some(r) if r.unreadable != here => return Err(unreadable_differ(&shared, &r, &here)),
            Some(r) => r,
            None => Record {
                settings,
                unreadable: here,
            },
        };
        let bytes = record_bytes(&record);
        nrw_dataset::atomic::write_bytes_atomic(&ws.settings(), &bytes)?;
        if remote.is_some() {
            shared.write(RECORD, bytes)?;
        }
        undistort_seconds = Some(timer.elapsed().as_secs_f64());
        record.unreadable
    } else {
        record.map(|r| r.unreadable).unwrap_or_default()
    };
    let (plan, verdicts) = plan(cfg, &rec, &entries, &unreadable);
    Ok(Prepared {
        rec,
        out,
        staging: shared.root(),
        ws,
        remote,
        entries,
        plan,
        verdicts,
        undistort_seconds,
    })
}

/// The workspace the views are densified in (the output's staging folder, or a local scratch
/// folder for an object-store output), the output claimed first; the remote output, if any.
fn workspace(cfg: &DensifyConfig, out: &Location) -> Result<(Workspace, Option<Remote>)> {
    Ok(match out {
        Location::Local(dir) => {
            claim(out, &Store::local(dir), cfg.settings.overwrite)?;
            (Workspace::new(&staging_dir(dir)), None)
        }
        Location::Url(_) => {
            let remote = Remote::open(out)?;
            claim(out, &remote.out, cfg.settings.overwrite)?;
            (Workspace::new(&remote.scratch), Some(remote))
        }
    })
}

/// The record earlier work left with these settings, if any: other settings are an error
/// for units and finalize (a whole run starts over), and finalize needs earlier work.
fn earlier_record(shared: &Store, settings: &Settings, step: Step) -> Result<Option<Record>> {
    Ok(match (agree(shared, RECORD, settings, settings_of)?, step) {
        (Agreement::Same(r), _) => Some(r),
        (Agreement::Differs { .. }, Step::Whole) => None,
        (Agreement::Differs { differ, .. }, _) => {
            return Err(settings_differ(shared.name(RECORD), &differ))
        }
        (Agreement::Fresh, Step::Finalize) => {
            return Err(PipelineError::input(
                shared.root(),
                "holds no densify work: run `densify --unit I/N --pass photometric`, then `--pass geometric`, before finalize",
            ))
        }
        (Agreement::Fresh, _) => None,
    })
}

/// The error for a machine that cannot read the photos the workspace's record says the
/// first machine read (or the other way round): the units would plan different views.
fn unreadable_differ(
    shared: &Store,
    record: &Record,
    here: &std::collections::BTreeMap<String, String>,
) -> PipelineError {
    let differ: Vec<&String> = record
        .unreadable
        .keys()
        .chain(here.keys())
        .filter(|n| record.unreadable.get(*n) != here.get(*n))
        .collect();
    PipelineError::input(
        shared.name(RECORD),
        format!(
            "lists other unreadable photos than this machine finds ({}): every unit must read the same photos",
            differ.iter().map(|n| n.as_str()).collect::<Vec<_>>().join(", ")
        ),
    )
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
