//! The seam every layout plugs into: a [`LayoutWriter`] checks what it can export and writes its
//! files into the staging folder; [`crate::export`] picks the layout's format and does the
//! rest (staging, `export.json`, publishing) the same way for all.

use nrw_dataset::reader::Dataset;
use nrw_dataset::split::TRAIN;

use crate::error::{ExportError, Result};
use crate::inputs::{Inputs, Prior, ScenePoint, RENDER_DEPTH};
use crate::staging::Staged;
use crate::{ExportConfig, ExportSummary, SplitExport};

/// One export's inputs, as every layout sees them.
pub struct Job<'a> {
    pub ds: &'a Dataset,
    /// The layout being written.
    pub about: &'static About,
    pub cfg: &'a ExportConfig,
    /// The dataset's splits and their view counts, in order.
    pub splits: Vec<(String, usize)>,
    pub inputs: &'a Inputs<'a>,
    /// Called once per view done (written or skipped).
    pub tick: &'a (dyn Fn() + Sync),
}

impl<'a> Job<'a> {
    /// Refuse a dataset without train views, which every layout but `files` needs.
    pub fn require_train(&self, advice: &str) -> Result<()> {
        if self.splits.iter().any(|(s, n)| s == TRAIN && *n > 0) {
            return Ok(());
        }
        Err(ExportError::refused(
            &self.ds.dir,
            format!(
                "the {} layout needs a train split with views; split it first (`split.val` N holds out N photos){advice}",
                self.about.name
            ),
        ))
    }

    /// The scene's 3D points, which the NeRF layouts carry: refused when not given or empty.
    pub fn points(&self) -> Result<&[ScenePoint]> {
        match self.inputs.points {
            Some(p) if !p.is_empty() => Ok(p),
            Some(_) => Err(ExportError::refused(
                &self.cfg.out,
                "the scene has no 3D points (NeRF-W loaders take near and far bounds from them, \
                 splatting trainers their initial Gaussians)",
            )),
            None => Err(ExportError::refused(
                &self.cfg.out,
                format!(
                    "the {} layout needs the scene's 3D points (Inputs::points)",
                    self.about.name
                ),
            )),
        }
    }

    /// The scene model the dataset was ingested from, which carries the tracks the layouts'
    /// COLMAP models keep: refused when not given.
    pub fn scene_model(&self) -> Result<&'a nrw_colmap::Reconstruction> {
        self.inputs.model.ok_or_else(|| {
            ExportError::refused(
                &self.cfg.out,
                format!(
                    "the {} layout needs the scene's model (Inputs::model) for its tracks",
                    self.about.name
                ),
            )
        })
    }

    /// A view's depth prior: the caller's (densify's MVS) where it has one, else the render's
    /// z-buffer.
    pub fn prior_depth(&self, v: &nrw_dataset::ViewRow) -> Result<nrw_dataset::depth::DepthMap> {
        Ok(self.prior(v)?.depth)
    }

    /// A view's depth prior with its confidence, when the source has one.
    pub fn prior(&self, v: &nrw_dataset::ViewRow) -> Result<Prior> {
        if let Some(p) = self.inputs.depth_prior {
            let got = (p.depth)(v).map_err(|problem| ExportError::Value {
                path: v.name.clone().into(),
                record: format!("image {}", v.image_id),
                field: "depth".into(),
                problem,
            })?;
            if let Some(prior) = got {
                return Ok(prior);
            }
        }
        Ok(Prior {
            depth: v.depth()?,
            confidence: None,
        })
    }

    /// What `export.json` names as the source of depth priors.
    pub fn depth_source(&self) -> String {
        self.inputs
            .depth_prior
            .map_or_else(|| RENDER_DEPTH.to_string(), |p| p.source.clone())
    }

    /// The splits with no view, as `export.json` lists them.
    pub fn empty_splits(&self) -> Vec<String> {
        self.splits
            .iter()
            .filter(|(_, n)| *n == 0)
            .map(|(s, _)| s.clone())
            .collect()
    }
}

/// What a layout is, declared in its own file: the name the CLI, pipeline files and
/// `export.json` use, its help line, and what it needs from the other stages.
#[derive(Debug)]
pub struct About {
    pub name: &'static str,
    /// What the layout holds, in one line (the CLI's help for the value).
    pub summary: &'static str,
    /// Whether it carries the scene's 3D points ([`crate::Inputs::points`]).
    pub needs_points: bool,
    /// Whether it writes depth priors, which prefer densify's MVS depth to the render's
    /// z-buffer.
    pub writes_depth_priors: bool,
    /// The crop when none is asked (the published 512 for the paper's layouts).
    pub default_crop: Option<u32>,
}

/// One export layout: what it refuses before anything is written, and the files it writes.
pub trait LayoutWriter: Sync {
    /// Refuse what this layout cannot export (settings, dataset), before the staging folder
    /// exists.
    fn check(&self, job: &Job) -> Result<()>;

    /// Write every file of the layout except `export.json` through `staged`, and fill in
    /// `summary` (which becomes `export.json`).
    fn write(&self, job: &Job, staged: &Staged, summary: &mut ExportSummary) -> Result<()>;
}

/// A layout that carries the scene's points (nerfstudio): its writer, given the job
/// and the points, returns the splits written and the consumer warnings.
pub type PointsWriter = fn(&Job, &[ScenePoint], &Staged) -> Result<(Vec<SplitExport>, Vec<String>)>;

/// The [`LayoutWriter`] of a layout with points: it needs train views and the points, and lists the
/// splits without views as empty.
pub struct WithPoints(pub PointsWriter);

impl LayoutWriter for WithPoints {
    fn check(&self, job: &Job) -> Result<()> {
        job.require_train("")?;
        job.points().map(|_| ())
    }

    fn write(&self, job: &Job, staged: &Staged, summary: &mut ExportSummary) -> Result<()> {
        summary.empty_splits = job.empty_splits();
        (summary.splits, summary.warnings) = (self.0)(job, job.points()?, staged)?;
        if job.about.writes_depth_priors {
            summary.depth_source = Some(job.depth_source());
        }
        Ok(())
    }
}

/// A layout that carries the scene's model (nerfw, nerfbaselines): its writer, given the job
/// and the model, returns the splits written and the consumer warnings.
pub type ModelWriter =
    fn(&Job, &nrw_colmap::Reconstruction, &Staged) -> Result<(Vec<SplitExport>, Vec<String>)>;

/// The [`LayoutWriter`] of a layout with the scene's model: it needs train views and the
/// model, and lists the splits without views as empty.
pub struct WithModel(pub ModelWriter);

impl LayoutWriter for WithModel {
    fn check(&self, job: &Job) -> Result<()> {
        job.require_train("")?;
        job.scene_model().map(|_| ())
    }

    fn write(&self, job: &Job, staged: &Staged, summary: &mut ExportSummary) -> Result<()> {
        summary.empty_splits = job.empty_splits();
        let model = job.scene_model()?;
        (summary.splits, summary.warnings) = (self.0)(job, model, staged)?;
        Ok(())
    }
}
