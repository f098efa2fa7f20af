//! The densify stage: a sparse COLMAP scene to COLMAP's dense workspace (`SCENE/dense`), so
//! that ingest finds `dense/fused.ply` and COLMAP's own tools read every file: the
//! undistorted photos and model (`images/`, `sparse/`), PatchMatch depth and normal maps per
//! view (photometric, then geometric), our confidence maps, `patch-match.cfg`, `fusion.cfg`,
//! and the fused cloud with its visibility (`fused.ply`, `fused.ply.vis`).
//!
//! Memory: stereo holds one reference view and its sources at a time (maps are written and
//! read back per view); fusion holds every view's final maps and colours, as COLMAP's does.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use nrw_colmap::dense::{DenseMap, MapKind, MapPass, Workspace};
use nrw_colmap::{CameraModel, Format, Reconstruction, UndistortOptions};
use nrw_stereo::{FusionOptions, GrayImage, Hypotheses, PatchMatchOptions, Pinhole, StereoView};
use rayon::prelude::*;

use crate::error::{PipelineError, Result, Setting};
use crate::Progress;

/// The longer side the undistorted views are capped at by default (about 0.5 MP at 4:3):
/// stereo's time grows with the pixels.
pub const DEFAULT_MAX_IMAGE_SIZE: u64 = 800;

/// Source views matched per reference view by default (COLMAP's `__auto__, 20` takes 20;
/// the cost of a view grows with the count, and Gipuma's best-3 rarely needs more than 8).
pub const DEFAULT_MAX_SOURCES: usize = 8;

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

