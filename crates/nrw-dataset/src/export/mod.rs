//! Exports of a dataset as files other tools read: the paper's published code (`official`
//! PNG folders and `tfrecord`, see `official`), or one folder per photo (`files`). An export
//! is built in a hidden folder beside its destination and moved into place whole, so a reader
//! never sees a half-written export or files left from an earlier one.

pub mod nerfstudio;
pub mod nerfw;
pub mod official;
pub mod pickle;
pub mod tfrecord;

use std::path::{Path, PathBuf};

use image::{GrayImage, RgbImage, RgbaImage};
use rayon::prelude::*;
use serde::Serialize;

use crate::error::{DatasetError, Result};
use crate::reader::{Dataset, View};
use official::{crop_start, official_seg_rgb, DepthMapping, DepthScale};

/// The JSON an export writes beside its files: what it holds and how to read it back. Its
/// presence marks a folder as an export this tool may replace.
pub const EXPORT_JSON: &str = "export.json";

/// Which files an export writes. One enum for the CLI (`--layout`), pipeline files
/// (`[export] layout`) and `export.json`, under the same lowercase names.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Layout {
    /// `train/` and `val/` with `NNNN_{reference,color,depth,seg_rgb}.png`, as the published
    /// code's `dataset_utils.AlignedRenderedDataset` and `pretrain_appearance` read them.
    Official,
    /// `<name>_<split>.tfrecord`: what `dataset_utils._generate_tfrecord_dataset` writes and
    /// `data._parser_rendered_dataset` parses.
    Tfrecord,
    /// `SPLIT/NAME/{photo.png, color.png, depth.exr, normal.png, semantics.png, labels.png,
    /// transient.png, meta.json}` for ordinary viewers.
    Files,
    /// NeRF-W's Phototourism layout (`NAME.tsv`, `dense/images`, `dense/sparse`), as nerf_pl
    /// and Ha-NeRF read it: see [`nerfw`]. Written by [`export_with_points`].
    Nerfw,
    /// nerfstudio's `transforms.json` with images, depth, masks and the sparse points: see
    /// [`nerfstudio`]. Written by [`export_with_points`].
    Nerfstudio,
}

impl Layout {
    /// Every layout, in the order help lists them.
    pub const ALL: [Layout; 5] = [
        Layout::Official,
        Layout::Tfrecord,
        Layout::Files,
        Layout::Nerfw,
        Layout::Nerfstudio,
    ];

    /// The layout's name on the command line, in pipeline files and in `export.json`.
    pub fn name(self) -> &'static str {
        match self {
            Layout::Official => "official",
            Layout::Tfrecord => "tfrecord",
            Layout::Files => "files",
            Layout::Nerfw => "nerfw",
            Layout::Nerfstudio => "nerfstudio",
        }
    }

    /// What the layout holds, in one line (the CLI's help for each value).
    pub fn summary(self) -> &'static str {
        match self {
            Layout::Official => "train/ and val/ with NNNN_reference.png, NNNN_color.png (RGBA), NNNN_depth.png (levels 0-255), NNNN_seg_rgb.png (the published colour coding), dist_NAME.pckl with official descriptors",
            Layout::Tfrecord => "NAME_train.tfrecord / NAME_val.tfrecord (or NAME-0000i-of-0000N_SPLIT.tfrecord with --shards N): the Examples the published data.py parses",
            Layout::Files => "SPLIT/NAME/{photo.png, color.png, depth.exr, normal.png, semantics.png, labels.png, transient.png, meta.json}",
            Layout::Nerfw => "NeRF-W's Phototourism layout for nerf_pl / Ha-NeRF loaders: NAME.tsv (filename, id, split, dataset), dense/images/, dense/sparse/ (one PINHOLE camera per image, the scene's points); needs a dataset ingested with --undistort (or pinhole cameras)",
            Layout::Nerfstudio => "nerfstudio's transforms.json (each frame's exact camera model, OpenGL camera-to-world poses with nerfstudio's applied_transform, depth/*.npy, masks/*.png from the transient mask, train/val/test_filenames) with images/ and sparse_pc.ply; refuses camera models nerfstudio cannot represent exactly (FOV, FULL_OPENCV, thin-prism fisheyes)",
        }
    }

    /// Whether the layout carries the scene's 3D points (written by [`export_with_points`]).
    pub fn needs_points(self) -> bool {
        matches!(self, Layout::Nerfw | Layout::Nerfstudio)
    }

    /// Whether the layout is one the paper's published code reads (official, tfrecord).
    pub fn paper(self) -> bool {
        matches!(self, Layout::Official | Layout::Tfrecord)
    }

    /// The crop when none is asked: the published 512 for the paper's layouts, none (views
    /// kept whole) for the others.
    pub fn default_crop(self) -> Option<u32> {
        self.paper().then_some(official::PUBLISHED_CROP)
    }
}

