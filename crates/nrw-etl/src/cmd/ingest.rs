//! `nrw-etl ingest`: read and validate a scene, render every registered photo's view of the
//! cloud, apply the paper's filters, and write shards, scene tables and the manifest.
//!
//! Work goes in groups of `--rows-per-shard` images in id order; each group becomes one
//! shard, written atomically, and is recorded in `.ingest-progress.json`. An interrupted run
//! resumes from the groups already done (when inputs and parameters are unchanged), and the
//! result is byte-identical to an uninterrupted run on any thread count.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use clap::Args;
use nrw_colmap::{read_ply, Reconstruction};
use nrw_dataset::codec::{
    encode_color_render, encode_normals, encode_rgb, load_photo, resize_photo,
};
use nrw_dataset::{FileEntry, ImageOutcome, Manifest, SceneSource, Tool, ViewRow, SCHEMA_VERSION};
use nrw_render::{render, render_size, Filters, RenderCloud, Verdict, View};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use super::{describe, load_model, Encoding};
use crate::error::{EtlError, Result};

/// Exit code when the run completed but every view was dropped by the filters.
pub const EXIT_NOTHING_KEPT: u8 = 3;

/// Arguments of `ingest`.
#[derive(Debug, Clone, Args)]
pub struct IngestArgs {
    /// Scene folder holding sparse/0/ (or sparse/) and images/, or a model folder itself
    pub scene: PathBuf,
    /// Dataset folder to write (created if missing; files in it are replaced atomically)
    #[arg(long)]
    pub out: PathBuf,
    /// Folder of the photos named in the model [default: <scene>/images]
    #[arg(long)]
    pub images: Option<PathBuf>,
    /// Read this encoding even if the other exists [default: bin when present, else txt]
    #[arg(long, value_enum)]
    pub format: Option<Encoding>,
    /// Point cloud to render [default: <scene>/dense/fused.ply if present, else the sparse points]
    #[arg(long)]
    pub points: Option<PathBuf>,
    /// Folder of per-photo ADE20K label maps (8-bit PNG of class ids, named like the photo
    /// with .png); stored colour-coded with a transient mask
    #[arg(long)]
    pub semantics: Option<PathBuf>,
    /// Render so the shorter side has this many pixels (the paper: 600)
    #[arg(long, default_value_t = 600)]
    pub min_dim: u32,
    /// Splat radius in render pixels: a point covers the pixels whose centres lie within it (0: its own pixel)
    #[arg(long, default_value_t = 1.0)]
    pub radius: f32,
    /// Drop views whose render has more than this fraction of empty pixels (the paper: 0.85)
    #[arg(long, default_value_t = nrw_render::Filters::default().max_empty_ratio)]
    pub max_empty: f64,
    /// Drop photos whose shorter side is under this many pixels (the paper: 450)
    #[arg(long, default_value_t = nrw_render::Filters::default().min_photo_side)]
    pub min_photo_side: u32,
    /// Images per shard (one shard per group of this many images, in id order)
    #[arg(long, default_value_t = 64)]
    pub rows_per_shard: usize,
    /// Worker threads [default: all cores]; output bytes do not depend on it
    #[arg(long)]
    pub threads: Option<usize>,
    /// No progress bars or summary
    #[arg(long)]
    pub quiet: bool,
    /// Print a JSON summary on stdout (for scripts)
    #[arg(long)]
    pub json: bool,
    /// Stop after writing this many shards, as an interruption would (for resume tests)
    #[arg(long, hide = true)]
    pub stop_after_shards: Option<usize>,
}

impl IngestArgs {
    /// Defaults for a scene and dataset (as the CLI would fill them in).
    pub fn new(scene: PathBuf, out: PathBuf) -> IngestArgs {
        IngestArgs {
            scene,
            out,
            images: None,
            format: None,
            points: None,
            semantics: None,
            min_dim: 600,
            radius: 1.0,
            max_empty: nrw_render::Filters::default().max_empty_ratio,
            min_photo_side: nrw_render::Filters::default().min_photo_side,
            rows_per_shard: 64,
            threads: None,
            quiet: false,
            json: false,
            stop_after_shards: None,
        }
    }
}

