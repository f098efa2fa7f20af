//! Ingest's settings, and what a unit prepares before its groups run: what every file of
//! the stage reads, in a file of its own so they import it and not each other.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use nrw_colmap::{Format, Reconstruction};
use nrw_dataset::units::UnitRecord;
use nrw_render::RenderCloud;

use crate::error::{PipelineError, Result, Setting};
use crate::settings::ingest::IngestSettings;

/// Largest splat radius accepted: wider splats smear a render into a few blobs, and each
/// point would touch thousands of pixels.
pub const MAX_RADIUS: f32 = 32.0;

/// An ingest run: where the scene, photos and cloud are, where the dataset goes, and the
/// settings it runs with (declared once, in [`crate::settings::ingest`]).
#[derive(Debug, Clone)]
pub struct IngestConfig {
    /// Scene folder (COLMAP layout) or a model folder itself.
    pub scene: PathBuf,
    /// Dataset folder to write.
    pub out: nrw_dataset::Location,
    /// Photo folder [default: images/ next to the model].
    pub images: Option<PathBuf>,
    /// Model encoding to read [default: bin when present].
    pub format: Option<Format>,
    /// Sub-model `sparse/N` to read [default: the one with the most registered images].
    pub model: Option<u32>,
    /// Point cloud [default: dense/fused.ply, else the sparse points].
    pub points: Option<PathBuf>,
    /// CSV or JSON Lines file of each photo's licence, author and source, keyed by image
    /// name ([`nrw_dataset::photo_info`]).
    pub photo_info: Option<PathBuf>,
    /// Segment each kept photo with this model instead of reading label maps.
    pub segment: Option<InlineSegment>,
    /// Read a photo that is a symbolic link out of the images folder (refused by default: a
    /// model's names cannot make ingest read files the user did not put there).
    pub follow_outside_links: bool,
    /// Stop after this many groups, as an interruption would (resume tests).
    pub stop_after_groups: Option<usize>,
    /// Sleep this long after each group (so tests can kill a unit mid-way).
    pub pause_after_group: Option<std::time::Duration>,
    /// How views are rendered, filtered and recorded (the paper's by default).
    pub settings: IngestSettings,
}

impl IngestConfig {
    /// The paper's settings for a scene and a dataset folder.
    pub fn new(scene: impl Into<PathBuf>, out: impl Into<nrw_dataset::Location>) -> IngestConfig {
        IngestConfig {
            scene: scene.into(),
            out: out.into(),
            images: None,
            format: None,
            model: None,
            points: None,
            photo_info: None,
            segment: None,
            follow_outside_links: false,
            stop_after_groups: None,
            pause_after_group: None,
            settings: IngestSettings::default(),
        }
    }
}

impl IngestSettings {
    /// Ingest of `scene` into `out` with these settings; `segment_weights` (a SegFormer given
    /// on the command line) labels the photos inline.
    pub fn config(
        &self,
        scene: &Path,
        out: &nrw_dataset::Location,
        segment_weights: Option<PathBuf>,
    ) -> Result<IngestConfig> {
        let segment = match segment_weights {
            Some(weights) => Some(InlineSegment {
                weights,
                mode: nrw_segment::Mode::new(self.segment_mode, self.segment_size).map_err(
                    |e| {
                        PipelineError::config(
                            Setting::Key("ingest.segment_size"),
                            format!("{}: {e}", self.segment_size),
                        )
                    },
                )?,
            }),
            None => None,
        };
        Ok(IngestConfig {
            segment,
            settings: self.clone(),
            ..IngestConfig::new(scene, out)
        })
    }
}

/// `ingest --segment-weights`: the model and mode that label each kept photo.
#[derive(Debug, Clone)]
pub struct InlineSegment {
    /// The SegFormer folder (config.json + model.safetensors).
    pub weights: PathBuf,
    pub mode: nrw_segment::Mode,
}

/// Everything a unit derives from the inputs before rendering (every unit derives the same).
pub(super) struct Prepared {
    pub(super) rec: Reconstruction,
    pub(super) photos_dir: PathBuf,
    pub(super) photos: BTreeMap<u32, (u32, u32)>,
    /// Photos whose header cannot be read, with the reason (their views are `unreadable`).
    pub(super) unreadable: BTreeMap<u32, String>,
    pub(super) cloud: RenderCloud,
    pub(super) source: String,
    pub(super) record: UnitRecord,
    /// The model of `--segment-weights`, loaded once, and its mode.
    pub(super) segmenter: Option<(nrw_segment::Segformer, nrw_segment::Mode)>,
    /// With `--undistort`: the photos' own (distorted) cameras; `rec` then holds the
    /// undistorted PINHOLE ones.
    pub(super) distorted: Option<BTreeMap<u32, nrw_colmap::Camera>>,
}
