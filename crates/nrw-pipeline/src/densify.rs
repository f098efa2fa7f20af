//! The densify stage: a sparse COLMAP scene to COLMAP's dense workspace (`SCENE/dense`), so
//! that ingest finds `dense/fused.ply` and COLMAP's own tools read every file: the
//! undistorted photos and model (`images/`, `sparse/`), PatchMatch depth and normal maps per
//! view (photometric, then geometric), our confidence maps, `patch-match.cfg`, `fusion.cfg`,
//! and the fused cloud with its visibility (`fused.ply`, `fused.ply.vis`).
//!
//! Memory: stereo holds one reference view and its sources at a time (maps are written and
//! read back per view); fusion holds a cache of final maps and colours of a given size
//! (COLMAP's `cache_size`) and one bit per pixel of every view.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use nrw_colmap::dense::{DenseMap, MapKind, MapPass, Workspace};
use nrw_colmap::{CameraModel, Format, Reconstruction, UndistortOptions};
use nrw_stereo::{FusionOptions, GrayImage, Hypotheses, PatchMatchOptions, Pinhole, StereoView};
use rayon::prelude::*;

use crate::error::{PipelineError, Result, Setting};
use crate::{Progress, Unit};

/// The longer side the undistorted views are capped at by default (about 0.5 MP at 4:3):
/// stereo's time grows with the pixels.
pub const DEFAULT_MAX_IMAGE_SIZE: u64 = 800;

/// Source views matched per reference view by default (COLMAP's `__auto__, 20` takes 20;
/// the cost of a view grows with the count, and Gipuma's best-3 rarely needs more than 8).
pub const DEFAULT_MAX_SOURCES: usize = 8;

/// Fusion's map cache by default, in MiB: about 100 views at 0.5 MP (19 bytes a pixel).
pub const DEFAULT_FUSION_CACHE_MB: usize = 1024;

/// What densify is asked to do.
#[derive(Debug, Clone)]
pub struct DensifyConfig {
    /// The scene folder (or its model folder).
    pub scene: PathBuf,
    /// The workspace folder; `SCENE/dense` when `None`.
    pub out: Option<PathBuf>,
    /// Replace an existing workspace (a user's own COLMAP run is never touched otherwise).
    pub overwrite: bool,
    /// Longer side of the undistorted views (`None`: the photos' own size).
    pub max_image_size: Option<u64>,
    /// Source views per reference view.
    pub max_sources: usize,
    /// Run the geometric-consistency pass (COLMAP's `geom_consistency`).
    pub geometric: bool,
    /// Where the photos are, if not the scene's `images/`.
    pub images: Option<PathBuf>,
    /// Whether photo names may resolve through links out of the photo folder.
    pub follow_outside_links: bool,
    pub stereo: PatchMatchOptions,
    pub fusion: FusionOptions,
    /// The most bytes of maps fusion holds at once (COLMAP's `cache_size`); the cloud does not
    /// depend on it.
    pub fusion_cache_bytes: usize,
    /// Stop a pass after this many views, as an interruption would (for resume tests).
    pub stop_after_views: Option<usize>,
}

impl DensifyConfig {
    /// The defaults for a scene folder.
    pub fn new(scene: &Path) -> DensifyConfig {
        DensifyConfig {
            scene: scene.to_path_buf(),
            out: None,
            overwrite: false,
            max_image_size: Some(DEFAULT_MAX_IMAGE_SIZE),
            max_sources: DEFAULT_MAX_SOURCES,
            geometric: true,
            images: None,
            follow_outside_links: false,
            stereo: PatchMatchOptions::default(),
            fusion: FusionOptions::default(),
            fusion_cache_bytes: DEFAULT_FUSION_CACHE_MB << 20,
            stop_after_views: None,
        }
    }
}

/// Why a view has (or has no) depth map.
#[derive(Debug, Clone, PartialEq)]
pub enum ViewVerdict {
    /// Depth kept at `pixels` pixels of the final map.
    Densified { pixels: usize },
    /// No other view shares enough points at a wide enough angle.
    NoSourceView,
    /// The view sees no sparse point in front of it, so stereo has no depth range.
    NoDepthRange,
    /// The photo could not be read or undistorted.
    Unreadable(String),
}

