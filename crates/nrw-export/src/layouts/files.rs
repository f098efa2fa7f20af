//! The `files` layout: `SPLIT/NAME/` with every stored payload as it is in the dataset and a
//! `meta.json` of the view's camera, for ordinary viewers.

use std::path::Path;

use nrw_dataset::ViewRow;

use crate::error::{ExportError, Result};
use crate::staging::Staged;
use crate::stream::{write_views, Encoded, ViewEncoder};
use crate::writer::{About, Job, LayoutWriter};
use crate::ExportSummary;

/// The `files` layout, as the CLI, pipeline files and `export.json` name it.
pub const ABOUT: About = About {
    name: "files",
    summary: "SPLIT/NAME/{photo.png, color.png, depth.exr, normal.png, semantics.png, labels.png, transient.png, meta.json}",
    needs_points: false,
    writes_depth_priors: false,
    default_crop: None,
};

/// The `files` layout.
pub struct Files;

impl LayoutWriter for Files {
    fn check(&self, job: &Job) -> Result<()> {
        crate::paper::check_counts(job.cfg)?;
        if job.cfg.paper.crop.is_some() {
            // The files layout keeps every payload as stored; a crop would be silently ignored.
            return Err(ExportError::refused(
                &job.cfg.out,
                "`export.crop` applies to the official and tfrecord layouts; the files layout keeps views whole",
            ));
        }
        Ok(())
    }

    fn write(&self, job: &Job, staged: &Staged, summary: &mut ExportSummary) -> Result<()> {
        summary.semantics = Some("ade20k".into());
        write_views(job, staged, self, summary)
    }
}

impl ViewEncoder for Files {
    fn encode(&self, v: &ViewRow, split: &str, _index: &str) -> Result<Encoded> {
        let stem = format!(
            "{split}/{}",
            Path::new(&v.name).with_extension("").display()
        );
        let mut files = vec![
            (format!("{stem}/photo.png"), v.photo_png.clone()),
            (format!("{stem}/color.png"), v.color_png.clone()),
            (format!("{stem}/depth.exr"), v.depth_exr.clone()),
        ];
        for (n, p) in [
            ("normal.png", &v.normal_png),
            ("semantics.png", &v.semantics_png),
            ("labels.png", &v.labels_png),
            ("transient.png", &v.transient_png),
        ] {
            if let Some(p) = p {
                files.push((format!("{stem}/{n}"), p.clone()));
            }
        }
        let meta = serde_json::json!({
            "image_id": v.image_id, "name": v.name, "camera_id": v.camera_id, "model": v.model,
            "width": v.width, "height": v.height, "params": v.params,
            "qvec": v.qvec, "tvec": v.tvec, "empty_ratio": v.empty_ratio,
        });
        files.push((
            format!("{stem}/meta.json"),
            serde_json::to_vec_pretty(&meta).expect("json"),
        ));
        Ok(files)
    }
}
