//! The pipeline runner: the stages a pipeline file lists, in order (`nrw-etl run`), and the
//! demo's pipeline on the embedded synthetic scene (`nrw-etl demo`).

use nrw_dataset::split::TRAIN;
use nrw_dataset::Location;
use std::path::{Path, PathBuf};

use nrw_export::{ExportConfig, ExportSummary, Layout};

use crate::error::{PipelineError, Result, Setting};
use crate::ingest::{IngestConfig, IngestSummary};
use crate::split::SplitSummary;
use crate::style::{StyleConfig, StyleSummary};
use crate::triplets::TripletsSummary;
use crate::Progress;

/// `[densify]` before ingest: multi-view stereo into `dense` (SCENE/dense when `None`) unless
/// that workspace has a cloud already (and `overwrite` is off). The cloud ingest should read
/// when it is not the scene's own `dense/fused.ply`.
fn densify_before_ingest(
    p: &Pipeline,
    d: &DensifyTable,
    scene: &Path,
    dense: Option<&Path>,
    progress: &dyn Progress,
    done: &mut dyn FnMut(StageDone),
) -> Result<Option<PathBuf>> {
    let own = dense.map(|dir| nrw_colmap::dense::Workspace::new(dir).fused_ply());
    let cloud = match &own {
        Some(path) => Some(path.clone()).filter(|c| c.is_file()),
        None => nrw_colmap::Scene::find(scene)
            .ok()
            .and_then(|s| s.dense_cloud()),
    };
    if let Some(cloud) = cloud.as_ref().filter(|_| !d.overwrite) {
        progress.warn(&format!(
            "pipeline {}: densify skipped, {} is there already (overwrite = true in [densify] replaces it)",
            p.name,
            cloud.display()
        ));
    } else {
        let mut cfg = densify_config(d, scene);
        cfg.out = dense.map(Into::into);
        let r = crate::densify::densify(&cfg, progress)?;
        done(StageDone::Densify(&r));
    }
    Ok(own)
}

/// Densify's settings from `[densify]` (or the command line's, which are the same struct).
pub fn densify_config(d: &DensifyTable, scene: &Path) -> crate::densify::DensifyConfig {
    d.config(scene)
}