/// One view's outcome.
#[derive(Debug, Clone)]
pub struct ViewOutcome {
    pub image_id: u32,
    pub name: String,
    pub width: u64,
    pub height: u64,
    pub verdict: ViewVerdict,
}

/// What densify did (the whole stage, or `finalize` after its work units).
#[derive(Debug, Clone)]
pub struct DensifyReport {
    pub out: PathBuf,
    pub views: Vec<ViewOutcome>,
    pub points: usize,
    /// Seconds of each phase this process ran: undistortion, photometric, geometric, fusion.
    pub seconds: [Option<f64>; 4],
}

impl DensifyReport {
    /// How many views got a depth map.
    pub fn densified(&self) -> usize {
        self.views
            .iter()
            .filter(|v| matches!(v.verdict, ViewVerdict::Densified { .. }))
            .count()
    }
}

/// What one work unit of a stereo pass did.
#[derive(Debug, Clone)]
pub struct UnitReport {
    /// The folder the units build the workspace in (published by `finalize`).
    pub staging: PathBuf,
    pub pass: MapPass,
    pub unit: Unit,
    /// Views this unit owns, of all views with sources.
    pub owned: usize,
    pub planned: usize,
    /// Views matched by this run, and views found done by an earlier (interrupted) one.
    pub computed: usize,
    pub resumed: usize,
    pub seconds: f64,
}

/// A view of the undistorted model as densify handles it.
struct Entry {
    image_id: u32,
    name: String,
    lens: Pinhole,
    rotation: glam::DMat3,
    translation: glam::DVec3,
    width: usize,
    height: usize,
}

/// The settings a workspace is built with: every unit and a resumed run must share them.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
struct Settings {
    tool_version: String,
    max_image_size: Option<u64>,
    max_sources: usize,
    geometric: bool,
    stereo: PatchMatchOptions,
    fusion: FusionOptions,
}

impl Settings {
    fn of(cfg: &DensifyConfig) -> Settings {
        Settings {
            tool_version: env!("CARGO_PKG_VERSION").to_string(),
            max_image_size: cfg.max_image_size,
            max_sources: cfg.max_sources,
            geometric: cfg.geometric,
            stereo: cfg.stereo.clone(),
            fusion: cfg.fusion.clone(),
        }
    }
}

/// `densify.json`: the settings, and the photos undistortion could not read (name → why).
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
struct Record {
    settings: Settings,
    unreadable: BTreeMap<String, String>,
}

/// Which part of densify an invocation does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Step {
    Whole,
    Unit,
    Finalize,
}

/// A workspace being built: the model, the views and the plan every step derives alike.
struct Prepared {
    rec: Reconstruction,
    out: PathBuf,
    staging: PathBuf,
    ws: Workspace,
    entries: Vec<Entry>,
    plan: Vec<Plan>,
    /// The verdict of each view stereo does not run on (`None` for planned views).
    verdicts: Vec<Option<ViewVerdict>>,
    undistort_seconds: Option<f64>,
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

/// Undistort every photo into `images/` and write the undistorted model into `sparse/`;
/// the photos that could not be read, with why.
fn undistort_views(
    ws: &Workspace,
    cfg: &DensifyConfig,
    photos: &Path,
    rec: &Reconstruction,
    distorted: &BTreeMap<u32, nrw_colmap::Camera>,
    entries: &[Entry],
    progress: &dyn Progress,
) -> Result<BTreeMap<String, String>> {
    std::fs::create_dir_all(ws.sparse()).map_err(|e| PipelineError::io(ws.sparse(), e))?;
    nrw_colmap::write_model(rec, &ws.sparse(), Format::Binary)
        .map_err(|e| PipelineError::io(ws.sparse(), e))?;
    progress.start("undistorting", entries.len() as u64, "photos");
    let written: Vec<std::result::Result<(), String>> = entries
        .par_iter()
        .map(|e| {
            let r = write_view(ws, photos, cfg.follow_outside_links, rec, distorted, e);
            progress.inc(1);
            r
        })
        .collect();
    progress.finish();
    Ok(entries
        .iter()
        .zip(written)
        .filter_map(|(e, w)| w.err().map(|why| (e.name.clone(), why)))
        .collect())
}

/// The workspace's record, if it has one.
fn read_record(ws: &Workspace) -> Result<Option<Record>> {
    let path = ws.settings();
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(PipelineError::io(&path, e)),
    };
    serde_json::from_str(&text).map(Some).map_err(|e| {
        PipelineError::input(
            &path,
            format!("is not densify's record ({e}); delete the folder to start over"),
        )
    })
}

