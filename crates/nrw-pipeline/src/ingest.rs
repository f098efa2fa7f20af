//! Ingest: read and validate a scene, render every registered photo's view of the cloud,
//! apply the paper's filters, and write shards; [`crate::finalize`] then writes the scene
//! tables and the manifest.
//!
//! Work goes in groups of `rows_per_shard` images in id order; each group becomes one shard,
//! written atomically, then recorded in `.units/ingest/group-NNNNN.json`. A rerun (or unit)
//! skips groups whose record matches its inputs and parameters, so an interrupted run resumes,
//! and the result is byte-identical on any thread count and any number of units.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use image::RgbImage;
use nrw_colmap::{read_ply, Format, Reconstruction, UndistortOptions};
use nrw_dataset::codec::{
    encode_color_render, encode_normals, encode_rgb, load_photo, resize_photo,
};
use nrw_dataset::units::{self, GroupImage, GroupRecord, UnitRecord};
use nrw_dataset::{FileEntry, ImageOutcome, SceneSource, Store, ViewRow};
use nrw_render::{render, render_size, Filters, RenderCloud, Verdict, View};
use rayon::prelude::*;

use crate::error::{PipelineError, Result};
use crate::{Progress, Unit};

/// Largest splat radius accepted: wider splats smear a render into a few blobs, and each
/// point would touch thousands of pixels.
pub const MAX_RADIUS: f32 = 32.0;

/// Ingest's settings; [`IngestConfig::new`] fills in the paper's.
#[derive(Debug, Clone)]
pub struct IngestConfig {
    /// Scene folder (COLMAP layout) or a model folder itself.
    pub scene: PathBuf,
    /// Dataset folder to write.
    pub out: PathBuf,
    /// Photo folder [default: images/ next to the model].
    pub images: Option<PathBuf>,
    /// Model encoding to read [default: bin when present].
    pub format: Option<Format>,
    /// Point cloud [default: dense/fused.ply, else the sparse points].
    pub points: Option<PathBuf>,
    /// Folder of per-photo ADE20K label maps.
    pub semantics: Option<PathBuf>,
    /// Segment each kept photo with this model instead of reading label maps.
    pub segment: Option<InlineSegment>,
    /// Store every view as COLMAP's `image_undistorter` would: the PINHOLE camera it computes
    /// and the photo resampled to it (`ingest --undistort`).
    pub undistort: Option<UndistortOptions>,
    /// Statistical outlier removal before rendering: (k neighbours, σ) (`ingest --denoise`).
    pub denoise: Option<(usize, f64)>,
    /// Normals by PCA of k neighbours for a cloud without them (`ingest --estimate-normals`).
    pub estimate_normals: Option<usize>,
    /// Shorter side of a render in pixels (the paper: 600).
    pub min_dim: u32,
    /// Splat radius in render pixels (the paper: 1).
    pub radius: f32,
    /// The paper's filters: 85% empty, 450 px.
    pub filters: Filters,
    /// Images per shard (the unit of resumption and of work units).
    pub rows_per_shard: usize,
    /// Make an unreadable photo or label map an error instead of an `unreadable` verdict.
    pub strict: bool,
    /// Read a photo that is a symbolic link out of the images folder (refused by default: a
    /// model's names cannot make ingest read files the user did not put there).
    pub follow_outside_links: bool,
    /// Stop after this many groups, as an interruption would (resume tests).
    pub stop_after_groups: Option<usize>,
    /// Sleep this long after each group (so tests can kill a unit mid-way).
    pub pause_after_group: Option<std::time::Duration>,
}

impl IngestConfig {
    /// The paper's settings for a scene and a dataset folder.
    pub fn new(scene: impl Into<PathBuf>, out: impl Into<PathBuf>) -> IngestConfig {
        IngestConfig {
            scene: scene.into(),
            out: out.into(),
            images: None,
            format: None,
            points: None,
            semantics: None,
            segment: None,
            undistort: None,
            denoise: None,
            estimate_normals: None,
            min_dim: 600,
            radius: 1.0,
            filters: Filters::default(),
            rows_per_shard: 64,
            strict: false,
            follow_outside_links: false,
            stop_after_groups: None,
            pause_after_group: None,
        }
    }
}

/// `ingest --segment-weights`: the model and mode that label each kept photo.
#[derive(Debug, Clone)]
pub struct InlineSegment {
    /// The SegFormer folder (config.json + model.safetensors).
    pub weights: PathBuf,
    pub mode: nrw_segment::Mode,
}

