//! `segment`: the paper's segmentation step. Every registered photo of a scene → an 8-bit
//! PNG of ADE20K class ids in a label folder (the format `ingest --semantics` reads), from a
//! SegFormer the user gives. Photos run in parallel, one per core; a photo whose label map
//! exists is skipped, so an interrupted run resumes; a record in the folder ties the maps to
//! the model and mode that made them. As a work unit (`--unit I/N`) it does the photos at
//! positions `p ≡ I (mod N)` in image-id order; units write disjoint files and need no
//! `finalize`.

use std::path::{Path, PathBuf};

use nrw_dataset::resume::Agreement;
use std::time::Instant;

use nrw_colmap::Format;
use nrw_segment::{Mode, Parallelism, Segformer};
use rayon::prelude::*;

use crate::error::{PipelineError, Result, Setting};
use crate::progress::Progress;

/// The label folder's record of what made its maps.
pub const RECORD: &str = "segment.json";

/// Settings of `segment`.
#[derive(Debug, Clone)]
pub struct SegmentConfig {
    /// Scene folder (COLMAP layout) or a model folder itself; `None`: every photo in
    /// `images` (a folder of photos without a model, e.g. a benchmark's validation set).
    pub scene: Option<PathBuf>,
    /// Photo folder [default: images/ next to the model].
    pub images: Option<PathBuf>,
    /// Model encoding to read [default: bin when present].
    pub format: Option<Format>,
    /// The SegFormer: a folder with config.json and model.safetensors.
    pub weights: PathBuf,
    /// Label folder to write.
    pub out: PathBuf,
    /// How photos are fed to the network.
    pub mode: Mode,
    /// Make an unreadable photo an error instead of a warning.
    pub strict: bool,
    /// Read a photo that is a symbolic link out of the images folder (refused by default).
    pub follow_outside_links: bool,
    /// The work unit this process does (`Unit::WHOLE`: every photo).
    pub unit: crate::Unit,
}

impl SegmentConfig {
    /// Hugging Face's default mode for a scene, a model and a label folder.
    pub fn new(
        scene: impl Into<PathBuf>,
        weights: impl Into<PathBuf>,
        out: impl Into<PathBuf>,
    ) -> SegmentConfig {
        SegmentConfig {
            scene: Some(scene.into()),
            images: None,
            format: None,
            weights: weights.into(),
            out: out.into(),
            mode: Mode::default(),
            strict: false,
            follow_outside_links: false,
            unit: crate::Unit::WHOLE,
        }
    }
}

/// What the label folder records about the maps in it.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SegmentRecord {
    pub model_sha256: String,
    pub mode: String,
    /// `ADE20K-150`: ids 1…150 as in schemas/ade20k.csv, 0 unlabelled.
    pub classes: String,
}

/// What `segment` did.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SegmentSummary {
    pub out: String,
    pub model: String,
    pub model_sha256: String,
    pub mode: String,
    /// The work unit, `I/N` (`0/1`: the whole stage).
    pub unit: crate::Unit,
    /// Registered photos this unit owns.
    pub photos: usize,
    /// Label maps written by this run.
    pub segmented: usize,
    /// Label maps found from an earlier run.
    pub resumed: usize,
    /// Photos that could not be decoded (no label map; their views are `unreadable` anyway).
    pub unreadable: Vec<String>,
    pub warnings: Vec<String>,
    pub seconds: f64,
}

/// Load the model named by a user, as a pipeline error.
pub fn load_segformer(weights: &Path) -> Result<Segformer> {
    Ok(Segformer::load(weights)?)
}