/// The error for a unit whose settings are not the workspace's: names the first that differs.
fn settings_differ(ws: &Workspace, have: &Settings, want: &Settings) -> PipelineError {
    let flat = |s: &Settings| {
        let mut out = BTreeMap::new();
        flatten(
            "",
            &serde_json::to_value(s).expect("settings serialise"),
            &mut out,
        );
        out
    };
    let (have, want) = (flat(have), flat(want));
    let null = serde_json::Value::Null;
    let differ: Vec<String> = want
        .iter()
        .filter(|(k, v)| have.get(*k) != Some(*v))
        .map(|(k, v)| format!("{k} = {} (this run: {v})", have.get(k).unwrap_or(&null)))
        .collect();
    PipelineError::input(
        ws.settings(),
        format!(
            "the workspace is being built with {}: run every unit and finalize with the same settings, or delete the folder to start over",
            differ.join(", ")
        ),
    )
}

/// A JSON object's leaves by dotted key.
fn flatten(prefix: &str, v: &serde_json::Value, out: &mut BTreeMap<String, serde_json::Value>) {
    match v {
        serde_json::Value::Object(m) => {
            for (k, v) in m {
                let key = if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}.{k}")
                };
                flatten(&key, v, out);
            }
        }
        _ => {
            out.insert(prefix.to_string(), v.clone());
        }
    }
}

/// The views stereo runs on (with their sources and depth range), and the verdict of every
/// other view.
fn plan(
    cfg: &DensifyConfig,
    rec: &Reconstruction,
    entries: &[Entry],
    unreadable: &BTreeMap<String, String>,
) -> (Vec<Plan>, Vec<Option<ViewVerdict>>) {
    let sources = nrw_colmap::overlap::source_images(
        rec,
        cfg.max_sources,
        nrw_colmap::overlap::DEFAULT_MIN_ANGLE_DEG,
    );
    let ranges = nrw_colmap::overlap::depth_ranges(rec);
    let index: BTreeMap<u32, usize> = entries
        .iter()
        .enumerate()
        .map(|(i, e)| (e.image_id, i))
        .collect();
    let readable = |id: &u32| {
        index
            .get(id)
            .is_some_and(|&i| !unreadable.contains_key(&entries[i].name))
    };
    let mut plan = Vec::new();
    let mut verdicts = Vec::with_capacity(entries.len());
    for (i, e) in entries.iter().enumerate() {
        if let Some(why) = unreadable.get(&e.name) {
            verdicts.push(Some(ViewVerdict::Unreadable(why.clone())));
            continue;
        }
        let srcs: Vec<usize> = sources[&e.image_id]
            .iter()
            .filter(|id| readable(id))
            .map(|id| index[id])
            .collect();
        verdicts.push(match ranges[&e.image_id] {
            _ if srcs.is_empty() => Some(ViewVerdict::NoSourceView),
            None => Some(ViewVerdict::NoDepthRange),
            Some(range) => {
                plan.push((i, srcs, range));
                None
            }
        });
    }
    (plan, verdicts)
}

/// Run one stereo pass over the views `unit` owns; (owned, computed, found done).
fn run_pass(
    prep: &Prepared,
    cfg: &DensifyConfig,
    pass: MapPass,
    unit: Unit,
    progress: &dyn Progress,
) -> Result<(usize, usize, usize)> {
    if pass == MapPass::Geometric && !cfg.geometric {
        // Without a geometric pass the photometric one writes the final maps.
        return Ok((0, 0, 0));
    }
    let owned: Vec<&Plan> = prep
        .plan
        .iter()
        .enumerate()
        .filter(|(k, _)| unit.owns(*k))
        .map(|(_, p)| p)
        .collect();
    let what = match pass {
        MapPass::Photometric => "photometric stereo",
        MapPass::Geometric => "geometric stereo",
    };
    progress.start(what, owned.len() as u64, "views");
    let (mut computed, mut resumed) = (0, 0);
    for p in &owned {
        if pass_done(prep, cfg, p, pass)? {
            resumed += 1;
        } else {
            match pass {
                MapPass::Photometric => photometric_view(&prep.ws, &prep.entries, p, cfg)?,
                MapPass::Geometric => geometric_view(&prep.ws, &prep.entries, p, cfg)?,
            }
            computed += 1;
            if cfg.stop_after_views == Some(computed) {
                progress.finish();
                return Err(PipelineError::Interrupted(format!(
                    "stopped after {computed} views of unit {unit}'s {} pass (--stop-after-views); run it again to resume",
                    pass.name()
                )));
            }
        }
        progress.inc(1);
    }
    progress.finish();
    Ok((owned.len(), computed, resumed))
}