/// What a unit of ingest did.
#[derive(Debug, Clone, serde::Serialize)]
pub struct UnitSummary {
    pub dataset: String,
    pub unit: String,
    /// Groups (shards) this unit owns, of all groups.
    pub groups_owned: usize,
    pub groups_total: usize,
    /// Groups found done from an earlier (interrupted) run.
    pub resumed_groups: usize,
    pub views: usize,
    pub point_source: String,
    pub points: usize,
    pub warnings: Vec<String>,
    pub seconds: f64,
}

/// Everything a unit derives from the inputs before rendering (every unit derives the same).
struct Prepared {
    rec: Reconstruction,
    photos_dir: PathBuf,
    photos: BTreeMap<u32, (u32, u32)>,
    /// Photos whose header cannot be read, with the reason (their views are `unreadable`).
    unreadable: BTreeMap<u32, String>,
    cloud: RenderCloud,
    source: String,
    record: UnitRecord,
    /// The model of `--segment-weights`, loaded once, and its mode.
    segmenter: Option<(nrw_segment::Segformer, nrw_segment::Mode)>,
    /// With `--undistort`: the photos' own (distorted) cameras; `rec` then holds the
    /// undistorted PINHOLE ones.
    distorted: Option<BTreeMap<u32, nrw_colmap::Camera>>,
}

fn check_config(cfg: &IngestConfig) -> Result<()> {
    if cfg.rows_per_shard == 0 {
        return Err(PipelineError::config(
            "--rows-per-shard",
            "must be at least 1",
        ));
    }
    if !(0.0..=MAX_RADIUS).contains(&cfg.radius) {
        return Err(PipelineError::config(
            "--radius",
            format!(
                "{} is outside 0..={MAX_RADIUS} render pixels (the paper uses 1)",
                cfg.radius
            ),
        ));
    }
    if !(0.0..=1.0).contains(&cfg.filters.max_empty_ratio) {
        return Err(PipelineError::config(
            "--max-empty",
            format!(
                "{} is not a fraction in 0..=1 (the paper drops views above 0.85)",
                cfg.filters.max_empty_ratio
            ),
        ));
    }
    if cfg.estimate_normals.is_some_and(|k| k < 3) {
        return Err(PipelineError::config(
            "--estimate-normals",
            "K needs K ≥ 3 neighbours (a plane needs three points)",
        ));
    }
    if let Some(d) = cfg.semantics.as_ref().filter(|d| !d.is_dir()) {
        return Err(PipelineError::input(d, "--semantics is not a folder"));
    }
    if cfg.semantics.is_some() && cfg.undistort.is_some() {
        return Err(PipelineError::config(
            "--undistort",
            "cannot be combined with --semantics yet (label maps of the distorted photos \
             would need resampling too); segment the undistorted photos with \
             --segment-weights instead",
        ));
    }
    if cfg.semantics.is_some() && cfg.segment.is_some() {
        return Err(PipelineError::config(
            "--segment-weights",
            "and --semantics both give label maps: use one",
        ));
    }
    Ok(())
}

/// Find and read the model of a scene folder (or a model folder itself).
pub fn load_model(scene: &Path, format: Option<Format>) -> Result<(PathBuf, Reconstruction)> {
    let dir = nrw_colmap::find_model_dir(scene)?;
    let rec = nrw_colmap::read_model(&dir, format)?;
    Ok((dir, rec))
}

/// The model with every camera replaced by the PINHOLE camera COLMAP's `image_undistorter`
/// gives it, and the original cameras; ingest and finalize both derive it this way.
pub fn undistort_model(
    rec: &mut Reconstruction,
    options: &UndistortOptions,
    model_dir: &Path,
) -> Result<BTreeMap<u32, nrw_colmap::Camera>> {
    let distorted = rec.cameras.clone();
    for cam in rec.cameras.values_mut() {
        *cam = nrw_colmap::undistort_camera(cam, options)
            .map_err(|e| PipelineError::input(model_dir, e.to_string()))?;
    }
    Ok(distorted)
}

/// The manifest's record of `--undistort` (absent without it).
pub fn undistort_parameters(o: &UndistortOptions) -> serde_json::Value {
    serde_json::json!({
        "blank_pixels": o.blank_pixels,
        "min_scale": o.min_scale,
        "max_scale": o.max_scale,
        "max_image_size": o.max_image_size,
    })
}

/// The options recorded by [`undistort_parameters`], read back (finalize).
pub fn undistort_from_parameters(v: &serde_json::Value) -> Option<UndistortOptions> {
    Some(UndistortOptions {
        blank_pixels: v.get("blank_pixels")?.as_f64()?,
        min_scale: v.get("min_scale")?.as_f64()?,
        max_scale: v.get("max_scale")?.as_f64()?,
        max_image_size: v.get("max_image_size")?.as_u64(),
    })
}

