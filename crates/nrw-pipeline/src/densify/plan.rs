//! The plan of a workspace (each view's sources and depth range) and the stereo passes over it,
//! whole or as work units.

use std::collections::BTreeMap;
use std::path::PathBuf;

use nrw_colmap::dense::{MapKind, MapPass, Workspace};
use nrw_colmap::Reconstruction;
use nrw_stereo::StereoView;

use super::config::DensifyConfig;
use super::maps::{
    map_path, photometric_map, photometric_unfinished, read_hypotheses, write_hypotheses,
    write_maps,
};
use super::outcome::DensifyVerdict;
use super::remote::Remote;
use super::views::{load_view, Entry, Plan};
use crate::error::{PipelineError, Result};
use crate::{Progress, Unit};
use nrw_dataset::Location;

/// The views stereo runs on (with their sources and depth range), and the verdict of every
/// other view.
pub(super) fn plan(
    cfg: &DensifyConfig,
    rec: &Reconstruction,
    entries: &[Entry],
    unreadable: &BTreeMap<String, String>,
) -> (Vec<Plan>, Vec<Option<DensifyVerdict>>) {
    let sources = nrw_colmap::overlap::source_images(
        rec,
        cfg.settings.matching().max_sources,
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
            verdicts.push(Some(DensifyVerdict::Unreadable(why.clone())));
            continue;
        }
        let srcs: Vec<usize> = sources[&e.image_id]
            .iter()
            .filter(|id| readable(id))
            .map(|id| index[id])
            .collect();
        verdicts.push(match ranges[&e.image_id] {
            _ if srcs.is_empty() => Some(DensifyVerdict::NoSourceView),
            None => Some(DensifyVerdict::NoDepthRange),
            Some(range) => {
                plan.push((i, srcs, range));
                None
            }
        });
    }
    (plan, verdicts)
}

/// Run one stereo pass over the views `unit` owns; (owned, computed, found done).
pub(super) fn run_pass(
    prep: &Prepared,
    cfg: &DensifyConfig,
    pass: MapPass,
    unit: Unit,
    progress: &dyn Progress,
) -> Result<(usize, usize, usize)> {
    if pass == MapPass::Geometric && !cfg.settings.geometric {
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
                MapPass::Geometric => {
                    fetch_inputs(prep, p)?;
                    geometric_view(&prep.ws, &prep.entries, p, cfg)?
                }
            }
            if let Some(remote) = &prep.remote {
                remote.share(
                    &prep.ws,
                    &written(&prep.ws, cfg, &prep.entries[p.0].name, pass)?,
                )?;
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
pub(super) fn last_map(
    ws: &Workspace,
    cfg: &DensifyConfig,
    name: &str,
    pass: MapPass,
) -> Result<PathBuf> {
    match pass {
        MapPass::Photometric if cfg.settings.geometric => {
            map_path(ws, MapKind::Normal, MapPass::Photometric, name)
        }
        _ => map_path(ws, MapKind::Confidence, MapPass::Geometric, name),
    }
}

/// The map files a view's pass writes, in the order it writes them ([`last_map`] last).
fn written(ws: &Workspace, cfg: &DensifyConfig, name: &str, pass: MapPass) -> Result<Vec<PathBuf>> {
    let (kinds, pass): (&[MapKind], _) = match pass {
        MapPass::Photometric if cfg.settings.geometric => {
            (&[MapKind::Depth, MapKind::Normal], MapPass::Photometric)
        }
        _ => (
            &[MapKind::Depth, MapKind::Normal, MapKind::Confidence],
            MapPass::Geometric,
        ),
    };
    kinds.iter().map(|&k| map_path(ws, k, pass, name)).collect()
}

/// Whether a view's pass is done: its last map is in the workspace (on object storage, in
/// the staging prefix the units share).
pub(super) fn pass_done(
    prep: &Prepared,
    cfg: &DensifyConfig,
    p: &Plan,
    pass: MapPass,
) -> Result<bool> {
    let last = last_map(&prep.ws, cfg, &prep.entries[p.0].name, pass)?;
    match &prep.remote {
        Some(remote) => remote.has(&prep.ws, &last),
        None => Ok(last.exists()),
    }
}

/// On object storage, fetch the photometric maps a view's geometric pass reads (its own
/// and its sources' depth, its own normals) that this machine has not computed itself.
fn fetch_inputs(prep: &Prepared, p: &Plan) -> Result<()> {
    let Some(remote) = &prep.remote else {
        return Ok(());
    };
    let name = |i: usize| prep.entries[i].name.as_str();
    let mut wanted = vec![map_path(
        &prep.ws,
        MapKind::Normal,
        MapPass::Photometric,
        name(p.0),
    )?];
    for &i in std::iter::once(&p.0).chain(&p.1) {
        wanted.push(map_path(
            &prep.ws,
            MapKind::Depth,
            MapPass::Photometric,
            name(i),
        )?);
    }
    for (k, path) in wanted.iter().enumerate() {
        if !remote.fetch(&prep.ws, path)? {
            let view = name(if k < 2 { p.0 } else { p.1[k - 2] });
            let url = remote.staging.name(&super::remote::rel(&prep.ws, path));
            return Err(PipelineError::input(url, photometric_unfinished(view)));
        }
    }
    Ok(())
}

/// A reference view and its sources, read back from the workspace.
pub(super) fn load_views(
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
pub(super) fn photometric_view(
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
    let state = nrw_stereo::photometric(&reference, &s, p.2, &cfg.settings.stereo())
        .expect("a planned view has sources and a range");
    let name = &entries[p.0].name;
    if cfg.settings.geometric {
        return write_hypotheses(ws, name, MapPass::Photometric, &state);
    }
    let maps = nrw_stereo::filter(&reference, &s, p.2, &state, false, &cfg.settings.stereo());
    write_maps(ws, name, MapPass::Geometric, &maps)
}

/// The geometric pass over one view, from its and its sources' photometric maps.
pub(super) fn geometric_view(
    ws: &Workspace,
    entries: &[Entry],
    p: &Plan,
    cfg: &DensifyConfig,
) -> Result<()> {
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
    let state = nrw_stereo::geometric(&reference, &s, p.2, start, &cfg.settings.stereo());
    let maps = nrw_stereo::filter(&reference, &s, p.2, &state, true, &cfg.settings.stereo());
    write_maps(ws, name, MapPass::Geometric, &maps)
}

/// A workspace being built: the model, the views and the plan every step derives alike.
pub(super) struct Prepared {
    pub(super) rec: Reconstruction,
    pub(super) out: Location,
    /// Where the units share the workspace being built: the staging folder or prefix.
    pub(super) staging: Location,
    /// The workspace this process builds in (the staging folder, or on object storage a
    /// local scratch folder).
    pub(super) ws: Workspace,
    /// The object-store side, when `out` is a URL.
    pub(super) remote: Option<Remote>,
    pub(super) entries: Vec<Entry>,
    pub(super) plan: Vec<Plan>,
    /// The verdict of each view stereo does not run on (`None` for planned views).
    pub(super) verdicts: Vec<Option<DensifyVerdict>>,
    pub(super) undistort_seconds: Option<f64>,
}