/// The map file a view's pass writes last (each file is written atomically, so it marks the
/// pass done).
fn last_map(ws: &Workspace, cfg: &DensifyConfig, name: &str, pass: MapPass) -> Result<PathBuf> {
    match pass {
        MapPass::Photometric if cfg.geometric => {
            map_path(ws, MapKind::Normal, MapPass::Photometric, name)
        }
        _ => map_path(ws, MapKind::Confidence, MapPass::Geometric, name),
    }
}

fn pass_done(prep: &Prepared, cfg: &DensifyConfig, p: &Plan, pass: MapPass) -> Result<bool> {
    Ok(last_map(&prep.ws, cfg, &prep.entries[p.0].name, pass)?.exists())
}

/// Fuse the final maps, write the configs, publish the workspace; the report.
fn finish(prep: &Prepared, cfg: &DensifyConfig, progress: &dyn Progress) -> Result<DensifyReport> {
    let last = if cfg.geometric {
        MapPass::Geometric
    } else {
        MapPass::Photometric
    };
    for p in &prep.plan {
        if !pass_done(prep, cfg, p, last)? {
            return Err(PipelineError::input(
                last_map(&prep.ws, cfg, &prep.entries[p.0].name, last)?,
                format!(
                    "is missing: the {} pass has not finished view {} (run every unit of `densify --unit I/N --pass {}` first)",
                    last.name(),
                    prep.entries[p.0].name,
                    last.name()
                ),
            ));
        }
    }
    let timer = std::time::Instant::now();
    write_cfgs(&prep.ws, &prep.entries, &prep.plan)?;
    progress.start("fusing", prep.plan.len() as u64, "views");
    let (points, pixels) = fuse(
        &prep.ws,
        &prep.rec,
        &prep.entries,
        &prep.plan,
        &cfg.fusion,
        cfg.fusion_cache_bytes,
    )?;
    progress.finish();
    let fusing = timer.elapsed().as_secs_f64();
    publish(&prep.staging, &prep.out)?;
    let mut verdicts = prep.verdicts.clone();
    for (p, pixels) in prep.plan.iter().zip(pixels) {
        verdicts[p.0] = Some(ViewVerdict::Densified { pixels });
    }
    Ok(DensifyReport {
        out: prep.out.clone(),
        views: prep
            .entries
            .iter()
            .zip(verdicts)
            .map(|(e, verdict)| ViewOutcome {
                image_id: e.image_id,
                name: e.name.clone(),
                width: e.width as u64,
                height: e.height as u64,
                verdict: verdict.expect("every view is planned or has a verdict"),
            })
            .collect(),
        points,
        seconds: [None, None, None, Some(fusing)],
    })
}

/// A view to match: its index in the entries, its sources' indices, its depth range.
type Plan = (usize, Vec<usize>, (f64, f64));

/// A reference view and its sources, read back from the workspace.
fn load_views(
    ws: &Workspace,
    entries: &[Entry],
    p: &Plan,
) -> Result<(StereoView, Vec<StereoView>)> {
    let reference = load_view(ws, &entries[p.0])?;
    let sources =
        p.1.iter()
            .map(|&j| load_view(ws, &entries[j]))
            .collect::<Result<Vec<_>>>()?;
    Ok((reference, sources))
}