impl std::fmt::Display for Layout {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Layout {
    type Err = String;

    /// A layout by its name; the error lists the names.
    fn from_str(s: &str) -> std::result::Result<Layout, String> {
        Layout::ALL
            .into_iter()
            .find(|l| l.name() == s)
            .ok_or_else(|| {
                let names: Vec<&str> = Layout::ALL.iter().map(|l| l.name()).collect();
                format!("{s:?} is not a layout: {}", names.join(", "))
            })
    }
}

/// What to export and how.
#[derive(Debug, Clone)]
pub struct ExportConfig {
    pub layout: Layout,
    /// Destination folder: created, or replaced whole when it holds an earlier export.
    pub out: PathBuf,
    /// The dataset name the published code is run with (`--dataset_name`): TFRecord and
    /// distance-matrix file names.
    pub name: String,
    /// A centred `crop` × `crop` of every channel (the published code's 512), official and
    /// tfrecord layouts; views smaller than it are skipped and listed.
    pub crop: Option<u32>,
    /// Write semantics (official and tfrecord): a dataset without them is refused unless this
    /// is false.
    pub semantics: bool,
    pub depth: DepthMapping,
    /// TFRecord files per split (1: `<name>_<split>.tfrecord`).
    pub shards: usize,
}

impl ExportConfig {
    /// The paper's layout with the defaults the published code runs with.
    pub fn official(out: PathBuf, name: String) -> Self {
        ExportConfig {
            layout: Layout::Official,
            out,
            name,
            crop: Some(official::PUBLISHED_CROP),
            semantics: true,
            depth: DepthMapping::Linear,
            shards: 1,
        }
    }
}

/// A view an export left out, and why.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Skipped {
    pub split: String,
    pub image_id: u32,
    pub name: String,
    pub width: u32,
    pub height: u32,
    pub reason: String,
}

/// One split of an export: its views in file order.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SplitExport {
    pub split: String,
    /// Image ids in index order: view k is file k (`NNNN_*` or record k).
    pub image_ids: Vec<u32>,
    pub names: Vec<String>,
    /// Files written for the split, relative to the export folder.
    pub files: Vec<String>,
}

/// What an export wrote: also the content of `export.json`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ExportSummary {
    pub tool: String,
    pub dataset: String,
    pub layout: Layout,
    pub name: String,
    pub crop: Option<u32>,
    /// Depth levels in the official and tfrecord layouts, with the formula to recover depth.
    pub depth: Option<DepthRecord>,
    /// `official` (schemas/official_colors.csv), `ade20k` (ids and colour150), or null.
    pub semantics: Option<String>,
    pub splits: Vec<SplitExport>,
    pub skipped: Vec<Skipped>,
    /// Splits the dataset has with no view, not written (the published code's glob would fail).
    pub empty_splits: Vec<String>,
    /// `dist_<name>.pckl` when the dataset has official style descriptors.
    pub dist_pickle: Option<String>,
}

impl ExportSummary {
    /// Views written over all splits.
    pub fn views(&self) -> usize {
        self.splits.iter().map(|s| s.image_ids.len()).sum()
    }
}

/// The depth mapping as recorded in `export.json`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DepthRecord {
    #[serde(flatten)]
    pub scale: DepthScale,
    pub formula: String,
    /// What the published loaders do with a level: `level * 2/255 - 1`, so 0 (empty) → −1.
    pub loader_scaling: String,
}

/// The train views' style distance matrix (row-major, f64) for the given image ids in that
/// order, or None when the dataset has no official descriptors. Given by the caller, which
/// owns the style stage.
pub type DistMatrix<'a> = &'a (dyn Fn(&[u32]) -> Result<Option<Vec<f64>>> + Sync);