/// What densify did.
#[derive(Debug, Clone)]
pub struct DensifyReport {
    pub out: PathBuf,
    pub views: Vec<ViewOutcome>,
    pub points: usize,
    /// Seconds of each phase: undistortion, photometric, geometric, fusion.
    pub seconds: [f64; 4],
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

/// Run densify.
pub fn densify(cfg: &DensifyConfig, progress: &dyn Progress) -> Result<DensifyReport> {
    check(cfg)?;
    let (scene, mut rec) = crate::model::load_model(&cfg.scene, None)?;
    let out = cfg.out.clone().unwrap_or_else(|| scene.dir.join("dense"));
    claim(&out, cfg.overwrite)?;
    let photos_dir = cfg
        .images
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
        })?;
    let options = UndistortOptions {
        max_image_size: cfg.max_image_size,
        ..UndistortOptions::default()
    };
    let distorted = crate::model::undistort_model(&mut rec, &options, &scene.model_dir)?;
    let staging = staging_dir(&out);
    if staging.exists() {
        std::fs::remove_dir_all(&staging).map_err(|e| PipelineError::io(&staging, e))?;
    }
    let ws = Workspace::new(&staging);
    std::fs::create_dir_all(ws.sparse()).map_err(|e| PipelineError::io(ws.sparse(), e))?;
    nrw_colmap::write_model(&rec, &ws.sparse(), Format::Binary)
        .map_err(|e| PipelineError::io(ws.sparse(), e))?;

    let mut timer = std::time::Instant::now();
    let mut seconds = [0.0; 4];
    let mut lap = |i: usize, timer: &mut std::time::Instant| {
        seconds[i] = timer.elapsed().as_secs_f64();
        *timer = std::time::Instant::now();
    };
    let entries = entries(&rec);
    progress.start("undistorting", entries.len() as u64, "photos");
    let written: Vec<std::result::Result<(), String>> = entries
        .par_iter()
        .map(|e| {
            let r = write_view(
                &ws,
                &photos_dir,
                cfg.follow_outside_links,
                &rec,
                &distorted,
                e,
            );
            progress.inc(1);
            r
        })
        .collect();
    progress.finish();
    lap(0, &mut timer);

    let sources = nrw_colmap::overlap::source_images(
        &rec,
        cfg.max_sources,
        nrw_colmap::overlap::DEFAULT_MIN_ANGLE_DEG,
    );
    let ranges = nrw_colmap::overlap::depth_ranges(&rec);
    let index: BTreeMap<u32, usize> = entries
        .iter()
        .enumerate()
        .map(|(i, e)| (e.image_id, i))
        .collect();
    let readable = |id: &u32| index.get(id).is_some_and(|&i| written[i].is_ok());
    let mut verdicts: Vec<ViewVerdict> = written
        .iter()
        .map(|w| match w {
            Ok(()) => ViewVerdict::NoSourceView,
            Err(e) => ViewVerdict::Unreadable(e.clone()),
        })
        .collect();
    // Each view that can be matched, with its sources (indices into `entries`) and range.
    let mut plan: Vec<Step> = Vec::new();
    for (i, e) in entries.iter().enumerate() {
        if written[i].is_err() {
            continue;
        }
        let srcs: Vec<usize> = sources[&e.image_id]
            .iter()
            .filter(|id| readable(id))
            .map(|id| index[id])
            .collect();
        match ranges[&e.image_id] {
            _ if srcs.is_empty() => verdicts[i] = ViewVerdict::NoSourceView,
            None => verdicts[i] = ViewVerdict::NoDepthRange,
            Some(range) => plan.push((i, srcs, range)),
        }
    }

    let first = if cfg.geometric {
        MapPass::Photometric
    } else {
        MapPass::Geometric
    };
    progress.start("photometric stereo", plan.len() as u64, "views");
    for step in &plan {
        if let Some(v) = photometric_view(&ws, &entries, step, cfg, first)? {
            verdicts[step.0] = v;
        }
        progress.inc(1);
    }
    progress.finish();
    lap(1, &mut timer);
    if cfg.geometric {
        progress.start("geometric stereo", plan.len() as u64, "views");
        for step in &plan {
            verdicts[step.0] = geometric_view(&ws, &entries, step, cfg, first)?;
            progress.inc(1);
        }
        progress.finish();
    }
    lap(2, &mut timer);

    write_cfgs(&ws, &entries, &plan)?;
    progress.start("fusing", plan.len() as u64, "views");
    let points = fuse(&ws, &rec, &entries, &plan, &cfg.fusion)?;
    progress.finish();
    lap(3, &mut timer);

    publish(&staging, &out)?;
    Ok(DensifyReport {
        out,
        views: entries
            .iter()
            .zip(verdicts)
            .map(|(e, verdict)| ViewOutcome {
                image_id: e.image_id,
                name: e.name.clone(),
                width: e.width as u64,
                height: e.height as u64,
                verdict,
            })
            .collect(),
        points,
        seconds,
    })
}

/// A view to match: its index in the entries, its sources' indices, its depth range.
type Step = (usize, Vec<usize>, (f64, f64));

/// A reference view and its sources, read back from the workspace.
fn load_views(
    ws: &Workspace,
    entries: &[Entry],
    step: &Step,
) -> Result<(StereoView, Vec<StereoView>)> {
    let reference = load_view(ws, &entries[step.0])?;
    let sources = step
        .1
        .iter()
        .map(|&j| load_view(ws, &entries[j]))
        .collect::<Result<Vec<_>>>()?;
    Ok((reference, sources))
}

/// The photometric pass over one view: its unfiltered hypotheses written for the geometric
/// pass, or (without one) its filtered maps and verdict.
fn photometric_view(
    ws: &Workspace,
    entries: &[Entry],
    step: &Step,
    cfg: &DensifyConfig,
    pass: MapPass,
) -> Result<Option<ViewVerdict>> {
    let (reference, views) = load_views(ws, entries, step)?;
    let s: Vec<nrw_stereo::Source> = views
        .iter()
        .map(|v| nrw_stereo::Source {
            view: v,
            depth: None,
        })
        .collect();
    let state = nrw_stereo::photometric(&reference, &s, step.2, &cfg.stereo)
        .expect("a planned view has sources and a range");
    let name = &entries[step.0].name;
    if cfg.geometric {
        write_hypotheses(ws, name, pass, &state)?;
        return Ok(None);
    }
    let maps = nrw_stereo::filter(&reference, &s, step.2, &state, false, &cfg.stereo);
    write_maps(ws, name, MapPass::Geometric, &maps)?;
    Ok(Some(densified(&maps)))
}