/// The model a dataset was ingested from (its manifest's or unit record's `scene`), read
/// again in the encoding ingest read, with the first of its files whose SHA-256 is not
/// among `inputs` (changed since ingest), if any.
pub fn reread_model(
    scene: &SceneSource,
    inputs: &[FileEntry],
) -> Result<(Reconstruction, Option<PathBuf>)> {
    let format = match scene.encoding.as_str() {
        "txt" => Some(Format::Text),
        "bin" => Some(Format::Binary),
        _ => None,
    };
    let rec = nrw_colmap::read_model(Path::new(&scene.model_dir), format)?;
    for f in &rec.files {
        let (_, sha) = nrw_dataset::manifest::sha256_file(f)?;
        let path = f.display().to_string();
        if !inputs.iter().any(|i| i.path == path && i.sha256 == sha) {
            let changed = f.clone();
            return Ok((rec, Some(changed)));
        }
    }
    Ok((rec, None))
}

/// `bin`/`txt` and `colmap3`/`colmap4`, as reports and manifests spell them.
pub fn describe(rec: &Reconstruction) -> (&'static str, &'static str) {
    let enc = rec.format.map_or("?", |f| f.ext());
    let layout = if rec.is_colmap4() {
        "colmap4"
    } else {
        "colmap3"
    };
    (enc, layout)
}