/// The photometric pass over one view: its unfiltered hypotheses written for the geometric
/// pass, or (without one) its filtered, final maps.
fn photometric_view(
    ws: &Workspace,
    entries: &[Entry],
    p: &Plan,
    cfg: &DensifyConfig,
) -> Result<()> {
    let (reference, views) = load_views(ws, entries, p)?;
    let s: Vec<nrw_stereo::Source> = views
        .iter()
        .map(|v| nrw_stereo::Source {
            view: v,
            depth: None,
        })
        .collect();
    let state = nrw_stereo::photometric(&reference, &s, p.2, &cfg.stereo)
        .expect("a planned view has sources and a range");
    let name = &entries[p.0].name;
    if cfg.geometric {
        return write_hypotheses(ws, name, MapPass::Photometric, &state);
    }
    let maps = nrw_stereo::filter(&reference, &s, p.2, &state, false, &cfg.stereo);
    write_maps(ws, name, MapPass::Geometric, &maps)
}

/// A photometric map the geometric pass reads, or an error saying that pass has not
/// finished it.
fn photometric_map(ws: &Workspace, kind: MapKind, name: &str) -> Result<DenseMap> {
    let path = map_path(ws, kind, MapPass::Photometric, name)?;
    if !path.exists() {
        return Err(PipelineError::input(
            &path,
            format!(
                "is missing: the photometric pass has not finished view {name} (every unit of `densify --unit I/N --pass photometric` must finish before the geometric pass)"
            ),
        ));
    }
    read_map(ws, kind, MapPass::Photometric, name)
}

/// The geometric pass over one view, from its and its sources' photometric maps.
fn geometric_view(ws: &Workspace, entries: &[Entry], p: &Plan, cfg: &DensifyConfig) -> Result<()> {
    let (reference, views) = load_views(ws, entries, p)?;
    let depths =
        p.1.iter()
            .map(|&j| photometric_map(ws, MapKind::Depth, &entries[j].name))
            .collect::<Result<Vec<_>>>()?;
    let s: Vec<nrw_stereo::Source> = views
        .iter()
        .zip(&depths)
        .map(|(v, d)| nrw_stereo::Source {
            view: v,
            depth: Some(&d.data),
        })
        .collect();
    let name = &entries[p.0].name;
    let start = read_hypotheses(ws, name)?;
    let state = nrw_stereo::geometric(&reference, &s, p.2, start, &cfg.stereo);
    let maps = nrw_stereo::filter(&reference, &s, p.2, &state, true, &cfg.stereo);
    write_maps(ws, name, MapPass::Geometric, &maps)
}

fn check(cfg: &DensifyConfig) -> Result<()> {
    if cfg.max_sources == 0 || cfg.max_sources > nrw_stereo::patchmatch::MAX_SOURCES {
        return Err(PipelineError::config(
            Setting::MaxSources,
            format!(
                "is {}; it must be 1 to {}",
                cfg.max_sources,
                nrw_stereo::patchmatch::MAX_SOURCES
            ),
        ));
    }
    if cfg.fusion.min_num_pixels == 0 {
        return Err(PipelineError::config(
            Setting::MinNumPixels,
            "is 0; a fused point needs at least 1 pixel (the default is 2, COLMAP's 5)",
        ));
    }
    if cfg.max_image_size == Some(0) {
        return Err(PipelineError::config(
            Setting::MaxImageSize,
            "is 0; leave it out for the photos' own size",
        ));
    }
    if cfg.stereo.iterations == 0 || cfg.stereo.window_radius == 0 || cfg.stereo.scales == 0 {
        return Err(PipelineError::config(
            Setting::Stereo,
            "iterations, window radius and scales must each be at least 1",
        ));
    }
    Ok(())
}

/// Refuse to replace a non-empty folder at `out` unless asked to.
fn claim(out: &Path, overwrite: bool) -> Result<()> {
    let occupied = std::fs::read_dir(out).is_ok_and(|mut d| d.next().is_some());
    if occupied && !overwrite {
        return Err(PipelineError::config(
            Setting::Overwrite,
            format!(
                "{} already holds a dense workspace (perhaps your own COLMAP run); it is kept unless {} is set — or write elsewhere with {}",
                out.display(),
                Setting::Overwrite,
                Setting::DenseOut
            ),
        ));
    }
    if out.exists() && !out.is_dir() {
        return Err(PipelineError::input(
            out,
            "is a file, not a folder: the dense workspace is a folder",
        ));
    }
    Ok(())
}