/// The geometric pass over one view, from its and its sources' photometric maps.
fn geometric_view(
    ws: &Workspace,
    entries: &[Entry],
    step: &Step,
    cfg: &DensifyConfig,
    photometric: MapPass,
) -> Result<ViewVerdict> {
    let (reference, views) = load_views(ws, entries, step)?;
    let depths = step
        .1
        .iter()
        .map(|&j| read_map(ws, MapKind::Depth, photometric, &entries[j].name))
        .collect::<Result<Vec<_>>>()?;
    let s: Vec<nrw_stereo::Source> = views
        .iter()
        .zip(&depths)
        .map(|(v, d)| nrw_stereo::Source {
            view: v,
            depth: Some(&d.data),
        })
        .collect();
    let name = &entries[step.0].name;
    let start = read_hypotheses(ws, name, photometric)?;
    let state = nrw_stereo::geometric(&reference, &s, step.2, start, &cfg.stereo);
    let maps = nrw_stereo::filter(&reference, &s, step.2, &state, true, &cfg.stereo);
    write_maps(ws, name, MapPass::Geometric, &maps)?;
    Ok(densified(&maps))
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

fn read_hypotheses(ws: &Workspace, name: &str, pass: MapPass) -> Result<Hypotheses> {
    let d = read_map(ws, MapKind::Depth, pass, name)?;
    let n = read_map(ws, MapKind::Normal, pass, name)?;
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

fn densified(m: &nrw_stereo::StereoMaps) -> ViewVerdict {
    ViewVerdict::Densified {
        pixels: m.depth.iter().filter(|d| **d > 0.0).count(),
    }
}

/// `patch-match.cfg` (each view and the sources it was matched with) and `fusion.cfg`.
fn write_cfgs(ws: &Workspace, entries: &[Entry], plan: &[Step]) -> Result<()> {
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

/// Fuse the final maps into `fused.ply` and `fused.ply.vis`; the number of points.
fn fuse(
    ws: &Workspace,
    rec: &Reconstruction,
    entries: &[Entry],
    plan: &[Step],
    opts: &FusionOptions,
) -> Result<usize> {
    let mut depths = Vec::with_capacity(plan.len());
    let mut normals = Vec::with_capacity(plan.len());
    let mut colours = Vec::with_capacity(plan.len());
    for (i, _, _) in plan {
        let e = &entries[*i];
        depths.push(read_map(ws, MapKind::Depth, MapPass::Geometric, &e.name)?.data);
        let n = read_map(ws, MapKind::Normal, MapPass::Geometric, &e.name)?;
        normals.push(
            n.data
                .chunks_exact(3)
                .map(|c| [c[0], c[1], c[2]])
                .collect::<Vec<_>>(),
        );
        colours.push(load_rgb(ws, e)?.into_raw());
    }
    // The images a walk may step into: COLMAP's fusion takes the 50 most overlapping.
    let overlap = nrw_colmap::overlap::source_images(rec, 50, 0.0);
    let position: BTreeMap<u32, usize> = plan
        .iter()
        .enumerate()
        .map(|(k, (i, _, _))| (entries[*i].image_id, k))
        .collect();
    let inputs: Vec<nrw_stereo::FusionInput> = plan
        .iter()
        .enumerate()
        .map(|(k, (i, _, _))| {
            let e = &entries[*i];
            nrw_stereo::FusionInput {
                lens: e.lens,
                rotation: e.rotation,
                translation: e.translation,
                width: e.width,
                height: e.height,
                depth: &depths[k],
                normal: &normals[k],
                rgb: &colours[k],
                overlapping: overlap[&e.image_id]
                    .iter()
                    .filter_map(|id| position.get(id).copied())
                    .collect(),
            }
        })
        .collect();
    let cloud = nrw_stereo::fuse(&inputs, opts);
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
    Ok(cloud.positions.len())
}
