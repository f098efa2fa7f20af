//! Fusion of the final maps into `fused.ply` and `fused.ply.vis`, and the finished workspace.

use std::collections::BTreeMap;

use std::ops::Range;
use std::os::unix::fs::FileExt;

use nrw_colmap::dense::{MapFile, MapKind, MapPass, Workspace};
use nrw_colmap::Reconstruction;
use nrw_stereo::FusionOptions;

use super::config::DensifyConfig;
use super::maps::{map_path, write_cfgs};
use super::outcome::{DensifyReport, DensifyVerdict, ViewOutcome};
use super::plan::{last_map, pass_done, Prepared};
use super::record::publish;
use super::views::{load_rgb, Entry, Plan};
use crate::error::{PipelineError, Result};
use crate::Progress;
use nrw_dataset::Location;

/// Fuse the final maps, write the configs, publish the workspace; the report.
pub(super) fn finish(
    prep: &Prepared,
    cfg: &DensifyConfig,
    progress: &dyn Progress,
) -> Result<DensifyReport> {
    let last = if cfg.settings.geometric {
        MapPass::Geometric
    } else {
        MapPass::Photometric
    };
    for p in &prep.plan {
        if !pass_done(prep, cfg, p, last)? {
            let missing = last_map(&prep.ws, cfg, &prep.entries[p.0].name, last)?;
            return Err(PipelineError::input(
                shared_name(prep, &missing),
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
    if let Some(remote) = &prep.remote {
        remote.fetch_maps(&prep.ws)?;
    }
    write_cfgs(&prep.ws, &prep.entries, &prep.plan)?;
    progress.start("fusing", prep.plan.len() as u64, "views");
    let (points, pixels, fusion) = fuse(
        &prep.ws,
        &prep.rec,
        &prep.entries,
        &prep.plan,
        &cfg.settings.fusion(),
        cfg.settings.fusion_cache_bytes(),
    )?;
    progress.finish();
    let fusing = timer.elapsed().as_secs_f64();
    match (&prep.remote, &prep.out) {
        (Some(remote), _) => remote.publish(&prep.ws)?,
        (None, Location::Local(out)) => publish(&prep.ws.root, out)?,
        (None, Location::Url(_)) => unreachable!("a URL output always has its remote side"),
    }
    let mut verdicts = prep.verdicts.clone();
    for (p, pixels) in prep.plan.iter().zip(pixels) {
        verdicts[p.0] = Some(DensifyVerdict::Densified { pixels });
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
        fusion,
        fusion_all_bytes: prep
            .plan
            .iter()
            .map(|p| {
                nrw_stereo::FusionMaps::bytes_for(
                    prep.entries[p.0].width * prep.entries[p.0].height,
                )
            })
            .sum(),
        seconds: [None, None, None, Some(fusing)],
    })
}

/// A workspace file as the units share it: its local path, or its URL in the staging prefix.
fn shared_name(prep: &Prepared, path: &std::path::Path) -> Location {
    match &prep.remote {
        Some(remote) => remote.staging.name(&super::remote::rel(&prep.ws, path)),
        None => path.into(),
    }
}

/// Reads bands of a view's final (geometric) maps and colours from the workspace for fusion,
/// and counts each view's depth pixels as its bands are first read.
pub(super) struct WorkspaceMaps<'a> {
    ws: &'a Workspace,
    views: Vec<&'a Entry>,
    /// Per view, its maps once opened and checked.
    files: Vec<Option<ViewFiles>>,
    /// Per view, which bands are counted in `pixels`.
    counted: Vec<Vec<bool>>,
    pixels: Vec<usize>,
    colours: ColourScratch,
}

/// A view's opened maps and its colours' scratch file.
struct ViewFiles {
    depth: MapFile,
    normal: MapFile,
    rgb: std::path::PathBuf,
}

/// The views' colours decoded once into raw RGB files, so a band's colours are read like its
/// maps; the folder is in the staging workspace and removed before it is published.
struct ColourScratch(std::path::PathBuf);

impl ColourScratch {
    fn new(ws: &Workspace) -> Result<Self> {
        let dir = ws.root.join(".fusion-colours");
        // Left by an interrupted finalize: nothing in it is kept.
        if dir.exists() {
            std::fs::remove_dir_all(&dir).map_err(|e| PipelineError::io(&dir, e))?;
        }
        std::fs::create_dir_all(&dir).map_err(|e| PipelineError::io(&dir, e))?;
        Ok(ColourScratch(dir))
    }
}

impl Drop for ColourScratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

impl WorkspaceMaps<'_> {
    /// A map of view `e` opened, refused unless it has the view's size and `channels`.
    fn open(&self, kind: MapKind, e: &Entry, channels: usize) -> Result<MapFile> {
        let path = map_path(self.ws, kind, MapPass::Geometric, &e.name)?;
        let m = MapFile::open(&path)?;
        if (m.width, m.height, m.channels) != (e.width, e.height, channels) {
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

    /// View `view`'s files, opened and its colours written to the scratch folder on first use.
    fn files(&mut self, view: usize) -> Result<&ViewFiles> {
        if self.files[view].is_none() {
            let e = self.views[view];
            let rgb = self.colours.0.join(format!("{view}.rgb"));
            // Scratch, rewritten by a finalize run again: no rename or sync needed.
            std::fs::write(&rgb, load_rgb(self.ws, e)?.as_raw())
                .map_err(|err| PipelineError::io(&rgb, err))?;
            self.files[view] = Some(ViewFiles {
                depth: self.open(MapKind::Depth, e, 1)?,
                normal: self.open(MapKind::Normal, e, 3)?,
                rgb,
            });
        }
        Ok(self.files[view].as_ref().expect("opened above"))
    }
}

impl nrw_stereo::MapReader for WorkspaceMaps<'_> {
    type Error = PipelineError;

    fn read(&mut self, view: usize, pixels: Range<usize>) -> Result<nrw_stereo::FusionMaps> {
        let f = self.files(view)?;
        let depth = f.depth.read_plane(0, pixels.clone())?;
        let [nx, ny, nz] = [0, 1, 2].map(|c| f.normal.read_plane(c, pixels.clone()));
        let (nx, ny, nz) = (nx?, ny?, nz?);
        let mut rgb = vec![0u8; pixels.len() * 3];
        std::fs::File::open(&f.rgb)
            .and_then(|file| file.read_exact_at(&mut rgb, 3 * pixels.start as u64))
            .map_err(|e| PipelineError::io(&f.rgb, e))?;
        let band = pixels.start / (self.views[view].width * nrw_stereo::BAND_ROWS);
        if !std::mem::replace(&mut self.counted[view][band], true) {
            self.pixels[view] += depth.iter().filter(|z| **z > 0.0).count();
        }
        Ok(nrw_stereo::FusionMaps {
            depth,
            normal: (0..pixels.len()).map(|k| [nx[k], ny[k], nz[k]]).collect(),
            rgb,
        })
    }
}

/// Fuse the final maps into `fused.ply` and `fused.ply.vis`, holding at most `cache_bytes` of
/// maps and writing each point as it is made; the number of points, each view's depth pixels
/// and what the cache did.
pub(super) fn fuse(
    ws: &Workspace,
    rec: &Reconstruction,
    entries: &[Entry],
    plan: &[Plan],
    opts: &FusionOptions,
    cache_bytes: usize,
) -> Result<(usize, Vec<usize>, nrw_stereo::FusionStats)> {
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
        files: (0..plan.len()).map(|_| None).collect(),
        counted: views
            .iter()
            .map(|v| vec![false; nrw_stereo::bands_of(v.height)])
            .collect(),
        pixels: vec![0; plan.len()],
        colours: ColourScratch::new(ws)?,
    };
    // Visibility names images by their index in the workspace model (by id, as COLMAP reads it).
    let model_index: Vec<u32> = plan.iter().map(|(i, _, _)| *i as u32).collect();
    let origin = rec.scene_origin();
    let (ply, vis) = (ws.fused_ply(), ws.fused_vis());
    let mut out = nrw_colmap::fused::FusedWriter::create(&ply, &vis)
        .map_err(|e| PipelineError::io(&ply, e))?;
    let stats = nrw_stereo::fuse_into(&views, &mut reader, cache_bytes, opts, |p| {
        let images: Vec<u32> = p.images.iter().map(|&k| model_index[k as usize]).collect();
        out.push(p.position + origin, p.normal, p.colour, &images)
            .map_err(|e| PipelineError::io(&ply, e))
    })?;
    let points = out.finish().map_err(|e| PipelineError::io(&ply, e))? as usize;
    // Every pixel starts a walk or was fused by one, so every band was read.
    let pixels = std::mem::take(&mut reader.pixels);
    drop(reader);
    Ok((points, pixels, stats))
}
