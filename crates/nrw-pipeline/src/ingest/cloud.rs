//! The cloud to render: the dense or sparse points, outliers removed and normals estimated
//! when asked, re-centred on the scene origin.

use std::collections::BTreeMap;
use std::path::PathBuf;

use nrw_colmap::{read_ply, Reconstruction};
use nrw_render::RenderCloud;

use crate::error::{PipelineError, Result, Setting};

use super::config::IngestConfig;
use nrw_dataset::provenance::DenoiseRecord;

/// A cloud as read, before clean-up: straight into f32 columns when no clean-up needs more
/// (a dense cloud without --denoise or --estimate-normals: 27 bytes a point at most), else
/// f64 positions, its channels, and per point where it is seen from (the mean centre of the
/// cameras that observe a sparse point; the scene's mean camera centre for a dense cloud,
/// which has no tracks).
pub(super) enum RawCloud {
    /// Read straight into the renderer's f32 columns: nothing asked for the f64 positions.
    Local(nrw_render::cloud::LocalPoints),
    /// World positions in f64, for the cleaning steps that need them.
    World {
        positions: Vec<glam::DVec3>,
        colors: Option<Vec<[u8; 3]>>,
        normals: Option<Vec<[f32; 3]>>,
        seen_from: Vec<glam::DVec3>,
    },
}

pub(super) fn point_source(
    cfg: &IngestConfig,
    scene: &nrw_colmap::Scene,
    rec: &Reconstruction,
) -> Result<(RawCloud, String, Option<PathBuf>)> {
    let candidate = cfg.points.clone().or_else(|| scene.dense_cloud());
    let centres: BTreeMap<u32, glam::DVec3> = rec
        .images
        .iter()
        .map(|(id, i)| (*id, i.cam_from_world.centre()))
        .collect();
    let mean_centre = centres.values().copied().sum::<glam::DVec3>() / centres.len().max(1) as f64;
    match candidate {
        Some(p) if cfg.settings.denoise.is_none() && cfg.settings.estimate_normals.is_none() => {
            let mut local = nrw_render::cloud::LocalPoints::new(rec.scene_origin());
            nrw_colmap::read_ply_file_into(&p, &mut local)?;
            Ok((RawCloud::Local(local), "ply".into(), Some(p)))
        }
        Some(p) => {
            let cloud = read_ply(&p)?;
            let raw = RawCloud::World {
                seen_from: vec![mean_centre; cloud.positions.len()],
                positions: cloud.positions,
                colors: cloud.colors,
                normals: cloud.normals,
            };
            Ok((raw, "ply".into(), Some(p)))
        }
        None if !rec.points.is_empty() => {
            let raw = RawCloud::World {
                positions: rec.points.values().map(|p| p.xyz).collect(),
                colors: Some(rec.points.values().map(|p| p.rgb).collect()),
                normals: None,
                seen_from: rec
                    .points
                    .values()
                    .map(|p| {
                        let n = p.track.len().max(1) as f64;
                        let sum: glam::DVec3 = p
                            .track
                            .iter()
                            .filter_map(|t| centres.get(&t.image_id))
                            .sum();
                        if p.track.is_empty() {
                            mean_centre
                        } else {
                            sum / n
                        }
                    })
                    .collect(),
            };
            Ok((raw, "sparse".into(), None))
        }
        None => Err(PipelineError::input(
            &scene.model_dir,
            format!(
                "nothing to render: no dense/fused.ply, no {} file, and the model has no 3D points",
                Setting::Points
            ),
        )),
    }
}

/// Keep the elements whose flag is set (flags and elements in the same order).
pub(super) fn keep_where<T>(v: &mut Vec<T>, keep: &[bool]) {
    let mut flags = keep.iter();
    v.retain(|_| *flags.next().expect("one flag per element"));
}

/// What clean-up did to the cloud, for the manifest (None: not asked for, or not needed).
#[derive(Debug, Default)]
pub(super) struct Cleaned {
    pub denoise: Option<DenoiseRecord>,
    pub estimated_normals_k: Option<usize>,
}

/// The cloud to render: outliers removed (`--denoise`), normals estimated where it has none
/// (`--estimate-normals`), re-centred on `origin`. Returns what clean-up did, for the
/// manifest (absent keys: not asked for).
pub(super) fn render_cloud(
    cfg: &IngestConfig,
    raw: RawCloud,
    origin: glam::DVec3,
    warnings: &mut Vec<String>,
) -> (RenderCloud, Cleaned) {
    let mut report = Cleaned::default();
    let (mut positions, mut colors, mut normals, mut seen_from) = match raw {
        RawCloud::Local(local) => return (local.finish(), report),
        RawCloud::World {
            positions,
            colors,
            normals,
            seen_from,
        } => (positions, colors, normals, seen_from),
    };
    if let Some(crate::settings::ingest::Denoise { k, sigma }) = cfg.settings.denoise {
        let (keep, r) = nrw_render::clean::statistical_outliers(&positions, origin, k, sigma);
        keep_where(&mut positions, &keep);
        keep_where(&mut seen_from, &keep);
        if let Some(c) = colors.as_mut() {
            keep_where(c, &keep);
        }
        if let Some(n) = normals.as_mut() {
            keep_where(n, &keep);
        }
        report.denoise = Some(DenoiseRecord {
            k: r.k,
            sigma: r.sigma,
            mean: r.mean,
            std: r.std,
            threshold: r.threshold,
            points: r.points,
            removed: r.removed,
        });
    }
    if let Some(k) = cfg.settings.estimate_normals {
        if normals.is_some() {
            warnings.push(format!(
                "{} {k}: the cloud has normals of its own; they are used",
                Setting::Key("ingest.estimate_normals")
            ));
        } else {
            let n = nrw_render::clean::estimate_normals(&positions, origin, k, &|i| seen_from[i]);
            normals = Some(n);
            report.estimated_normals_k = Some(k);
        }
    }
    let cloud = RenderCloud::new(origin, &positions, colors.as_deref(), normals.as_deref());
    (cloud, report)
}