/// The folder a workspace is built in before it replaces `out` whole.
fn staging_dir(out: &Path) -> PathBuf {
    let name = out
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "dense".into());
    out.with_file_name(format!(".{name}.partial"))
}

/// Move the finished workspace into place (replacing an older one the caller may replace).
fn publish(staging: &Path, out: &Path) -> Result<()> {
    if out.exists() {
        std::fs::remove_dir_all(out).map_err(|e| PipelineError::io(out, e))?;
    }
    std::fs::rename(staging, out).map_err(|e| PipelineError::io(out, e))
}

/// The views of the undistorted model, by image id.
fn entries(rec: &Reconstruction) -> Vec<Entry> {
    let origin = rec.scene_origin();
    rec.images
        .values()
        .map(|im| {
            let cam = &rec.cameras[&im.camera_id];
            debug_assert_eq!(cam.model, CameraModel::Pinhole);
            let p = &cam.params;
            let local = im.cam_from_world.recentred(origin);
            Entry {
                image_id: im.id,
                name: im.name.clone(),
                lens: Pinhole {
                    fx: p[0],
                    fy: p[1],
                    cx: p[2],
                    cy: p[3],
                },
                rotation: local.matrix,
                translation: local.translation,
                width: cam.width as usize,
                height: cam.height as usize,
            }
        })
        .collect()
}

/// Read, undistort and write one photo into `images/`; the problem if it cannot be.
fn write_view(
    ws: &Workspace,
    photos: &Path,
    follow_outside_links: bool,
    rec: &Reconstruction,
    distorted: &BTreeMap<u32, nrw_colmap::Camera>,
    e: &Entry,
) -> std::result::Result<(), String> {
    let im = &rec.images[&e.image_id];
    let path = nrw_colmap::names::photo_path(photos, &im.name, follow_outside_links)?;
    let photo = nrw_dataset::codec::load_photo(&path).map_err(|err| err.to_string())?;
    let out = crate::model::undistorted_photo(
        &photo,
        &distorted[&im.camera_id],
        &rec.cameras[&im.camera_id],
    );
    let target = ws.image(&im.name)?;
    let bytes = encode(&im.name, &out).map_err(|err| format!("{}: {err}", target.display()))?;
    nrw_dataset::atomic::write_bytes_atomic(&target, &bytes).map_err(|err| err.to_string())
}

/// The undistorted photo in the encoding its name says (JPEG at quality 95, else PNG).
fn encode(name: &str, img: &image::RgbImage) -> std::result::Result<Vec<u8>, String> {
    let lower = name.to_ascii_lowercase();
    if lower.ends_with(".jpg") || lower.ends_with(".jpeg") {
        let mut out = Vec::new();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 95)
            .encode_image(img)
            .map_err(|e| e.to_string())?;
        Ok(out)
    } else {
        nrw_dataset::codec::encode_rgb(name, img).map_err(|e| e.to_string())
    }
}

/// A workspace view as stereo reads it (its undistorted photo, decoded again).
fn load_view(ws: &Workspace, e: &Entry) -> Result<StereoView> {
    let rgb = load_rgb(ws, e)?;
    Ok(StereoView {
        id: e.image_id as u64,
        image: GrayImage::from_rgb8(e.width, e.height, rgb.as_raw()),
        lens: e.lens,
        rotation: e.rotation,
        translation: e.translation,
    })
}

fn load_rgb(ws: &Workspace, e: &Entry) -> Result<image::RgbImage> {
    let path = ws
        .image(&e.name)
        .map_err(|p| PipelineError::input(ws.images(), p))?;
    let rgb = nrw_dataset::codec::load_photo(&path)?;
    if rgb.width() as usize != e.width || rgb.height() as usize != e.height {
        return Err(PipelineError::input(
            &path,
            format!(
                "is {}x{}, its undistorted camera {}x{}",
                rgb.width(),
                rgb.height(),
                e.width,
                e.height
            ),
        ));
    }
    Ok(rgb)
}

fn map_path(ws: &Workspace, kind: MapKind, pass: MapPass, name: &str) -> Result<PathBuf> {
    ws.map(kind, pass, name)
        .map_err(|p| PipelineError::input(ws.stereo(), p))
}

