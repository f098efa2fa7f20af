//! Fusion of the final maps into `fused.ply` and `fused.ply.vis`, and the finished workspace.

use std::collections::BTreeMap;

use nrw_colmap::dense::{DenseMap, MapKind, MapPass, Workspace};
use nrw_colmap::Reconstruction;
use nrw_stereo::FusionOptions;

use super::config::DensifyConfig;
use super::maps::{map_path, read_map, write_cfgs};
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

/// Reads a view's final (geometric) maps and colours from the workspace for fusion, and
/// counts each view's depth pixels the first time it is read.
pub(super) struct WorkspaceMaps<'a> {
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
/// maps; the number of points, each view's depth pixels and what the cache did.
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
        pixels: vec![None; plan.len()],
    };
    let (cloud, stats) = nrw_stereo::fuse(&views, &mut reader, cache_bytes, opts)?;
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
    Ok((cloud.positions.len(), pixels, stats))
}