/// The photo folder: given, or `images/` next to the model as COLMAP lays scenes out.
fn images_dir(args: &IngestArgs, model_dir: &Path) -> Result<PathBuf> {
    if let Some(d) = &args.images {
        if !d.is_dir() {
            return Err(EtlError::Usage(format!(
                "{}: --images is not a folder",
                d.display()
            )));
        }
        return Ok(d.clone());
    }
    let mut tried = vec![args.scene.join("images")];
    for up in model_dir.ancestors().skip(1).take(2) {
        tried.push(up.join("images"));
    }
    tried.iter().find(|d| d.is_dir()).cloned().ok_or_else(|| {
        EtlError::Usage(format!(
            "no photo folder found (tried {}); pass --images DIR",
            tried
                .iter()
                .map(|d| d.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ))
    })
}

/// Photo sizes from file headers (no pixel decoded), with warnings for size mismatches.
fn photo_sizes(
    rec: &Reconstruction,
    dir: &Path,
    warnings: &mut Vec<String>,
) -> Result<BTreeMap<u32, Option<(u32, u32)>>> {
    let mut photos = BTreeMap::new();
    let mut missing = Vec::new();
    for img in rec.images.values() {
        let path = dir.join(&img.name);
        if !path.is_file() {
            missing.push(img.name.clone());
            continue;
        }
        let (w, h) = image::ImageReader::open(&path)
            .and_then(|r| r.with_guessed_format())
            .map_err(|e| EtlError::Photo {
                path: path.clone(),
                source: image::ImageError::IoError(e),
            })?
            .into_dimensions()
            .map_err(|e| EtlError::Photo {
                path: path.clone(),
                source: e,
            })?;
        let cam = &rec.cameras[&img.camera_id];
        if (w as u64, h as u64) != (cam.width, cam.height) {
            // Same aspect ratio (to a pixel): the photo is rescaled to the render size like
            // any other. Otherwise the camera does not describe this photo.
            let aspect_ok =
                ((w as f64 / h as f64) * cam.height as f64 - cam.width as f64).abs() <= 1.0;
            if !aspect_ok {
                return Err(EtlError::Usage(format!(
                    "{}: photo is {w}x{h} but camera {} is {}x{} (another aspect ratio): the model does not describe this photo",
                    path.display(),
                    cam.id,
                    cam.width,
                    cam.height
                )));
            }
            warnings.push(format!(
                "{}: photo is {w}x{h} but camera {} is {}x{}; same aspect ratio, rescaled",
                path.display(),
                cam.id,
                cam.width,
                cam.height
            ));
        }
        photos.insert(img.id, Some((w, h)));
    }
    if !missing.is_empty() {
        let shown: Vec<_> = missing.iter().take(5).cloned().collect();
        return Err(EtlError::Usage(format!(
            "{}: {} of {} registered photos are missing ({}{})",
            dir.display(),
            missing.len(),
            rec.images.len(),
            shown.join(", "),
            if missing.len() > 5 { ", …" } else { "" }
        )));
    }
    Ok(photos)
}

/// Which cloud to render, and the file it came from (if any).
fn point_source(
    args: &IngestArgs,
    model_dir: &Path,
    rec: &Reconstruction,
) -> Result<(RenderCloud, String, Option<PathBuf>)> {
    let origin = rec.scene_origin();
    let candidate = args.points.clone().or_else(|| {
        [args.scene.join("dense/fused.ply")]
            .into_iter()
            .chain(
                model_dir
                    .ancestors()
                    .skip(1)
                    .take(2)
                    .map(|d| d.join("dense/fused.ply")),
            )
            .find(|p| p.is_file())
    });
    match candidate {
        Some(p) => {
            let cloud = read_ply(&p)?;
            Ok((RenderCloud::from_ply(origin, &cloud), "ply".into(), Some(p)))
        }
        None if !rec.points.is_empty() => Ok((RenderCloud::from_sparse(origin, rec), "sparse".into(), None)),
        None => Err(EtlError::Usage(format!(
            "{}: nothing to render: no dense/fused.ply, no --points FILE, and the model has no 3D points",
            model_dir.display()
        ))),
    }
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
struct GroupDone {
    shard: Option<FileEntry>,
    outcomes: Vec<(u32, ImageOutcome)>,
}

#[derive(Debug, Clone, Serialize, Deserialize, Default)]
struct Progress {
    fingerprint: String,
    groups: BTreeMap<usize, GroupDone>,
}

const PROGRESS_FILE: &str = ".ingest-progress.json";

fn load_progress(out: &Path, fingerprint: &str) -> Progress {
    let fresh = Progress {
        fingerprint: fingerprint.into(),
        groups: BTreeMap::new(),
    };
    let Ok(text) = std::fs::read_to_string(out.join(PROGRESS_FILE)) else {
        return fresh;
    };
    let Ok(mut p) = serde_json::from_str::<Progress>(&text) else {
        return fresh;
    };
    if p.fingerprint != fingerprint {
        return fresh;
    }
    // Keep only groups whose shard is still there with the bytes recorded.
    p.groups.retain(|_, g| match &g.shard {
        None => true,
        Some(e) => {
            nrw_dataset::manifest::sha256_file(&out.join(&e.path)).is_ok_and(|(_, h)| h == e.sha256)
        }
    });
    p
}

fn save_progress(out: &Path, p: &Progress) -> Result<()> {
    let text = serde_json::to_string(p).expect("progress serialises");
    nrw_dataset::atomic::write_bytes_atomic(&out.join(PROGRESS_FILE), text.as_bytes())?;
    Ok(())
}

/// Render one image and, if kept, encode its row.
fn process(
    args: &IngestArgs,
    rec: &Reconstruction,
    cloud: &RenderCloud,
    filters: &Filters,
    photos_dir: &Path,
    image_id: u32,
    photo_size: (u32, u32),
) -> Result<(ImageOutcome, Option<ViewRow>)> {
    let img = &rec.images[&image_id];
    let cam = &rec.cameras[&img.camera_id];
    if let Some(v) = filters.check_size(photo_size.0 as u64, photo_size.1 as u64) {
        return Ok((
            ImageOutcome {
                verdict: v.name().into(),
                verdict_value: v.value(),
                empty_ratio: None,
                render_size: None,
                shard: None,
                depth_range: None,
            },
            None,
        ));
    }
    let (w, h) = render_size(cam.width, cam.height, args.min_dim);
    let view = View::new(img, cam, cloud.origin, w, h, args.radius);
    let buf = render(&view, cloud);
    let empty = buf.empty_ratio();
    let verdict = filters.check_render(empty);
    let outcome = ImageOutcome {
        verdict: verdict.name().into(),
        verdict_value: verdict.value(),
        empty_ratio: Some(empty),
        render_size: Some((w, h)),
        shard: None,
        depth_range: None,
    };
    if !matches!(verdict, Verdict::Kept { .. }) {
        return Ok((outcome, None));
    }
    // Kept: record its depth range (export's 16-bit scale and QA's depth plots read it).
    let outcome = ImageOutcome {
        depth_range: buf.depth.iter().filter(|d| **d > 0.0).fold(
            None,
            |r: Option<(f64, f64)>, &d| {
                let d = d as f64;
                Some(r.map_or((d, d), |(lo, hi)| (lo.min(d), hi.max(d))))
            },
        ),
        ..outcome
    };
    let photo_path = photos_dir.join(&img.name);
    let photo = resize_photo(&load_photo(&photo_path)?, w, h);
    let name = format!("image {}", img.id);
    let (semantics_png, transient_png, labels_png) = match &args.semantics {
        None => (None, None, None),
        Some(dir) => {
            let path = dir.join(Path::new(&img.name).with_extension("png"));
            let labels = nrw_dataset::semantics::load_labels(&path, photo_size.0, photo_size.1)?;
            let ids = nrw_dataset::semantics::resize_labels(&labels, w, h);
            let (rgb, mask) = nrw_dataset::semantics::colorize(&ids);
            (
                Some(nrw_dataset::codec::encode_rgb_bytes(&name, w, h, &rgb)?),
                Some(nrw_dataset::codec::encode_gray(&name, w, h, &mask)?),
                Some(nrw_dataset::codec::encode_gray(&name, w, h, ids.as_raw())?),
            )
        }
    };
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
    Ok((outcome, Some(row)))
}

/// What an ingest run produced (printed with --json).
#[derive(Debug, Serialize)]
pub struct IngestSummary {
    pub dataset: String,
    pub registered: usize,
    pub rendered: usize,
    pub kept: usize,
    pub too_small: usize,
    pub too_sparse: usize,
    pub shards: usize,
    pub point_source: String,
    pub points: usize,
    pub resumed_groups: usize,
    pub seconds: f64,
}

/// Run `ingest`; returns the summary (the caller maps "nothing kept" to its exit code).
/// Largest splat radius accepted: wider splats smear a render into a few blobs, and each
/// point would touch thousands of pixels.
pub const MAX_RADIUS: f32 = 32.0;

pub fn run(args: &IngestArgs) -> Result<IngestSummary> {
    super::qa::timed(Some(args.out.as_path()), "ingest", || run_stage(args))
}

fn run_stage(args: &IngestArgs) -> Result<IngestSummary> {
    let t0 = Instant::now();
    if args.rows_per_shard == 0 {
        return Err(EtlError::Usage(
            "--rows-per-shard must be at least 1".into(),
        ));
    }
    if !(0.0..=MAX_RADIUS).contains(&args.radius) {
        return Err(EtlError::Usage(format!(
            "--radius {} is outside 0..={MAX_RADIUS} render pixels (the paper uses 1)",
            args.radius
        )));
    }
    if !(0.0..=1.0).contains(&args.max_empty) {
        return Err(EtlError::Usage(format!(
            "--max-empty {} is not a fraction in 0..=1 (the paper drops views above 0.85)",
            args.max_empty
        )));
    }
    let (model_dir, rec) = load_model(&args.scene, args.format)?;
    let photos_dir = images_dir(args, &model_dir)?;
    let mut warnings: Vec<String> = rec.warnings.iter().map(|w| w.to_string()).collect();
    let photos = photo_sizes(&rec, &photos_dir, &mut warnings)?;
    let (cloud, source, source_path) = point_source(args, &model_dir, &rec)?;
    let filters = Filters {
        max_empty_ratio: args.max_empty,
        min_photo_side: args.min_photo_side,
    };

    let mut inputs = rec
        .files
        .iter()
        .chain(source_path.iter())
        .map(|p| {
            let (bytes, sha256) = nrw_dataset::manifest::sha256_file(p)?;
            Ok(FileEntry {
                path: p.display().to_string(),
                bytes,
                sha256,
                rows: None,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    inputs.sort_by(|a, b| a.path.cmp(&b.path));
    let (enc, layout) = describe(&rec);
    let mut parameters = serde_json::Map::new();
    parameters.insert("format".into(), enc.into());
    parameters.insert("point_source".into(), source.clone().into());
    parameters.insert("points".into(), cloud.len().into());
    parameters.insert("min_dim".into(), args.min_dim.into());
    parameters.insert("radius".into(), (args.radius as f64).into());
    parameters.insert("max_empty".into(), args.max_empty.into());
    parameters.insert("min_photo_side".into(), args.min_photo_side.into());
    parameters.insert("rows_per_shard".into(), args.rows_per_shard.into());
    if let Some(d) = &args.semantics {
        if !d.is_dir() {
            return Err(EtlError::Usage(format!(
                "{}: --semantics is not a folder",
                d.display()
            )));
        }
        parameters.insert("semantics".into(), d.display().to_string().into());
    }
    let fingerprint = {
        let mut h = Sha256::new();
        h.update(serde_json::to_string(&inputs).expect("json").as_bytes());
        h.update(serde_json::to_string(&parameters).expect("json").as_bytes());
        h.finalize()
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect::<String>()
    };
    std::fs::create_dir_all(&args.out).map_err(|e| nrw_dataset::DatasetError::io(&args.out, e))?;
    let mut progress = load_progress(&args.out, &fingerprint);
    let resumed_groups = progress.groups.len();

    let ids: Vec<u32> = rec.images.keys().copied().collect();
    let groups: Vec<&[u32]> = ids.chunks(args.rows_per_shard).collect();
    let todo: usize = groups
        .iter()
        .enumerate()
        .filter(|(g, _)| !progress.groups.contains_key(g))
        .map(|(_, ids)| ids.len())
        .sum();
    let bar = super::progress_bar(todo, "views", args.quiet);
    bar.set_message("rendering");
    let mut written = 0usize;
    for (g, group) in groups.iter().enumerate() {
        if progress.groups.contains_key(&g) {
            continue;
        }
        let results: Vec<(ImageOutcome, Option<ViewRow>)> = group
            .par_iter()
            .map(|id| {
                let r = process(
                    args,
                    &rec,
                    &cloud,
                    &filters,
                    &photos_dir,
                    *id,
                    photos[id].expect("sized"),
                );
                bar.inc(1);
                r
            })
            .collect::<Result<_>>()?;
        let rows: Vec<ViewRow> = results.iter().filter_map(|(_, r)| r.clone()).collect();
        let rel = nrw_dataset::views::shard_path(g);
        let shard = if rows.is_empty() {
            None
        } else {
            Some(nrw_dataset::write_shard(&args.out, &rel, &rows)?)
        };
        let outcomes = group
            .iter()
            .zip(results)
            .map(|(id, (mut o, row))| {
                if row.is_some() {
                    o.shard = Some(rel.clone());
                }
                (*id, o)
            })
            .collect();
        progress.groups.insert(g, GroupDone { shard, outcomes });
        save_progress(&args.out, &progress)?;
        written += 1;
        if args.stop_after_shards.is_some_and(|n| written >= n)
            && progress.groups.len() < groups.len()
        {
            bar.abandon();
            return Err(EtlError::Interrupted(format!(
                "stopped after {written} groups as asked; run the same command again to resume"
            )));
        }
    }
    bar.finish_and_clear();

    let outcomes: BTreeMap<u32, ImageOutcome> = progress
        .groups
        .values()
        .flat_map(|g| g.outcomes.iter().cloned())
        .collect();
    let shards: Vec<FileEntry> = progress
        .groups
        .values()
        .filter_map(|g| g.shard.clone())
        .collect();
    // Shards of an earlier run with other parameters must not linger next to these.
    for stale in nrw_dataset::views::stale_shards(&args.out, &shards) {
        let _ = std::fs::remove_file(stale);
    }
    let mut tables = nrw_dataset::write_scene_tables(&args.out, &rec, &photos, &outcomes)?;
    tables.extend(shards.iter().cloned());
    // A split from an earlier run stays (split assigns only new photos when run again).
    if args.out.join(nrw_dataset::split::SPLITS_TABLE).is_file() {
        tables.push(FileEntry::of(&args.out, nrw_dataset::split::SPLITS_TABLE)?);
    }
    // Triplets depend on which views survive: a new ingest makes them stale.
    let stale = args.out.join(nrw_dataset::triplets::TRIPLETS_TABLE);
    if stale.is_file() {
        std::fs::remove_file(&stale).map_err(|e| nrw_dataset::DatasetError::io(&stale, e))?;
        warnings.push(format!(
            "{}: removed (stale after a new ingest); run `nrw-etl triplets` again",
            stale.display()
        ));
    }
    let count = |v: &str| outcomes.values().filter(|o| o.verdict == v).count();
    let (kept, too_small, too_sparse) = (
        count(nrw_dataset::scene::VERDICT_KEPT),
        count("too_small"),
        count("too_sparse"),
    );
    let manifest = Manifest {
        schema_version: SCHEMA_VERSION,
        tool: Tool {
            name: "nrw-etl".into(),
            version: env!("CARGO_PKG_VERSION").into(),
        },
        scene: SceneSource {
            scene_dir: args.scene.display().to_string(),
            model_dir: model_dir.display().to_string(),
            images_dir: Some(photos_dir.display().to_string()),
            encoding: enc.into(),
            layout: layout.into(),
        },
        inputs,
        parameters,
        tables,
        warnings: warnings.clone(),
    };
    manifest.write(&args.out)?;
    let _ = std::fs::remove_file(args.out.join(PROGRESS_FILE));
    let summary = IngestSummary {
        dataset: args.out.display().to_string(),
        registered: rec.images.len(),
        rendered: kept + too_sparse,
        kept,
        too_small,
        too_sparse,
        shards: shards.len(),
        point_source: source,
        points: cloud.len(),
        resumed_groups,
        seconds: t0.elapsed().as_secs_f64(),
    };
    if !args.quiet {
        for w in &warnings {
            eprintln!("warning: {w}");
        }
        eprintln!(
            "ingested {}: {} registered, {} kept, {} too sparse (>{:.0}% empty), {} too small (<{} px); {} shards; {} points ({}) in {:.1} s",
            args.out.display(),
            summary.registered,
            kept,
            too_sparse,
            args.max_empty * 100.0,
            too_small,
            args.min_photo_side,
            summary.shards,
            summary.points,
            summary.point_source,
            summary.seconds
        );
        if kept == 0 {
            let mut ratios: Vec<f64> = outcomes.values().filter_map(|o| o.empty_ratio).collect();
            ratios.sort_by(|a, b| a.partial_cmp(b).expect("finite"));
            eprintln!(
                "no view survived the filters{}: the dataset records every verdict but holds no view (exit code {EXIT_NOTHING_KEPT})",
                ratios.first().map_or(String::new(), |m| format!(" (least empty render: {:.1}% empty)", m * 100.0))
            );
        }
    }
    if args.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&summary).expect("summary serialises")
        );
    }
    Ok(summary)
}