fn write_map(
    ws: &Workspace,
    kind: MapKind,
    pass: MapPass,
    name: &str,
    map: &DenseMap,
) -> Result<()> {
    let path = map_path(ws, kind, pass, name)?;
    nrw_dataset::atomic::write_bytes_atomic(&path, &map.to_bytes())?;
    Ok(())
}

fn read_map(ws: &Workspace, kind: MapKind, pass: MapPass, name: &str) -> Result<DenseMap> {
    let path = map_path(ws, kind, pass, name)?;
    let bytes = std::fs::read(&path).map_err(|e| PipelineError::io(&path, e))?;
    Ok(DenseMap::from_bytes(&bytes, &path)?)
}

fn depth_map(w: usize, h: usize, depth: &[f32]) -> DenseMap {
    DenseMap {
        width: w,
        height: h,
        channels: 1,
        data: depth.to_vec(),
    }
}

fn normal_map(w: usize, h: usize, normal: &[[f32; 3]]) -> DenseMap {
    DenseMap {
        width: w,
        height: h,
        channels: 3,
        data: normal.iter().flatten().copied().collect(),
    }
}

/// A depth map and its normal map.
fn write_depth_normal(
    ws: &Workspace,
    name: &str,
    pass: MapPass,
    (w, h): (usize, usize),
    depth: &[f32],
    normal: &[[f32; 3]],
) -> Result<()> {
    write_map(ws, MapKind::Depth, pass, name, &depth_map(w, h, depth))?;
    write_map(ws, MapKind::Normal, pass, name, &normal_map(w, h, normal))
}

/// Unfiltered hypotheses, as COLMAP writes the photometric maps a geometric pass reads.
fn write_hypotheses(ws: &Workspace, name: &str, pass: MapPass, h: &Hypotheses) -> Result<()> {
    write_depth_normal(ws, name, pass, (h.width, h.height), &h.depth, &h.normal)
}

fn read_hypotheses(ws: &Workspace, name: &str) -> Result<Hypotheses> {
    let d = photometric_map(ws, MapKind::Depth, name)?;
    let n = photometric_map(ws, MapKind::Normal, name)?;
    Ok(Hypotheses {
        width: d.width,
        height: d.height,
        normal: n.data.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        cost: vec![nrw_stereo::patchmatch::MAX_COST; d.data.len()],
        views: vec![0; d.data.len()],
        depth: d.data,
    })
}

/// The filtered maps of a pass, with their confidence.
fn write_maps(ws: &Workspace, name: &str, pass: MapPass, m: &nrw_stereo::StereoMaps) -> Result<()> {
    write_depth_normal(ws, name, pass, (m.width, m.height), &m.depth, &m.normal)?;
    let confidence = DenseMap {
        width: m.width,
        height: m.height,
        channels: 2,
        data: m.confidence.iter().flatten().copied().collect(),
    };
    write_map(ws, MapKind::Confidence, pass, name, &confidence)
}

/// `patch-match.cfg` (each view and the sources it was matched with) and `fusion.cfg`.
fn write_cfgs(ws: &Workspace, entries: &[Entry], plan: &[Plan]) -> Result<()> {
    let pm: Vec<(String, Vec<String>)> = plan
        .iter()
        .map(|(i, s, _)| {
            (
                entries[*i].name.clone(),
                s.iter().map(|&j| entries[j].name.clone()).collect(),
            )
        })
        .collect();
    let text = nrw_colmap::dense::patch_match_cfg(&pm, &ws.patch_match_cfg())?;
    nrw_dataset::atomic::write_bytes_atomic(&ws.patch_match_cfg(), text.as_bytes())?;
    let names: Vec<String> = plan
        .iter()
        .map(|(i, _, _)| entries[*i].name.clone())
        .collect();
    let text = nrw_colmap::dense::fusion_cfg(&names, &ws.fusion_cfg())?;
    nrw_dataset::atomic::write_bytes_atomic(&ws.fusion_cfg(), text.as_bytes())?;
    Ok(())
}