/// The photo folder: given, or `images/` next to the model as COLMAP lays scenes out.
pub fn images_dir(images: Option<&Path>, scene: &Path, model_dir: &Path) -> Result<PathBuf> {
    if let Some(d) = images {
        if !d.is_dir() {
            return Err(PipelineError::input(d, "--images is not a folder"));
        }
        return Ok(d.to_path_buf());
    }
    let mut tried = vec![scene.join("images")];
    for up in model_dir.ancestors().skip(1).take(2) {
        tried.push(up.join("images"));
    }
    tried.iter().find(|d| d.is_dir()).cloned().ok_or_else(|| {
        PipelineError::input(
            scene,
            format!(
                "no photo folder found (tried {}); pass --images DIR",
                tried
                    .iter()
                    .map(|d| d.display().to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        )
    })
}

/// One photo's size from its header (no pixel decoded), or why it has none.
fn header_size(path: &Path) -> std::result::Result<(u32, u32), String> {
    use std::io::Read;
    let mut head = Vec::with_capacity(16);
    std::fs::File::open(path)
        .and_then(|f| f.take(16).read_to_end(&mut head))
        .map_err(|e| e.to_string())?;
    nrw_dataset::codec::photo_format(&head)?;
    image::ImageReader::open(path)
        .and_then(|r| r.with_guessed_format())
        .map_err(|e| e.to_string())?
        .into_dimensions()
        .map_err(|e| format!("cannot read the photo's size: {}", e.to_string().trim()))
}

/// The photo of `img` inside `dir`, or an error naming the image: the one place a model's
/// image name becomes a path (names are checked when the model is read; links out of the
/// folder are refused here unless `follow_outside_links`).
fn photo_path(dir: &Path, img: &nrw_colmap::Image, follow_outside_links: bool) -> Result<PathBuf> {
    nrw_colmap::names::photo_path(dir, &img.name, follow_outside_links)
        .map_err(|p| PipelineError::input(dir, format!("image {}: field `name`: {p}", img.id)))
}

/// Registered photos' sizes from their headers, and those whose header cannot be read.
struct PhotoSizes {
    sizes: BTreeMap<u32, (u32, u32)>,
    unreadable: BTreeMap<u32, String>,
}

/// Photo sizes from file headers, with warnings for size mismatches; an unreadable header
/// is an error only when `strict`.
fn photo_sizes(
    rec: &Reconstruction,
    dir: &Path,
    cfg: &IngestConfig,
    warnings: &mut Vec<String>,
) -> Result<PhotoSizes> {
    let strict = cfg.strict;
    let mut photos = BTreeMap::new();
    let mut unreadable = BTreeMap::new();
    let mut missing = Vec::new();
    for img in rec.images.values() {
        let path = photo_path(dir, img, cfg.follow_outside_links)?;
        if !path.is_file() {
            missing.push(img.name.clone());
            continue;
        }
        let (w, h) = match header_size(&path) {
            Ok(size) => size,
            Err(problem) if strict => return Err(unreadable_error(&path, problem)),
            Err(problem) => {
                unreadable.insert(img.id, problem);
                continue;
            }
        };
        let cam = &rec.cameras[&img.camera_id];
        if (w as u64, h as u64) != (cam.width, cam.height) {
            // Same aspect ratio (to a pixel): the photo is rescaled to the render size like
            // any other. Otherwise the camera does not describe this photo.
            let aspect_ok =
                ((w as f64 / h as f64) * cam.height as f64 - cam.width as f64).abs() <= 1.0;
            let sizes = format!(
                "photo is {w}x{h} but camera {} is {}x{}",
                cam.id, cam.width, cam.height
            );
            if !aspect_ok {
                return Err(PipelineError::input(
                    &path,
                    format!(
                        "{sizes} (another aspect ratio): the model does not describe this photo"
                    ),
                ));
            }
            warnings.push(format!(
                "{}: {sizes}; same aspect ratio, rescaled",
                path.display()
            ));
        }
        photos.insert(img.id, (w, h));
    }
    if !missing.is_empty() {
        let shown: Vec<_> = missing.iter().take(5).cloned().collect();
        return Err(PipelineError::input(
            dir,
            format!(
                "{} of {} registered photos are missing ({}{})",
                missing.len(),
                rec.images.len(),
                shown.join(", "),
                if missing.len() > 5 { ", …" } else { "" }
            ),
        ));
    }
    Ok(PhotoSizes {
        sizes: photos,
        unreadable,
    })
}

fn unreadable_error(path: &Path, problem: String) -> PipelineError {
    nrw_dataset::DatasetError::Unreadable {
        path: path.to_path_buf(),
        problem,
    }
    .into()
}

/// A cloud as read, before clean-up: f64 positions, its channels, and per point where it
/// is seen from (the mean centre of the cameras that observe a sparse point; the scene's
/// mean camera centre for a dense cloud, which has no tracks).
struct RawCloud {
    positions: Vec<glam::DVec3>,
    colors: Option<Vec<[u8; 3]>>,
    normals: Option<Vec<[f32; 3]>>,
    seen_from: Vec<glam::DVec3>,
}

/// Which cloud to render, what it is called, and the file it came from (if any).
fn point_source(
    cfg: &IngestConfig,
    model_dir: &Path,
    rec: &Reconstruction,
) -> Result<(RawCloud, String, Option<PathBuf>)> {
    let candidate = cfg.points.clone().or_else(|| {
        std::iter::once(cfg.scene.join("dense/fused.ply"))
            .chain(
                model_dir
                    .ancestors()
                    .skip(1)
                    .take(2)
                    .map(|d| d.join("dense/fused.ply")),
            )
            .find(|p| p.is_file())
    });
    let centres: BTreeMap<u32, glam::DVec3> = rec
        .images
        .iter()
        .map(|(id, i)| (*id, i.cam_from_world.centre()))
        .collect();
    let mean_centre = centres.values().copied().sum::<glam::DVec3>() / centres.len().max(1) as f64;
    match candidate {
        Some(p) => {
            let cloud = read_ply(&p)?;
            let raw = RawCloud {
                seen_from: vec![mean_centre; cloud.positions.len()],
                positions: cloud.positions,
                colors: cloud.colors,
                normals: cloud.normals,
            };
            Ok((raw, "ply".into(), Some(p)))
        }
        None if !rec.points.is_empty() => {
            let raw = RawCloud {
                positions: rec.points.values().map(|p| p.xyz).collect(),
                colors: Some(rec.points.values().map(|p| p.rgb).collect()),
                normals: None,
                seen_from: rec
                    .points
                    .values()
                    .map(|p| {
                        let n = p.track.len().max(1) as f64;
                        let sum: glam::DVec3 =
                            p.track.iter().filter_map(|t| centres.get(&t.image_id)).sum();
                        if p.track.is_empty() { mean_centre } else { sum / n }
                    })
                    .collect(),
            };
            Ok((raw, "sparse".into(), None))
        }
        None => Err(PipelineError::input(
            model_dir,
            "nothing to render: no dense/fused.ply, no --points FILE, and the model has no 3D points",
        )),
    }
}

/// Keep the elements whose flag is set (flags and elements in the same order).
fn keep_where<T>(v: &mut Vec<T>, keep: &[bool]) {
    let mut flags = keep.iter();
    v.retain(|_| *flags.next().expect("one flag per element"));
}

/// The cloud to render: outliers removed (`--denoise`), normals estimated where it has none
/// (`--estimate-normals`), re-centred on `origin`. Returns what clean-up did, for the
/// manifest (absent keys: not asked for).
fn render_cloud(
    cfg: &IngestConfig,
    raw: RawCloud,
    origin: glam::DVec3,
    warnings: &mut Vec<String>,
) -> (RenderCloud, serde_json::Map<String, serde_json::Value>) {
    let mut report = serde_json::Map::new();
    let RawCloud {
        mut positions,
        mut colors,
        mut normals,
        mut seen_from,
    } = raw;
    if let Some((k, sigma)) = cfg.denoise {
        let (keep, r) = nrw_render::clean::statistical_outliers(&positions, origin, k, sigma);
        keep_where(&mut positions, &keep);
        keep_where(&mut seen_from, &keep);
        if let Some(c) = colors.as_mut() {
            keep_where(c, &keep);
        }
        if let Some(n) = normals.as_mut() {
            keep_where(n, &keep);
        }
        report.insert("denoise".into(), serde_json::to_value(&r).expect("json"));
    }
    if let Some(k) = cfg.estimate_normals {
        if normals.is_some() {
            warnings.push(format!(
                "--estimate-normals {k}: the cloud has normals of its own; they are used"
            ));
        } else {
            let n = nrw_render::clean::estimate_normals(&positions, origin, k, &|i| seen_from[i]);
            normals = Some(n);
            report.insert("estimated_normals_k".into(), k.into());
        }
    }
    let cloud = RenderCloud::new(origin, &positions, colors.as_deref(), normals.as_deref());
    (cloud, report)
}

/// Inputs with their hashes, sorted by path.
fn hashed_inputs(files: impl Iterator<Item = PathBuf>) -> Result<Vec<FileEntry>> {
    let mut inputs = files
        .map(|p| {
            let (bytes, sha256) = nrw_dataset::manifest::sha256_file(&p)?;
            Ok(FileEntry {
                path: p.display().to_string(),
                bytes,
                sha256,
                rows: None,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    inputs.sort_by(|a, b| a.path.cmp(&b.path));
    Ok(inputs)
}

/// SHA-256 (hex) of the inputs and parameters: what makes two runs' outputs interchangeable.
pub fn fingerprint(
    inputs: &[FileEntry],
    parameters: &serde_json::Map<String, serde_json::Value>,
) -> String {
    let mut text = serde_json::to_string(inputs).expect("json");
    text.push_str(&serde_json::to_string(parameters).expect("json"));
    crate::sha256_hex(text.as_bytes())
}

fn prepare(cfg: &IngestConfig, unit: Unit) -> Result<Prepared> {
    check_config(cfg)?;
    let (model_dir, mut rec) = load_model(&cfg.scene, cfg.format)?;
    let photos_dir = images_dir(cfg.images.as_deref(), &cfg.scene, &model_dir)?;
    let mut warnings: Vec<String> = rec.warnings.iter().map(|w| w.to_string()).collect();
    let photos = photo_sizes(&rec, &photos_dir, cfg, &mut warnings)?;
    let distorted = match &cfg.undistort {
        Some(o) => Some(undistort_model(&mut rec, o, &model_dir)?),
        None => None,
    };
    let (raw, source, source_path) = point_source(cfg, &model_dir, &rec)?;
    let (cloud, cleaned) = render_cloud(cfg, raw, rec.scene_origin(), &mut warnings);
    let inputs = hashed_inputs(rec.files.iter().cloned().chain(source_path))?;
    let (enc, layout) = describe(&rec);
    let mut parameters = serde_json::Map::new();
    parameters.insert("format".into(), enc.into());
    parameters.insert("point_source".into(), source.clone().into());
    parameters.insert("points".into(), cloud.len().into());
    parameters.insert("min_dim".into(), cfg.min_dim.into());
    parameters.insert("radius".into(), (cfg.radius as f64).into());
    parameters.insert("max_empty".into(), cfg.filters.max_empty_ratio.into());
    parameters.insert("min_photo_side".into(), cfg.filters.min_photo_side.into());
    parameters.insert("rows_per_shard".into(), cfg.rows_per_shard.into());
    if let Some(d) = &cfg.semantics {
        parameters.insert("semantics".into(), d.display().to_string().into());
    }
    if let Some(o) = &cfg.undistort {
        parameters.insert("undistort".into(), undistort_parameters(o));
    }
    parameters.extend(cleaned);
    let segmenter = match &cfg.segment {
        Some(s) => {
            let model = crate::segment::load_model(&s.weights)?;
            parameters.insert("segment_model_sha256".into(), model.sha256.clone().into());
            parameters.insert("segment_mode".into(), s.mode.to_string().into());
            Some((model, s.mode))
        }
        None => None,
    };
    let record = UnitRecord {
        stage: units::INGEST.into(),
        index: unit.index,
        count: unit.count,
        fingerprint: fingerprint(&inputs, &parameters),
        parameters,
        inputs,
        scene: Some(SceneSource {
            scene_dir: cfg.scene.display().to_string(),
            model_dir: model_dir.display().to_string(),
            images_dir: Some(photos_dir.display().to_string()),
            encoding: enc.into(),
            layout: layout.into(),
        }),
        warnings,
        groups: rec.images.len().div_ceil(cfg.rows_per_shard),
        seconds: 0.0,
    };
    Ok(Prepared {
        rec,
        photos_dir,
        photos: photos.sizes,
        unreadable: photos.unreadable,
        cloud,
        source,
        record,
        segmenter,
        distorted,
    })
}

/// A group's record if it is done with these inputs and parameters and its shard is intact.
fn done_group(out: &Store, g: usize, fingerprint: &str) -> Option<GroupRecord> {
    let r: GroupRecord =
        units::read_record(out, &units::group_record_path(units::INGEST, g)).ok()??;
    let intact = r.fingerprint == fingerprint
        && r.shard
            .as_ref()
            .is_none_or(|e| FileEntry::of(out, &e.path).is_ok_and(|f| f.sha256 == e.sha256));
    intact.then_some(r)
}

fn outcome(verdict: &Verdict, empty: Option<f64>, size: Option<(u32, u32)>) -> ImageOutcome {
    ImageOutcome {
        verdict: verdict.name().into(),
        verdict_value: verdict.value(),
        empty_ratio: empty,
        render_size: size,
        shard: None,
        depth_range: None,
        detail: None,
    }
}

/// The outcome of a view whose photo or label map cannot be decoded: the verdict's value is
/// the file's size in bytes (0 for an empty file), the detail the decoder's message.
fn unreadable(path: &Path, problem: String) -> ImageOutcome {
    ImageOutcome {
        verdict: nrw_dataset::VERDICT_UNREADABLE.into(),
        verdict_value: std::fs::metadata(path).map_or(0.0, |m| m.len() as f64),
        empty_ratio: None,
        render_size: None,
        shard: None,
        depth_range: None,
        detail: Some(problem),
    }
}

/// Smallest and largest rendered depth (0 = empty).
fn depth_range(depth: &[f32]) -> Option<(f64, f64)> {
    depth.iter().filter(|d| **d > 0.0).fold(None, |r, &d| {
        let d = d as f64;
        Some(r.map_or((d, d), |(lo, hi): (f64, f64)| (lo.min(d), hi.max(d))))
    })
}

type LabelPngs = (Option<Vec<u8>>, Option<Vec<u8>>, Option<Vec<u8>>);

/// The view's label maps (colour-coded, transient mask, class ids), when ingest has them:
/// read from the label folder, or made from the photo by the model (`--segment-weights`).
fn label_pngs(
    cfg: &IngestConfig,
    p: &Prepared,
    name: &str,
    photo_name: &str,
    photo: &RgbImage,
    w: u32,
    h: u32,
) -> Result<LabelPngs> {
    let labels = if let Some((model, mode)) = &p.segmenter {
        let what = p.photos_dir.join(photo_name).display().to_string();
        nrw_segment::segment(model, photo, *mode, &what, nrw_segment::Parallelism::None)?
    } else if let Some(dir) = &cfg.semantics {
        let path = nrw_dataset::semantics::label_path(dir, photo_name)?;
        nrw_dataset::semantics::load_labels(&path, photo.width(), photo.height())?
    } else {
        return Ok((None, None, None));
    };
    let ids = nrw_dataset::semantics::resize_labels(&labels, w, h);
    let (rgb, mask) = nrw_dataset::semantics::colorize(&ids);
    Ok((
        Some(nrw_dataset::codec::encode_rgb_bytes(name, w, h, &rgb)?),
        Some(nrw_dataset::codec::encode_gray(name, w, h, &mask)?),
        Some(nrw_dataset::codec::encode_gray(name, w, h, ids.as_raw())?),
    ))
}

/// The photo resampled from its own camera `from` to the undistorted PINHOLE camera `to`
/// (a photo stored at another size than its camera's, same aspect ratio, is brought to the
/// camera's size first).
fn undistorted_photo(
    photo: &RgbImage,
    from: &nrw_colmap::Camera,
    to: &nrw_colmap::Camera,
) -> RgbImage {
    let photo = resize_photo(photo, from.width as u32, from.height as u32);
    let src = nrw_render::Rgb8 {
        width: photo.width(),
        height: photo.height(),
        data: photo.into_raw(),
    };
    let out = nrw_render::undistort_photo(&src, from, to);
    RgbImage::from_raw(out.width, out.height, out.data).expect("width × height × 3 bytes")
}

/// Render one image and, if kept, encode its row.
fn process(
    cfg: &IngestConfig,
    p: &Prepared,
    image_id: u32,
) -> Result<(ImageOutcome, Option<ViewRow>)> {
    let img = &p.rec.images[&image_id];
    let cam = &p.rec.cameras[&img.camera_id];
    // Every image's path was checked (name, links) when its size was read in `photo_sizes`.
    let photo_path = p.photos_dir.join(&img.name);
    if let Some(problem) = p.unreadable.get(&image_id) {
        return Ok((unreadable(&photo_path, problem.clone()), None));
    }
    let size = p.photos[&image_id];
    if let Some(v) = cfg.filters.check_size(size.0 as u64, size.1 as u64) {
        return Ok((outcome(&v, None, None), None));
    }
    let (w, h) = render_size(cam.width, cam.height, cfg.min_dim);
    let view = View::new(img, cam, p.cloud.origin, w, h, cfg.radius);
    let buf = render(&view, &p.cloud);
    let empty = buf.empty_ratio();
    let verdict = cfg.filters.check_render(empty);
    let o = outcome(&verdict, Some(empty), Some((w, h)));
    if !matches!(verdict, Verdict::Kept { .. }) {
        return Ok((o, None));
    }
    // Kept: record its depth range (export's depth scale and QA's depth plots read it).
    let o = ImageOutcome {
        depth_range: depth_range(&buf.depth),
        ..o
    };
    let name = format!("image {}", img.id);
    let decoded = load_photo(&photo_path)
        .map_err(PipelineError::from)
        .map(|photo| match &p.distorted {
            Some(originals) => undistorted_photo(&photo, &originals[&img.camera_id], cam),
            None => photo,
        })
        .and_then(|photo| {
            let labels = label_pngs(cfg, p, &name, &img.name, &photo, w, h)?;
            Ok((photo, labels))
        });
    let (photo, (semantics_png, transient_png, labels_png)) = match decoded {
        Ok(d) => d,
        Err(PipelineError::Dataset(nrw_dataset::DatasetError::Unreadable { path, problem }))
            if !cfg.strict =>
        {
            return Ok((unreadable(&path, problem), None));
        }
        Err(e) => return Err(e),
    };
    let photo = resize_photo(&photo, w, h);
    let row = ViewRow {
        image_id: img.id,
        name: img.name.clone(),
        camera_id: cam.id,
        model: cam.model.name().into(),
        width: w,
        height: h,
        scale_x: view.scale.x,
        scale_y: view.scale.y,
        params: view.camera.params.clone(),
        qvec: img.cam_from_world.qvec(),
        tvec: img.cam_from_world.translation.to_array(),
        empty_ratio: empty,
        photo_png: encode_rgb(&name, &photo)?,
        color_png: encode_color_render(&name, w, h, buf.color.as_deref(), &buf.depth)?,
        depth_exr: nrw_dataset::depth::encode_exr(&nrw_dataset::depth::DepthMap {
            width: w as usize,
            height: h as usize,
            data: buf.depth.clone(),
        })?,
        normal_png: match &buf.normal {
            Some(n) => Some(encode_normals(&name, w, h, n, &buf.depth)?),
            None => None,
        },
        semantics_png,
        transient_png,
        labels_png,
    };
    Ok((o, Some(row)))
}

/// Render one group, write its shard, then its record.
fn run_group(
    cfg: &IngestConfig,
    store: &Store,
    p: &Prepared,
    g: usize,
    ids: &[u32],
    progress: &dyn Progress,
) -> Result<usize> {
    let results: Vec<(ImageOutcome, Option<ViewRow>)> = ids
        .par_iter()
        .map(|id| {
            let r = process(cfg, p, *id);
            progress.inc(1);
            r
        })
        .collect::<Result<_>>()?;
    let rows: Vec<ViewRow> = results.iter().filter_map(|(_, r)| r.clone()).collect();
    let rel = nrw_dataset::views::shard_path(g);
    let shard = if rows.is_empty() {
        None
    } else {
        Some(nrw_dataset::write_shard(store, &rel, &rows)?)
    };
    let images = ids
        .iter()
        .zip(results)
        .map(|(id, (mut o, row))| {
            if row.is_some() {
                o.shard = Some(rel.clone());
            }
            GroupImage {
                image_id: *id,
                photo_size: p.photos.get(id).copied(),
                outcome: o,
            }
        })
        .collect();
    let record = GroupRecord {
        fingerprint: p.record.fingerprint.clone(),
        shard,
        images,
    };
    units::write_record(store, &units::group_record_path(units::INGEST, g), &record)?;
    Ok(rows.len())
}

/// Run one unit of ingest: render the groups `unit` owns (skipping those already done) and
/// record the unit as done. Writes only this unit's shards and records; deletes nothing.
pub fn ingest_unit(cfg: &IngestConfig, unit: Unit, progress: &dyn Progress) -> Result<UnitSummary> {
    let t0 = Instant::now();
    let mut p = prepare(cfg, unit)?;
    let store = &Store::open_path(&cfg.out)?;
    let ids: Vec<u32> = p.rec.images.keys().copied().collect();
    let groups: Vec<(usize, &[u32])> = ids
        .chunks(cfg.rows_per_shard)
        .enumerate()
        .filter(|(g, _)| unit.owns(*g))
        .collect();
    let todo: Vec<&(usize, &[u32])> = groups
        .iter()
        .filter(|(g, _)| done_group(store, *g, &p.record.fingerprint).is_none())
        .collect();
    let resumed = groups.len() - todo.len();
    progress.start(
        "rendering",
        todo.iter().map(|(_, ids)| ids.len() as u64).sum(),
        "views",
    );
    let mut views = 0;
    for (written, (g, group)) in todo.iter().enumerate() {
        views += run_group(cfg, store, &p, *g, group, progress)?;
        if let Some(d) = cfg.pause_after_group {
            std::thread::sleep(d);
        }
        if cfg.stop_after_groups.is_some_and(|n| written + 1 >= n) && written + 1 < todo.len() {
            progress.finish();
            return Err(PipelineError::Interrupted(format!(
                "stopped after {} groups as asked; run the same command again to resume",
                written + 1
            )));
        }
    }
    progress.finish();
    p.record.seconds = t0.elapsed().as_secs_f64();
    let rel = units::unit_record_path(units::INGEST, unit.index, unit.count);
    units::write_record(store, &rel, &p.record)?;
    Ok(UnitSummary {
        dataset: store.root().display().to_string(),
        unit: unit.to_string(),
        groups_owned: groups.len(),
        groups_total: p.record.groups,
        resumed_groups: resumed,
        views,
        point_source: p.source,
        points: p.cloud.len(),
        warnings: p.record.warnings,
        seconds: p.record.seconds,
    })
}

/// What a whole ingest produced (printed with `--json`).
#[derive(Debug, Clone, serde::Serialize)]
pub struct IngestSummary {
    pub dataset: String,
    pub registered: usize,
    pub rendered: usize,
    pub kept: usize,
    pub too_small: usize,
    pub too_sparse: usize,
    /// Photos (or label maps) that could not be decoded whole, each named in `warnings`.
    pub unreadable: usize,
    pub shards: usize,
    pub point_source: String,
    pub points: usize,
    pub resumed_groups: usize,
    /// Empty ratio of the least empty render (what the filter would have to allow).
    pub least_empty: Option<f64>,
    /// The filters the verdicts came from: renders emptier than this fraction are too sparse,
    pub max_empty: f64,
    /// and photos with a shorter side under this many pixels too small.
    pub min_photo_side: u32,
    pub warnings: Vec<String>,
    pub seconds: f64,
}

/// Ingest the whole scene in this process: one unit of one, then finalize. Unit records of
/// earlier unfinished unit runs are cleared first (this run owns the dataset); their group
/// records are reused when they match.
pub fn ingest(cfg: &IngestConfig, progress: &dyn Progress) -> Result<IngestSummary> {
    let t0 = Instant::now();
    check_config(cfg)?;
    let store = &Store::open_path(&cfg.out)?;
    units::remove_unit_records(store, units::INGEST, None)?;
    let u = ingest_unit(cfg, Unit::WHOLE, progress)?;
    let f = crate::finalize::finalize_ingest(store)?;
    Ok(IngestSummary {
        dataset: u.dataset,
        registered: f.registered,
        rendered: f.kept + f.too_sparse,
        kept: f.kept,
        too_small: f.too_small,
        too_sparse: f.too_sparse,
        unreadable: f.unreadable,
        shards: f.shards,
        point_source: u.point_source,
        points: u.points,
        resumed_groups: u.resumed_groups,
        least_empty: f.least_empty,
        max_empty: cfg.filters.max_empty_ratio,
        min_photo_side: cfg.filters.min_photo_side,
        warnings: f.warnings,
        seconds: t0.elapsed().as_secs_f64(),
    })
}