fn refuse(path: &Path, problem: impl Into<String>) -> DatasetError {
    DatasetError::Schema {
        path: path.to_path_buf(),
        problem: problem.into(),
    }
}

/// The hidden folder an export is built in, and every file claimed in it so far: no two
/// files of one export may have names equal, or equal but for letter case or Unicode
/// normalisation ([`nrw_colmap::names::fold_key`]), since on macOS and Windows the second
/// would overwrite the first. Every file an export writes is claimed here.
pub(crate) struct Staged {
    dir: PathBuf,
    /// The export's destination, named in messages (the hidden folder means nothing to a user).
    out: PathBuf,
    claimed: std::sync::Mutex<std::collections::HashMap<String, String>>,
}

impl Staged {
    /// The hidden folder itself (for files of fixed names written by other code, such as a
    /// COLMAP model).
    pub(crate) fn dir(&self) -> &Path {
        &self.dir
    }

    /// `dir/rel` through the checked join ([`join_under`]), claimed for one file.
    pub(crate) fn claim(&self, rel: &str) -> Result<PathBuf> {
        // Named by the export folder: the hidden staging folder means nothing to a user.
        let path = join_under(&self.dir, rel).map_err(|e| match e {
            DatasetError::Value { problem, .. } => name_error(&self.out, problem),
            e => e,
        })?;
        let key = nrw_colmap::names::fold_key(rel);
        let mut claimed = self.claimed.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(first) = claimed.get(&key) {
            let how = if first == rel {
                "two views would write the same file"
            } else {
                "the names differ only in letter case or Unicode normalisation, so on macOS and Windows they are one file"
            };
            return Err(name_error(
                &self.out,
                format!("{rel:?} and {first:?}: {how}; rename one photo in the model (or leave one out) and export again"),
            ));
        }
        claimed.insert(key, rel.to_string());
        Ok(path)
    }

    /// Write `bytes` to a claimed `rel`, creating its folders.
    pub(crate) fn write(&self, rel: &str, bytes: &[u8]) -> Result<()> {
        write_file(&self.claim(rel)?, bytes)
    }
}

/// An output file name refused, naming the export folder.
fn name_error(out: &Path, problem: String) -> DatasetError {
    DatasetError::Value {
        path: out.into(),
        record: "output file".into(),
        field: "name".into(),
        problem,
    }
}

/// Check the destination and make the hidden folder the export is built in.
fn stage(out: &Path) -> Result<Staged> {
    if out.is_file() {
        return Err(refuse(out, "is a file; give a folder to export into"));
    }
    if out.is_dir() {
        let mut entries = std::fs::read_dir(out).map_err(|e| DatasetError::io(out, e))?;
        if entries.next().is_some() && !out.join(EXPORT_JSON).is_file() {
            return Err(refuse(
                out,
                format!("holds files that are not an nrw-etl export (no {EXPORT_JSON}); export into an empty or new folder, or into an earlier export to replace it"),
            ));
        }
    }
    let parent = match out.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    std::fs::create_dir_all(&parent).map_err(|e| DatasetError::io(&parent, e))?;
    let base = out
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "export".into());
    // Leftovers of interrupted exports into the same folder go first.
    if let Ok(entries) = std::fs::read_dir(&parent) {
        for e in entries.flatten() {
            let n = e.file_name().to_string_lossy().into_owned();
            if n.starts_with(&format!(".{base}.export-")) {
                let _ = std::fs::remove_dir_all(e.path());
            }
        }
    }
    let staged = parent.join(format!(".{base}.export-new-{}", std::process::id()));
    std::fs::create_dir_all(&staged).map_err(|e| DatasetError::io(&staged, e))?;
    Ok(Staged {
        dir: staged,
        out: out.into(),
        claimed: Default::default(),
    })
}

/// Move the finished export into place, replacing an earlier one whole.
fn commit(staged: &Staged, out: &Path) -> Result<()> {
    let staged = staged.dir();
    let old = staged.with_file_name(
        staged
            .file_name()
            .expect("named")
            .to_string_lossy()
            .replace(".export-new-", ".export-old-"),
    );
    crate::atomic::commit_pause(out);
    if out.exists() {
        std::fs::rename(out, &old).map_err(|e| DatasetError::io(out, e))?;
    }
    std::fs::rename(staged, out).map_err(|e| DatasetError::io(out, e))?;
    if old.exists() {
        std::fs::remove_dir_all(&old).map_err(|e| DatasetError::io(&old, e))?;
    }
    Ok(())
}