/// Reads a view's final (geometric) maps and colours from the workspace for fusion, and
/// counts each view's depth pixels the first time it is read.
struct WorkspaceMaps<'a> {
    ws: &'a Workspace,
    views: Vec<&'a Entry>,
    pixels: Vec<Option<usize>>,
}

impl WorkspaceMaps<'_> {
    /// A map of view `e`, refused unless it has the view's size and `channels`.
    fn map(&self, kind: MapKind, e: &Entry, channels: usize) -> Result<DenseMap> {
        let m = read_map(self.ws, kind, MapPass::Geometric, &e.name)?;
        if (m.width, m.height, m.channels) != (e.width, e.height, channels) {
            let path = map_path(self.ws, kind, MapPass::Geometric, &e.name)?;
            return Err(PipelineError::input(
                &path,
                format!(
                    "is {}x{}x{}, its view {}x{}x{channels}",
                    m.width, m.height, m.channels, e.width, e.height
                ),
            ));
        }
        Ok(m)
    }
}

impl nrw_stereo::MapReader for WorkspaceMaps<'_> {
    type Error = PipelineError;

    fn read(&mut self, view: usize) -> Result<nrw_stereo::FusionMaps> {
        let e = self.views[view];
        let depth = self.map(MapKind::Depth, e, 1)?.data;
        let normal = self.map(MapKind::Normal, e, 3)?.data;
        self.pixels[view].get_or_insert(depth.iter().filter(|z| **z > 0.0).count());
        Ok(nrw_stereo::FusionMaps {
            depth,
            normal: normal.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
            rgb: load_rgb(self.ws, e)?.into_raw(),
        })
    }
}

/// Fuse the final maps into `fused.ply` and `fused.ply.vis`, holding at most `cache_bytes` of
/// maps; the number of points and each view's depth pixels.
fn fuse(
    ws: &Workspace,
    rec: &Reconstruction,
    entries: &[Entry],
    plan: &[Plan],
    opts: &FusionOptions,
    cache_bytes: usize,
) -> Result<(usize, Vec<usize>)> {
    // The images a walk may step into: COLMAP's fusion takes the 50 most overlapping.
    let overlap = nrw_colmap::overlap::source_images(rec, 50, 0.0);
    let position: BTreeMap<u32, usize> = plan
        .iter()
        .enumerate()
        .map(|(k, (i, _, _))| (entries[*i].image_id, k))
        .collect();
    let views: Vec<nrw_stereo::FusionView> = plan
        .iter()
        .map(|(i, _, _)| {
            let e = &entries[*i];
            nrw_stereo::FusionView {
                lens: e.lens,
                rotation: e.rotation,
                translation: e.translation,
                width: e.width,
                height: e.height,
                overlapping: overlap[&e.image_id]
                    .iter()
                    .filter_map(|id| position.get(id).copied())
                    .collect(),
            }
        })
        .collect();
    let mut reader = WorkspaceMaps {
        ws,
        views: plan.iter().map(|(i, _, _)| &entries[*i]).collect(),
        pixels: vec![None; plan.len()],
    };
    let (cloud, _) = nrw_stereo::fuse(&views, &mut reader, cache_bytes, opts)?;
    // Visibility names images by their index in the workspace model (by id, as COLMAP reads it).
    let model_index: Vec<u32> = plan.iter().map(|(i, _, _)| *i as u32).collect();
    let origin = rec.scene_origin();
    let ply = nrw_colmap::PointCloud {
        path: ws.fused_ply(),
        positions: cloud.positions.iter().map(|p| *p + origin).collect(),
        colors: Some(cloud.colors.clone()),
        normals: Some(cloud.normals.clone()),
    };
    nrw_colmap::write_ply(&ply, &ws.fused_ply())
        .map_err(|e| PipelineError::io(ws.fused_ply(), e))?;
    let vis: Vec<Vec<u32>> = cloud
        .visibility
        .iter()
        .map(|v| v.iter().map(|&k| model_index[k as usize]).collect())
        .collect();
    nrw_dataset::atomic::write_bytes_atomic(
        &ws.fused_vis(),
        &nrw_colmap::dense::visibility_to_bytes(&vis),
    )?;
    // Every view starts walks, so every view was read.
    let pixels = reader.pixels.iter().map(|p| p.unwrap_or(0)).collect();
    Ok((cloud.positions.len(), pixels))
}