/// Label maps of every registered photo of a scene.
pub fn segment(cfg: &SegmentConfig, progress: &dyn Progress) -> Result<SegmentSummary> {
    let start = Instant::now();
    let (photos_dir, all) = photo_list(cfg)?;
    let model = load_segformer(&cfg.weights)?;
    let record = SegmentRecord {
        model_sha256: model.sha256.clone(),
        mode: cfg.mode.to_string(),
        classes: "ADE20K-150".into(),
    };
    claim_folder(&cfg.out, &record)?;
    let names: Vec<&str> = all
        .iter()
        .enumerate()
        .filter(|(p, _)| cfg.unit.owns(*p))
        .map(|(_, n)| n.as_str())
        .collect();
    let mut done = Vec::new();
    let mut todo = Vec::new();
    for &n in &names {
        if nrw_dataset::semantics::label_path(&cfg.out, n)?.is_file() {
            done.push(n);
        } else {
            todo.push(n);
        }
    }
    progress.start("segmenting photos", todo.len() as u64, "photos");
    let photos = nrw_colmap::names::PhotoDir::new(&photos_dir, cfg.follow_outside_links);
    let results: Vec<Result<Option<String>>> = todo
        .par_iter()
        .map(|name| {
            let r = segment_one(cfg, &model, &photos, name);
            progress.inc(1);
            r
        })
        .collect();
    progress.finish();
    let mut unreadable = Vec::new();
    let mut warnings = Vec::new();
    for r in results {
        if let Some(problem) = r? {
            progress.warn(&problem);
            warnings.push(problem.clone());
            unreadable.push(problem);
        }
    }
    Ok(SegmentSummary {
        out: cfg.out.display().to_string(),
        model: cfg.weights.display().to_string(),
        model_sha256: model.sha256.clone(),
        mode: record.mode,
        unit: cfg.unit,
        photos: names.len(),
        segmented: todo.len() - unreadable.len(),
        resumed: done.len(),
        unreadable,
        warnings,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// The photo folder and the photos to segment, in a fixed order: a scene's registered
/// photos in image-id order, or every JPEG and PNG under the folder, sorted by path.
fn photo_list(cfg: &SegmentConfig) -> Result<(PathBuf, Vec<String>)> {
    if let Some(scene) = &cfg.scene {
        let (scene, rec) = crate::model::load_model(scene, cfg.format, None)?;
        let dir = crate::model::images_dir(cfg.images.as_deref(), &scene)?;
        return Ok((dir, rec.images.values().map(|i| i.name.clone()).collect()));
    }
    let Some(dir) = &cfg.images else {
        return Err(PipelineError::config(
            Setting::Photos,
            "or an images folder: give one",
        ));
    };
    if !dir.is_dir() {
        return Err(PipelineError::input(
            dir,
            format!("{} is not a folder", Setting::Images),
        ));
    }
    let mut names = Vec::new();
    let mut stack = vec![dir.clone()];
    while let Some(d) = stack.pop() {
        let entries = std::fs::read_dir(&d).map_err(|e| PipelineError::io(&d, e))?;
        for e in entries {
            let p = e.map_err(|e| PipelineError::io(&d, e))?.path();
            let photo = p
                .extension()
                .and_then(|x| x.to_str())
                .is_some_and(|x| ["jpg", "jpeg", "png"].contains(&x.to_ascii_lowercase().as_str()));
            if p.is_dir() {
                stack.push(p);
            } else if photo {
                let rel = p.strip_prefix(dir).expect("under the folder");
                names.push(rel.to_string_lossy().into_owned());
            }
        }
    }
    if names.is_empty() {
        return Err(PipelineError::input(
            dir,
            "no .jpg, .jpeg or .png photos in this folder",
        ));
    }
    names.sort();
    Ok((dir.clone(), names))
}

/// Create the label folder or check that its maps came from the same model and mode.
fn claim_folder(out: &Path, record: &SegmentRecord) -> Result<()> {
    let store = nrw_dataset::Store::local(out);
    match nrw_dataset::resume::agree(&store, RECORD, record, itself)? {
        Agreement::Same(_) => Ok(()),
        Agreement::Differs { found, .. } => Err(PipelineError::input(
            out.join(RECORD),
            format!(
                "this folder holds label maps of model {} (mode {}), not of model {} (mode {}); write to another folder",
                found.model_sha256, found.mode, record.model_sha256, record.mode
            ),
        )),
        Agreement::Fresh => {
            std::fs::create_dir_all(out).map_err(|e| PipelineError::io(out, e))?;
            Ok(nrw_dataset::resume::write_record(&store, RECORD, record)?)
        }
    }
}

/// The whole record is what every run must share.
fn itself(r: &SegmentRecord) -> &SegmentRecord {
    r
}

/// One photo's label map, written atomically; `Some(problem)` when the photo is unreadable.
fn segment_one(
    cfg: &SegmentConfig,
    model: &Segformer,
    photos: &nrw_colmap::names::PhotoDir,
    name: &str,
) -> Result<Option<String>> {
    let path = photos
        .photo(name)
        .map_err(|p| PipelineError::input(photos.dir(), p))?;
    let photo = match nrw_dataset::codec::load_photo(&path) {
        Ok(p) => p,
        Err(nrw_dataset::DatasetError::Unreadable { path, problem }) if !cfg.strict => {
            return Ok(Some(format!("{}: {problem}", path)));
        }
        Err(e) => return Err(e.into()),
    };
    let labels = nrw_segment::segment(
        model,
        &photo,
        cfg.mode,
        &path.display().to_string(),
        Parallelism::None,
    )?;
    let out = nrw_dataset::semantics::label_path(&cfg.out, name)?;
    if let Some(dir) = out.parent() {
        std::fs::create_dir_all(dir).map_err(|e| PipelineError::io(dir, e))?;
    }
    let png =
        nrw_dataset::codec::encode_gray(name, labels.width(), labels.height(), labels.as_raw())?;
    nrw_dataset::atomic::write_bytes_atomic(&out, &png)?;
    Ok(None)
}