/// `root/rel`, refusing a `rel` that is not a relative path of normal components
/// ([`nrw_colmap::names::check_name`]): every file an export writes is joined this way (by
/// [`Staged::claim`]), so no name from a dataset (or an export's `--name`) can put a file
/// outside the export folder.
pub fn join_under(root: &Path, rel: &str) -> Result<std::path::PathBuf> {
    nrw_colmap::names::join_checked(root, rel).map_err(|problem| name_error(root, problem))
}

fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    if let Some(d) = path.parent() {
        std::fs::create_dir_all(d).map_err(|e| DatasetError::io(d, e))?;
    }
    std::fs::write(path, bytes).map_err(|e| DatasetError::io(path, e))
}

/// Zero-padded index width for `n` files: at least 4 (the published `%04d`), more when `n`
/// needs it, so names sort in index order at any size.
pub fn index_width(n: usize) -> usize {
    n.saturating_sub(1).to_string().len().max(4)
}

/// The channels of one view as the published code reads them, cropped if asked.
struct OfficialView {
    reference: RgbImage,
    color: RgbaImage,
    depth: GrayImage,
    seg: Option<RgbImage>,
}

/// The published colour coding of a view's labels, or None with `--no-semantics`.
fn official_seg(v: &View, cfg: &ExportConfig) -> Result<Option<RgbImage>> {
    if !cfg.semantics {
        return Ok(None);
    }
    let labels = v.labels()?.ok_or_else(|| no_semantics(v))?;
    Ok(Some(official_seg_rgb(&labels)))
}

fn official_view(v: &View, cfg: &ExportConfig, scale: &DepthScale) -> Result<OfficialView> {
    let depth = v.depth()?;
    let mut out = OfficialView {
        reference: v.photo()?,
        color: v.color()?,
        depth: scale.image(v.width, v.height, &depth.data),
        seg: official_seg(v, cfg)?,
    };
    if let Some(c) = cfg.crop {
        let (x, y) = (crop_start(v.width, c), crop_start(v.height, c));
        use image::imageops::crop_imm;
        out.reference = crop_imm(&out.reference, x, y, c, c).to_image();
        out.color = crop_imm(&out.color, x, y, c, c).to_image();
        out.depth = crop_imm(&out.depth, x, y, c, c).to_image();
        out.seg = out.seg.map(|s| crop_imm(&s, x, y, c, c).to_image());
    }
    Ok(out)
}

fn no_semantics(v: &View) -> DatasetError {
    DatasetError::Value {
        path: PathBuf::from(&v.name),
        record: format!("image {}", v.image_id),
        field: "labels_png".into(),
        problem: "the dataset has no semantic labels, and the published code reads *_seg_rgb.png by default: ingest with --semantics LABELS_DIR, or export with --no-semantics and train with --use_semantic=False --deep_buffer_nc=4 (RGB and depth)".into(),
    }
}

/// Encoded files of one view, in the order they are written.
type Encoded = Vec<(String, Vec<u8>)>;

fn encode_official(
    v: &View,
    cfg: &ExportConfig,
    scale: &DepthScale,
    stem: &str,
) -> Result<Encoded> {
    use crate::codec::{encode_gray, encode_rgb, encode_rgba};
    let name = &v.name;
    let (reference, color, depth, seg) = match cfg.crop {
        // Uncropped, the stored photo and render PNGs are the files already: no decode, no
        // re-encode.
        None => (
            v.photo_png.clone(),
            v.color_png.clone(),
            scale.image(v.width, v.height, &v.depth()?.data),
            official_seg(v, cfg)?,
        ),
        Some(_) => {
            let o = official_view(v, cfg, scale)?;
            (
                encode_rgb(name, &o.reference)?,
                encode_rgba(name, &o.color)?,
                o.depth,
                o.seg,
            )
        }
    };
    let mut files = vec![
        (format!("{stem}_reference.png"), reference),
        (format!("{stem}_color.png"), color),
        (
            format!("{stem}_depth.png"),
            encode_gray(name, depth.width(), depth.height(), depth.as_raw())?,
        ),
    ];
    if let Some(s) = &seg {
        files.push((format!("{stem}_seg_rgb.png"), encode_rgb(name, s)?));
    }
    Ok(files)
}