/// A stage the runner finished, with its summary (for the caller to show).
#[derive(Debug)]
pub enum StageDone<'a> {
    Densify(&'a crate::densify::DensifyReport),
    Ingest(&'a IngestSummary),
    Split(&'a SplitSummary),
    Style(&'a StyleSummary),
    Triplets(&'a TripletsSummary),
    Export(&'a Location, &'a ExportSummary),
    Qa(&'a nrw_qa::Written),
}

/// Where a pipeline run left its results.
#[derive(Debug, Clone)]
pub struct RunOutcome {
    /// false when ingest kept no view (later stages were skipped).
    pub kept: bool,
    pub dataset: Location,
    pub export: Option<Location>,
    pub report: Option<Location>,
}

/// The model files a pipeline's stages read, given on the command line (never downloaded).
#[derive(Debug, Clone, Copy, Default)]
pub struct Models<'a> {
    /// VGG weights for a style stage with a VGG tier.
    pub vgg: Option<&'a Path>,
    /// A SegFormer: ingest segments every kept photo with it.
    pub segformer: Option<&'a Path>,
}

/// Ingest's settings from `[ingest]` and the models.
fn ingest_config(
    i: &IngestTable,
    scene: &Path,
    out: &Location,
    models: Models,
) -> Result<IngestConfig> {
    let mut c = i.config(scene, out, models.segformer.map(Into::into))?;
    c.settings.semantics = i.semantics.as_ref().map(|s| scene.join(s));
    Ok(c)
}

fn export_config(
    e: &ExportTable,
    dataset: &Location,
    out: &Location,
    segmented: bool,
) -> Result<(Layout, ExportConfig)> {
    let mut c = e.config(dataset, out)?;
    // A run that segments its photos exports their labels.
    c.paper.semantics |= segmented;
    Ok((e.layout, c))
}

fn style_config(s: &StyleTable, dataset: &Location, weights: Option<&Path>) -> Result<StyleConfig> {
    let c = s.config(dataset, weights.map(Into::into))?;
    if c.tier.needs_weights() && weights.is_none() {
        return Err(PipelineError::config(Setting::Weights, format!(
            "FILE is required: the pipeline's style tier {} runs VGG (the tool never downloads weights)",
            s.tier
        )));
    }
    // A pipeline run owns its dataset: descriptors of another tier are replaced.
    Ok(StyleConfig {
        overwrite: true,
        ..c
    })
}

/// The configs of the stages a pipeline file turns on that are built before any runs (so a
/// bad table stops the run before any work).
struct StageConfigs {
    style: Option<StyleConfig>,
    export: Option<(Layout, ExportConfig)>,
    ingest: Option<IngestConfig>,
}

impl StageConfigs {
    fn of(
        p: &Pipeline,
        scene: &Path,
        (out, export_dir): (&Location, &Location),
        models: Models,
    ) -> Result<StageConfigs> {
        let style = p
            .style
            .as_ref()
            .map(|s| style_config(s, out, models.vgg))
            .transpose()?;
        let segmented = models.segformer.is_some() && p.ingest.is_some();
        let export = p
            .export
            .as_ref()
            .map(|e| export_config(e, out, export_dir, segmented))
            .transpose()?;
        let ingest = p
            .ingest
            .as_ref()
            .map(|i| ingest_config(i, scene, out, models))
            .transpose()?;
        Ok(StageConfigs {
            style,
            export,
            ingest,
        })
    }
}

/// Run every stage `p` lists on `scene` into the dataset `out` (the export into
/// `export_dir`, the report into out/qa). Settings are checked before the first stage runs.
#[allow(clippy::too_many_arguments)] // each a place or a model the caller names
pub fn run(
    p: &Pipeline,
    scene: &Path,
    dense: Option<&Path>,
    out: &Location,
    export_dir: &Location,
    models: Models,
    progress: &dyn Progress,
    done: &mut dyn FnMut(StageDone),
) -> Result<RunOutcome> {
    let StageConfigs {
        style,
        export,
        mut ingest,
    } = StageConfigs::of(p, scene, (out, export_dir), models)?;
    preflight::preflight(p, scene)?;
    let mut outcome = RunOutcome {
        kept: true,
        dataset: out.clone(),
        export: None,
        report: None,
    };
    if let Some(d) = &p.densify {
        if let Some(cloud) = densify_before_ingest(p, d, scene, dense, progress, done)? {
            if let Some(c) = ingest.as_mut().filter(|c| c.points.is_none()) {
                c.points = Some(cloud);
            }
        }
    }
    if let Some(c) = &ingest {
        let s = crate::ingest::ingest(c, progress)?;
        done(StageDone::Ingest(&s));
        outcome.kept = s.kept > 0;
    }
    if !outcome.kept {
        progress.warn(&format!(
            "pipeline {}: no view kept, later stages skipped",
            p.name
        ));
        return Ok(outcome);
    }
    if let Some(s) = &p.split {
        let r = crate::split::split(&s.config(out)?)?;
        done(StageDone::Split(&r));
    }
    if let Some(c) = &style {
        let r = crate::style::style(c, progress)?;
        done(StageDone::Style(&r));
    }
    if let Some(t) = &p.triplets {
        let mut cfg = t.config(out);
        cfg.settings.k = capped_k(t.k, out, progress)?;
        let r = crate::triplets::triplets(&cfg)?;
        done(StageDone::Triplets(&r));
    }
    if let Some((layout, c)) = &export {
        let r = crate::export::export(out, *layout, c, progress)?;
        done(StageDone::Export(export_dir, &r));
        outcome.export = Some(export_dir.clone());
    }
    if p.qa.is_some() {
        let w = crate::qa::qa(&crate::qa::QaConfig {
            dataset: out.into(),
            out: None,
        })?;
        done(StageDone::Qa(&w));
        outcome.report = Some(w.report.clone());
    }
    Ok(outcome)
}

/// `k`, lowered to the training photos minus the anchor when there are fewer (with a warning).
fn capped_k(k: usize, dataset: &nrw_dataset::Location, progress: &dyn Progress) -> Result<usize> {
    let dataset = &nrw_dataset::Store::open(dataset)?;
    let splits = nrw_dataset::split::read_splits(dataset)?;
    let scope = if splits.is_empty() {
        nrw_dataset::reader::Dataset::open(dataset)?.len()
    } else {
        splits.iter().filter(|a| a.split == TRAIN).count()
    };
    let cap = scope.saturating_sub(1).max(1);
    if k > cap {
        progress.warn(&format!(
            "triplets: k lowered from {k} to {cap}: the scope holds {scope} photos"
        ));
    }
    Ok(k.min(cap))
}

/// Synthesise the demo scene (or `spec`) into `dir/scene` and run the demo pipeline into
/// `dir/dataset`.
pub fn demo(
    dir: &Path,
    spec: Option<&Path>,
    seed: Option<u64>,
    weights: Option<&Path>,
    progress: &dyn Progress,
    done: &mut dyn FnMut(StageDone),
) -> Result<(nrw_synth::SynthReport, RunOutcome)> {
    let spec = crate::synth::load_spec(spec, seed)?;
    let scene = dir.join("scene");
    let report = crate::synth::generate(&spec, &scene, progress)?;
    let pipeline = Pipeline::demo(weights.is_some());
    let out = run(
        &pipeline,
        &scene,
        None,
        &dir.join("dataset").into(),
        &dir.join("export").into(),
        Models {
            vgg: weights,
            segformer: None,
        },
        progress,
        done,
    )?;
    if !out.kept {
        return Err(PipelineError::dataset(
            &out.dataset,
            "the demo scene kept no view: this is a bug",
        ));
    }
    Ok((report, out))
}

mod overrides;
mod pipeline;
mod preflight;
#[cfg(test)]
mod tests;

pub use overrides::Override;
pub use pipeline::{
    DensifyTable, ExportTable, IngestTable, Pipeline, QaTable, SplitTable, StyleTable,
    TripletsTable,
};
