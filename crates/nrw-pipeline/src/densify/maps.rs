//! The workspace's map files: depth, normal and confidence maps, hypotheses, and COLMAP's
//! `patch-match.cfg` / `fusion.cfg`.

use std::path::PathBuf;

use nrw_colmap::dense::{DenseMap, MapKind, MapPass, Workspace};
use nrw_stereo::Hypotheses;

use super::views::{Entry, Plan};
use crate::error::{PipelineError, Result};

pub(super) fn map_path(
    ws: &Workspace,
    kind: MapKind,
    pass: MapPass,
    name: &str,
) -> Result<PathBuf> {
    ws.map(kind, pass, name)
        .map_err(|p| PipelineError::input(ws.stereo(), p))
}

pub(super) fn write_map(
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

pub(super) fn read_map(
    ws: &Workspace,
    kind: MapKind,
    pass: MapPass,
    name: &str,
) -> Result<DenseMap> {
    let path = map_path(ws, kind, pass, name)?;
    let bytes = std::fs::read(&path).map_err(|e| PipelineError::io(&path, e))?;
    Ok(DenseMap::from_bytes(&bytes, &path)?)
}

pub(super) fn depth_map(w: usize, h: usize, depth: &[f32]) -> DenseMap {
    DenseMap {
        width: w,
        height: h,
        channels: 1,
        data: depth.to_vec(),
    }
}

pub(super) fn normal_map(w: usize, h: usize, normal: &[[f32; 3]]) -> DenseMap {
    DenseMap {
        width: w,
        height: h,
        channels: 3,
        data: normal.iter().flatten().copied().collect(),
    }
}

/// A depth map and its normal map.
pub(super) fn write_depth_normal(
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
pub(super) fn write_hypotheses(
    ws: &Workspace,
    name: &str,
    pass: MapPass,
    h: &Hypotheses,
) -> Result<()> {
    write_depth_normal(ws, name, pass, (h.width, h.height), &h.depth, &h.normal)
}

pub(super) fn read_hypotheses(ws: &Workspace, name: &str) -> Result<Hypotheses> {
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
pub(super) fn write_maps(
    ws: &Workspace,
    name: &str,
    pass: MapPass,
    m: &nrw_stereo::StereoMaps,
) -> Result<()> {
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
pub(super) fn write_cfgs(ws: &Workspace, entries: &[Entry], plan: &[Plan]) -> Result<()> {
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

/// A photometric map the geometric pass reads, or an error saying that pass has not
/// finished it.
pub(super) fn photometric_map(ws: &Workspace, kind: MapKind, name: &str) -> Result<DenseMap> {
    let path = map_path(ws, kind, MapPass::Photometric, name)?;
    if !path.exists() {
        return Err(PipelineError::input(&path, photometric_unfinished(name)));
    }
    read_map(ws, kind, MapPass::Photometric, name)
}

/// Why a photometric map the geometric pass reads is missing.
pub(super) fn photometric_unfinished(name: &str) -> String {
    format!(
        "is missing: the photometric pass has not finished view {name} (every unit of `densify --unit I/N --pass photometric` must finish before the geometric pass)"
    )
}