/// The TFRecord frame of the Example `AlignedRenderedDataset` + `_to_example` make of a view: `height`, `width`,
/// `rendered` (RGBA u8), `depth` (u16, little-endian), `real` (RGB u8), `seg` (RGB u8; empty
/// with --no-semantics, which the published parser reads only with --use_semantic).
fn encode_record(v: &View, cfg: &ExportConfig, scale: &DepthScale) -> Result<Vec<u8>> {
    use tfrecord::Feature;
    let o = official_view(v, cfg, scale)?;
    let depth16: Vec<u8> = o
        .depth
        .as_raw()
        .iter()
        .flat_map(|&l| (l as u16).to_le_bytes())
        .collect();
    let empty: &[u8] = &[];
    Ok(tfrecord::encode_record(&[
        ("height", Feature::Int64(o.reference.height() as i64)),
        ("width", Feature::Int64(o.reference.width() as i64)),
        ("rendered", Feature::Bytes(o.color.as_raw())),
        ("depth", Feature::Bytes(&depth16)),
        ("real", Feature::Bytes(o.reference.as_raw())),
        (
            "seg",
            Feature::Bytes(o.seg.as_ref().map_or(empty, |s| s.as_raw().as_slice())),
        ),
    ]))
}

fn encode_files(v: &View, stem: &str) -> Result<Encoded> {
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

/// TFRecord file name of shard `i` of `n` of a split, matched by the published glob
/// `<name>*_<split>.tfrecord`.
pub fn tfrecord_name(name: &str, split: &str, i: usize, n: usize) -> String {
    if n <= 1 {
        format!("{name}_{split}.tfrecord")
    } else {
        format!("{name}-{i:05}-of-{n:05}_{split}.tfrecord")
    }
}

/// Views read, encoded in parallel and written in order this many at a time: small enough
/// that reading, encoding and writing overlap, large enough to keep every core busy.
const BATCH: usize = 8;

/// Export `ds` as `cfg` says; `dist` gives the distance matrix of the official layout's
/// train views, `tick` is called once per view done.
pub fn export(
    ds: &Dataset,
    cfg: &ExportConfig,
    dist: DistMatrix,
    tick: &(dyn Fn() + Sync),
) -> Result<ExportSummary> {
    if cfg.layout.needs_points() {
        return Err(refuse(
            &cfg.out,
            format!(
                "the {:?} layout needs the scene's 3D points: call export_with_points",
                cfg.layout
            ),
        ));
    }
    let paper = cfg.layout != Layout::Files;
    let splits: Vec<(String, usize)> = ds.splits();
    if paper && !splits.iter().any(|(s, n)| s == "train" && *n > 0) {
        return Err(refuse(
            &ds.dir,
            format!(
                "the {:?} layout needs a train split with views; run `nrw-etl split {} --val N` first (--val 0 puts every photo in train)",
                cfg.layout,
                ds.dir.display()
            ),
        ));
    }
    if cfg.crop.is_some_and(|c| c == 0) || cfg.shards == 0 {
        return Err(refuse(&cfg.out, "--crop and --shards must be at least 1"));
    }
    if !paper && cfg.crop.is_some() {
        // The files layout keeps every payload as stored; a crop would be silently ignored.
        return Err(refuse(
            &cfg.out,
            "--crop applies to the official and tfrecord layouts; the files layout keeps views whole",
        ));
    }
    let scale = if paper {
        let (near, far) = crate::scene::read_depth_range(&ds.store)?.unwrap_or((1.0, 1.0));
        Some(DepthScale {
            mapping: cfg.depth,
            near,
            far,
        })
    } else {
        None
    };
    let staged = stage(&cfg.out)?;
    let result = write_all(ds, cfg, scale.as_ref(), &splits, &staged, dist, tick);
    match result {
        Ok(summary) => {
            commit(&staged, &cfg.out)?;
            Ok(summary)
        }
        Err(e) => {
            let _ = std::fs::remove_dir_all(staged.dir());
            Err(e)
        }
    }
}

/// Export `ds` in a layout that carries the scene's 3D `points` (NeRF-W's, nerfstudio's);
/// `tick` is called once per view done.
pub fn export_with_points(
    ds: &Dataset,
    cfg: &ExportConfig,
    points: &[nerfw::ScenePoint],
    tick: &(dyn Fn() + Sync),
) -> Result<ExportSummary> {
    let splits: Vec<(String, usize)> = ds.splits();
    if !splits.iter().any(|(s, n)| s == "train" && *n > 0) {
        return Err(refuse(
            &ds.dir,
            format!(
                "the {:?} layout needs a train split with views; run `nrw-etl split {} --val N` first",
                cfg.layout,
                ds.dir.display()
            ),
        ));
    }
    let staged = stage(&cfg.out)?;
    if points.is_empty() {
        return Err(refuse(
            &cfg.out,
            "the scene has no 3D points (NeRF-W loaders take near and far bounds from them, \
             splatting trainers their initial Gaussians)",
        ));
    }
    let written = match cfg.layout {
        Layout::Nerfw => nerfw::write(ds, cfg, points, &splits, &staged, tick),
        Layout::Nerfstudio => nerfstudio::write(ds, cfg, points, &splits, &staged, tick),
        other => Err(refuse(
            &cfg.out,
            format!("the {other:?} layout carries no points: call export"),
        )),
    };
    let result = written.and_then(|written| {
        let summary = ExportSummary {
            tool: format!("nrw-etl {}", env!("CARGO_PKG_VERSION")),
            dataset: ds.dir.display().to_string(),
            layout: cfg.layout,
            name: cfg.name.clone(),
            crop: None,
            depth: None,
            semantics: None,
            empty_splits: splits
                .iter()
                .filter(|(_, n)| *n == 0)
                .map(|(s, _)| s.clone())
                .collect(),
            splits: written,
            skipped: Vec::new(),
            dist_pickle: None,
        };
        staged.write(
            EXPORT_JSON,
            &serde_json::to_vec_pretty(&summary).expect("json"),
        )?;
        Ok(summary)
    });
    match result {
        Ok(summary) => {
            commit(&staged, &cfg.out)?;
            Ok(summary)
        }
        Err(e) => {
            let _ = std::fs::remove_dir_all(staged.dir());
            Err(e)
        }
    }
}

fn write_all(
    ds: &Dataset,
    cfg: &ExportConfig,
    scale: Option<&DepthScale>,
    splits: &[(String, usize)],
    staged: &Staged,
    dist: DistMatrix,
    tick: &(dyn Fn() + Sync),
) -> Result<ExportSummary> {
    let mut summary = ExportSummary {
        tool: format!("nrw-etl {}", env!("CARGO_PKG_VERSION")),
        dataset: ds.dir.display().to_string(),
        layout: cfg.layout,
        name: cfg.name.clone(),
        crop: if cfg.layout == Layout::Files { None } else { cfg.crop },
        depth: scale.map(|s| DepthRecord {
            scale: *s,
            formula: s.formula().into(),
            loader_scaling: "x = level * 2/255 - 1 (data._parser_rendered_dataset, pretrain_appearance._load_and_concatenate_image_channels): empty = -1, near = -0.992, far = 1".into(),
        }),
        semantics: match cfg.layout {
            Layout::Files => Some("ade20k".into()),
            _ if cfg.semantics => Some("official".into()),
            _ => None,
        },
        splits: Vec::new(),
        skipped: Vec::new(),
        empty_splits: Vec::new(),
        dist_pickle: None,
    };
    if cfg.layout != Layout::Files && !splits.iter().any(|(s, _)| s == "val") {
        // The published code validates on val/ (or <name>_val.tfrecord): say it is missing.
        summary.empty_splits.push("val".into());
    }
    for (split, n) in splits {
        if *n == 0 {
            summary.empty_splits.push(split.clone());
            continue;
        }
        let s = write_split(
            ds,
            cfg,
            scale,
            split,
            *n,
            staged,
            &mut summary.skipped,
            tick,
        )?;
        if s.image_ids.is_empty() {
            summary.empty_splits.push(split.clone());
        } else {
            summary.splits.push(s);
        }
    }
    if !summary.splits.iter().any(|s| s.split == "train") && cfg.layout != Layout::Files {
        return Err(refuse(
            &ds.dir,
            format!(
                "no train view is left to export: {} skipped as smaller than the crop, e.g. {}; use a smaller --crop",
                summary.skipped.len(),
                summary
                    .skipped
                    .first()
                    .map_or("none".into(), |s| format!("{} ({}×{})", s.name, s.width, s.height))
            ),
        ));
    }
    if cfg.layout == Layout::Official {
        let train = summary
            .splits
            .iter()
            .find(|s| s.split == "train")
            .expect("checked");
        if let Some(m) = dist(&train.image_ids)? {
            let n = train.image_ids.len();
            let file = format!("dist_{}.pckl", cfg.name);
            staged.write(&file, &pickle::matrix_dict("dist_matrix", n, &m))?;
            summary.dist_pickle = Some(file);
        }
    }
    staged.write(
        EXPORT_JSON,
        &serde_json::to_vec_pretty(&summary).expect("json"),
    )?;
    Ok(summary)
}

/// Where one split's encoded views go: files in the staging folder, or TFRecord shards.
struct Sink<'a> {
    staged: &'a Staged,
    records: Vec<(String, std::io::BufWriter<std::fs::File>)>,
    /// Views of the split in all (shard choice: position · shards / views).
    views: usize,
    files: Vec<String>,
}

