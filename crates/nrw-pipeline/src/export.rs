//! Export: a dataset as files other tools read (the layouts and their bytes live in
//! `nrw_export`); this supplies what the layouts need from other stages (the style distance
//! matrix, the scene's points) and the default name.

use nrw_export::{ExportConfig, ExportSummary, Layout};

use crate::error::Result;
use crate::Progress;

/// The export's default name: the dataset folder's.
pub fn default_name(dataset: &nrw_dataset::Location) -> String {
    let folder = match dataset {
        nrw_dataset::Location::Local(d) => std::fs::canonicalize(d)
            .ok()
            .and_then(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
            .or_else(|| d.file_name().map(|n| n.to_string_lossy().into_owned())),
        nrw_dataset::Location::Url(u) => u.rsplit('/').next().map(str::to_string),
    };
    folder
        .filter(|n| !n.is_empty())
        .unwrap_or_else(|| "dataset".into())
}

pub fn official(dataset: &nrw_dataset::Location, out: &nrw_dataset::Location) -> ExportConfig {
    ExportConfig::official(out.clone(), default_name(dataset))
}

/// Export `dataset` in `layout` as `cfg` says.
pub fn export(
    dataset: &nrw_dataset::Location,
    layout: Layout,
    cfg: &ExportConfig,
    progress: &dyn Progress,
) -> Result<ExportSummary> {
    let store = &nrw_dataset::Store::open(dataset)?;
    crate::timing::timed(store, "export", || {
        let ds = crate::triplets::require_views(store)?;
        let total: usize = ds.splits().iter().map(|(_, n)| n).sum();
        let model = if layout.about().needs_points {
            Some(scene_model(store)?)
        } else {
            None
        };
        let points = match &model {
            Some(rec) => Some(init_points(store, rec)?),
            None => None,
        };
        let mvs = if layout.about().writes_depth_priors {
            crate::mvs_prior::MvsPriors::of_dataset(store)?
        } else {
            None
        };
        let mvs_depth = |v: &nrw_dataset::ViewRow| match &mvs {
            Some(m) => m.depth(v).map_err(|e| e.to_string()),
            None => Ok(None),
        };
        let prior = mvs.as_ref().map(|m| nrw_export::DepthPrior {
            source: m.source(),
            depth: &mvs_depth,
        });
        let dist =
            |ids: &[u32]| crate::triplets::official_distance_matrix(store, ids, cfg.paper.crop);
        let inputs = nrw_export::Inputs {
            dist: Some(&dist),
            points: points.as_deref(),
            model: model.as_ref(),
            depth_prior: prior.as_ref(),
        };
        progress.start("export", total as u64, "views");
        let summary = nrw_export::export(&ds, layout, cfg, &inputs, &|| progress.inc(1))?;
        progress.finish();
        Ok(summary)
    })
}

/// The model the dataset was ingested from (named in its manifest), after checking that the
/// model files are the ones ingest read.
pub fn scene_model(store: &nrw_dataset::Store) -> Result<nrw_colmap::Reconstruction> {
    let m = nrw_dataset::Manifest::read(store)?;
    let (rec, changed) = crate::model::reread_model(&m.scene, &m.inputs)?;
    if let Some(f) = changed {
        return Err(crate::error::PipelineError::input(
            &f,
            "changed since this dataset was ingested from it (its SHA-256 differs from the \
             manifest's): the exported points would not belong to the dataset's poses",
        ));
    }
    Ok(rec)
}

/// The initialisation cloud the layouts carry: the cloud ingest rendered — a dense PLY
/// cleaned as ingest cleaned it (its recorded outlier removal and normal estimation), with
/// its normals — or the model's SfM points when ingest rendered those.
pub fn init_points(
    store: &nrw_dataset::Store,
    rec: &nrw_colmap::Reconstruction,
) -> Result<Vec<nrw_export::ScenePoint>> {
    let m = nrw_dataset::Manifest::read(store)?;
    let at = store.name(nrw_dataset::Manifest::FILE);
    let p: nrw_dataset::provenance::IngestParameters =
        nrw_dataset::provenance::from_parameters(&at, &m.parameters)?;
    let Some(ply) = m.inputs.iter().find(|f| f.path.ends_with(".ply")) else {
        return Ok(points_of(rec));
    };
    if p.point_source != "ply" {
        return Ok(points_of(rec));
    }
    let path = std::path::Path::new(&ply.path);
    let (_, sha) = nrw_dataset::manifest::sha256_file(path)?;
    if sha != ply.sha256 {
        return Err(crate::error::PipelineError::input(
            path,
            "changed since this dataset was ingested from it (its SHA-256 differs from the \
             manifest's): the exported cloud would not be the one rendered",
        ));
    }
    let mut cloud = nrw_colmap::read_ply(path)?;
    let origin = rec.scene_origin();
    if let Some(d) = p.denoise {
        let (keep, _) =
            nrw_render::clean::statistical_outliers(&cloud.positions, origin, d.k, d.sigma);
        let mut flags = keep.iter();
        cloud
            .positions
            .retain(|_| *flags.next().expect("one flag a point"));
        for c in [cloud.colors.as_mut()].into_iter().flatten() {
            let mut flags = keep.iter();
            c.retain(|_| *flags.next().expect("one flag a point"));
        }
        for n in [cloud.normals.as_mut()].into_iter().flatten() {
            let mut flags = keep.iter();
            n.retain(|_| *flags.next().expect("one flag a point"));
        }
    }
    if let (Some(k), None) = (p.estimated_normals_k, &cloud.normals) {
        // As ingest estimates them for a PLY: oriented toward the mean camera centre.
        let centres: Vec<glam::DVec3> = rec
            .images
            .values()
            .map(|i| i.cam_from_world.centre())
            .collect();
        let mean = centres.iter().copied().sum::<glam::DVec3>() / centres.len().max(1) as f64;
        cloud.normals = Some(nrw_render::clean::estimate_normals(
            &cloud.positions,
            origin,
            k,
            &|_| mean,
        ));
    }
    Ok(cloud
        .positions
        .iter()
        .enumerate()
        .map(|(i, x)| nrw_export::ScenePoint {
            id: i as u64 + 1,
            xyz: x.to_array(),
            rgb: cloud.colors.as_ref().map_or([128; 3], |c| c[i]),
            error: -1.0,
            normal: cloud.normals.as_ref().map(|n| n[i]),
        })
        .collect())
}

/// A model's 3D points as the layouts carry them.
pub fn points_of(rec: &nrw_colmap::Reconstruction) -> Vec<nrw_export::ScenePoint> {
    rec.points
        .values()
        .map(|p| nrw_export::ScenePoint {
            id: p.id,
            xyz: p.xyz.to_array(),
            rgb: p.rgb,
            error: p.error,
            normal: None,
        })
        .collect()
}