impl Sink<'_> {
    fn put(&mut self, pos: usize, files: Encoded) -> Result<()> {
        use std::io::Write;
        for (rel, bytes) in files {
            if self.records.is_empty() {
                self.staged.write(&rel, &bytes)?;
                self.files.push(rel);
            } else {
                let shard = pos * self.records.len() / self.views;
                let (rel, w) = &mut self.records[shard];
                w.write_all(&bytes)
                    .map_err(|e| DatasetError::io(self.staged.dir().join(&*rel), e))?;
            }
        }
        Ok(())
    }

    /// Flush and sync the TFRecord files; the files written, relative to the export.
    fn finish(self) -> Result<Vec<String>> {
        let mut files = self.files;
        for (rel, w) in self.records {
            let path = self.staged.dir().join(&rel);
            let f = w
                .into_inner()
                .map_err(|e| DatasetError::io(&path, e.into_error()))?;
            f.sync_all().map_err(|e| DatasetError::io(&path, e))?;
            files.push(rel);
        }
        Ok(files)
    }
}

/// Encoded views of one batch: (position in the split, files).
type EncodedBatch = Vec<(usize, Encoded)>;

#[allow(clippy::too_many_arguments)]
fn write_split(
    ds: &Dataset,
    cfg: &ExportConfig,
    scale: Option<&DepthScale>,
    split: &str,
    n: usize,
    staged: &Staged,
    skipped: &mut Vec<Skipped>,
    tick: &(dyn Fn() + Sync),
) -> Result<SplitExport> {
    let width = index_width(n);
    let mut out = SplitExport {
        split: split.into(),
        image_ids: Vec::new(),
        names: Vec::new(),
        files: Vec::new(),
    };
    let mut sink = Sink {
        staged,
        records: Vec::new(),
        views: n,
        files: Vec::new(),
    };
    if cfg.layout == Layout::Tfrecord {
        for i in 0..cfg.shards {
            let rel = tfrecord_name(&cfg.name, split, i, cfg.shards);
            let p = staged.claim(&rel)?;
            let f = std::fs::File::create(&p).map_err(|e| DatasetError::io(&p, e))?;
            sink.records
                .push((rel, std::io::BufWriter::with_capacity(1 << 20, f)));
        }
    }
    // Batches are decoded and encoded on all cores while a writer thread appends the
    // previous batch, in order.
    out.files = std::thread::scope(|scope| -> Result<Vec<String>> {
        let (tx, rx) = std::sync::mpsc::sync_channel::<EncodedBatch>(2);
        let writer = scope.spawn(move || -> Result<Vec<String>> {
            for batch in rx {
                for (pos, files) in batch {
                    sink.put(pos, files)?;
                }
            }
            sink.finish()
        });
        // A reader thread streams the split's views (shard reads and payload copies), so
        // reading, encoding and writing overlap.
        let (rtx, rrx) = std::sync::mpsc::sync_channel::<Result<Vec<View>>>(2);
        scope.spawn(move || {
            let mut iter = match ds.iter_split(split) {
                Ok(it) => it,
                Err(e) => {
                    let _ = rtx.send(Err(e));
                    return;
                }
            };
            loop {
                let batch: Result<Vec<View>> = iter.by_ref().take(BATCH).collect();
                let last = batch.as_ref().map_or(true, |b| b.is_empty());
                if rtx.send(batch).is_err() || last {
                    return;
                }
            }
        });
        let produced = (|| -> Result<()> {
            let mut seen = 0usize; // views of the split read so far
            for batch in rrx {
                let batch = batch?;
                if batch.is_empty() {
                    return Ok(());
                }
                let mut jobs: Vec<(usize, usize, &View)> = Vec::new(); // (index, position, view)
                for v in &batch {
                    // A missing label map is refused before any size check: it is the
                    // dataset's problem, whatever the crop.
                    if cfg.semantics && cfg.layout.paper() && v.labels_png.is_none() {
                        return Err(no_semantics(v));
                    }
                    let fits = cfg.layout == Layout::Files
                        || cfg.crop.is_none_or(|c| v.width >= c && v.height >= c);
                    if fits {
                        jobs.push((out.image_ids.len(), seen, v));
                        out.image_ids.push(v.image_id);
                        out.names.push(v.name.clone());
                    } else {
                        let c = cfg.crop.expect("only a crop skips");
                        skipped.push(Skipped {
                            split: split.into(),
                            image_id: v.image_id,
                            name: v.name.clone(),
                            width: v.width,
                            height: v.height,
                            reason: format!("smaller than the {c}×{c} crop"),
                        });
                        tick();
                    }
                    seen += 1;
                }
                let encoded: EncodedBatch = jobs
                    .par_iter()
                    .map(|&(k, pos, v)| {
                        let e = encode_view(v, cfg, scale, split, &format!("{k:0width$}"))?;
                        tick();
                        Ok((pos, e))
                    })
                    .collect::<Result<_>>()?;
                if tx.send(encoded).is_err() {
                    return Ok(()); // the writer stopped on an error, which join returns
                }
            }
            Ok(())
        })();
        drop(tx);
        let written = writer.join().expect("writer thread does not panic");
        produced?;
        written
    })?;
    Ok(out)
}

/// One view's files in the layout asked for (a single TFRecord frame for `tfrecord`).
fn encode_view(
    v: &View,
    cfg: &ExportConfig,
    scale: Option<&DepthScale>,
    split: &str,
    stem: &str,
) -> Result<Encoded> {
    match cfg.layout {
        Layout::Official => encode_official(
            v,
            cfg,
            scale.expect("paper layout"),
            &format!("{split}/{stem}"),
        ),
        Layout::Tfrecord => Ok(vec![(
            String::new(),
            encode_record(v, cfg, scale.expect("paper layout"))?,
        )]),
        Layout::Files => encode_files(
            v,
            &format!(
                "{split}/{}",
                Path::new(&v.name).with_extension("").display()
            ),
        ),
        Layout::Nerfw | Layout::Nerfstudio => {
            unreachable!("export() refuses the layouts with points before encoding")
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn index_names_sort_in_index_order_at_any_size() {
        assert_eq!(index_width(1), 4);
        assert_eq!(index_width(10_000), 4);
        assert_eq!(index_width(10_001), 5);
        assert_eq!(index_width(1_000_001), 7);
        for n in [9_999usize, 10_000, 10_001, 123_457] {
            let w = index_width(n);
            let names: Vec<String> = [0, 9, 999, 9_999, n - 1]
                .iter()
                .filter(|&&k| k < n)
                .map(|k| format!("{k:0w$}_color.png"))
                .collect();
            let mut sorted = names.clone();
            sorted.sort();
            assert_eq!(names, sorted, "n = {n}");
        }
    }

    #[test]
    fn tfrecord_names_match_the_published_glob() {
        assert_eq!(
            tfrecord_name("trevi", "train", 0, 1),
            "trevi_train.tfrecord"
        );
        let s = tfrecord_name("trevi", "val", 3, 12);
        assert_eq!(s, "trevi-00003-of-00012_val.tfrecord");
        assert!(s.starts_with("trevi") && s.ends_with("_val.tfrecord"));
    }
}
