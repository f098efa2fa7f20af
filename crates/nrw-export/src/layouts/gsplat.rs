//! The COLMAP folder the 3DGS family reads (graphdeco, gsplat, OpenSplat, nerfbaselines'
//! `colmap` loader):
//!
//! ```text
//! OUT/images/FILE                    each view's photo as stored (FILE = its name with .png)
//! OUT/images_{2,4,8}/FILE            the image pyramid (crate::pyramid: whole f × f blocks)
//! OUT/masks/FILE                     use-mask, 255 = use the pixel, 0 = ignore (a transient
//!                                    object): nerfbaselines reads masks/<name with .png>
//! OUT/masks/FILE.png                 the same mask under COLMAP's name (<image name>.png),
//!                                    which COLMAP, OpenSplat and gsplat's tools read
//! OUT/masks_{2,4,8}/FILE             the mask pyramid (a block is used only if all of it is)
//! OUT/sky/FILE                       255 = sky (ADE20K `sky`), 0 = anything else
//! OUT/depths/FILE                    16-bit inverse depth (crate::inverse_depth), 0 = none
//! OUT/depths_{2,4,8}/FILE            the inverse-depth pyramid, same scale per view
//! OUT/depth_masks/FILE               255 = the depth prior has depth at the pixel, 0 = none
//! OUT/depth_confidence/FILE          with densify's depth: its confidence, 0–255 for 0–1
//! OUT/sparse/0/{cameras,images,points3D}.bin   the SfM points the images observe, with
//!                                    their tracks (`crate::colmap_model`)
//! OUT/sparse/0/points3D.ply          the initialisation cloud ingest rendered, with normals
//! OUT/sparse/0/depth_params.json     {stem: {scale, offset, med_scale}}, graphdeco's
//! OUT/train_list.txt, test_list.txt  the split, as nerfbaselines' colmap loader reads it
//! ```
//!
//! Masks and sky come from the labels a dataset carries (`ingest --semantics` or
//! `--segment-weights`); without labels none are written. Depth is the render's z-buffer, or
//! densify's MVS depth when the dataset was rendered from its workspace ([`crate::Prior`]).
//! Cameras are PINHOLE, one per image with the image's id (graphdeco, gsplat and
//! Splatfacto-W read `params[0..4]` as fx, fy, cx, cy; loaders that look cameras up by image id
//! find the right one): a distorted camera is refused by name (ingest with `--undistort`).
//!
//! Where the initialisation cloud goes: graphdeco reads `sparse/0/points3D.ply` before
//! `points3D.bin` (and writes the ply from the bin only when there is none), so the cloud
//! ingest rendered — a dense cloud with its normals — is that ply; gsplat's `Parser`,
//! OpenSplat and nerfbaselines read `points3D.bin`, so they start from the SfM points and
//! find every image's observations there (gsplat's `point_indices`, its depth supervision).

use std::collections::BTreeMap;
use std::sync::Mutex;

use nrw_colmap::{Camera, Image, Reconstruction};
use nrw_dataset::codec::{encode_gray, encode_gray16, encode_rgb};
use nrw_dataset::depth::DepthMap;
use nrw_dataset::split::{TRAIN, VAL};
use nrw_dataset::ViewRow;

use crate::error::{ExportError, Result};
use crate::inputs::{Prior, ScenePoint};
use crate::inverse_depth::{self, DepthParams};
use crate::pyramid::{self, FACTORS};
use crate::staging::Staged;
use crate::stream::{write_views, Encoded, ViewEncoder};
use crate::writer::{About, Job, LayoutWriter};
use crate::ExportSummary;

/// ADE20K's `sky` (1-based id, as the dataset's label maps store it).
pub const ADE_SKY: u8 = 3;

/// The `gsplat` layout, as the CLI, pipeline files and `export.json` name it.
pub const ABOUT: About = About {
    name: "gsplat",
    summary: "the COLMAP folder 3DGS trainers read (graphdeco, gsplat, OpenSplat, nerfbaselines): images/ and images_2|4|8/ (box-filtered whole blocks, intrinsics / N exactly), masks/ (255 = use; NAME.png and COLMAP's NAME.png.png) and masks_N/, sky/, depths/ and depths_N/ (graphdeco's 16-bit inverse depth) with sparse/0/depth_params.json, sparse/0 (one PINHOLE camera per image, the scene's points), train_list.txt / test_list.txt; needs PINHOLE cameras (`ingest.undistort`)",
    needs_points: true,
    writes_depth_priors: true,
    default_crop: None,
};

/// The gsplat layout.
pub struct Gsplat;

impl LayoutWriter for Gsplat {
    fn check(&self, job: &Job) -> Result<()> {
        job.require_train("")?;
        job.scene_model()?;
        job.points().map(|_| ())
    }

    fn write(&self, job: &Job, staged: &Staged, summary: &mut ExportSummary) -> Result<()> {
        let scene = job.scene_model()?;
        let own = own_depth_scales(job)?;
        let (depth, above) = inverse_depth::params(&own);
        let enc = Encoder {
            job,
            scene,
            depth,
            model: Mutex::new(BTreeMap::new()),
        };
        write_views(job, staged, &enc, summary)?;
        let model = enc.model.into_inner().expect("no encoder panicked");
        write_model(&model, scene, staged)?;
        write_init_ply(job.points()?, staged)?;
        write_depth_params(&model, &enc.depth, staged)?;
        write_split_lists(&summary.splits, staged)?;
        summary.semantics = Some("masks: 255 = use, 0 = ignore; sky: 255 = sky".into());
        summary.warnings.extend(consumer_warnings(&model, &above));
        summary.depth_source = Some(job.depth_source());
        Ok(())
    }
}

/// Each view's own inverse-depth scale, read before any file is written since
/// `depth_params.json`'s `med_scale` (and the band it sets) depends on every view.
fn own_depth_scales(job: &Job) -> Result<BTreeMap<u32, f64>> {
    let mut own = BTreeMap::new();
    for (split, n) in &job.splits {
        if *n == 0 {
            continue;
        }
        for v in job.ds.iter_split(split)? {
            let v = v?;
            let inv = inverse_depth::inverse_depth(&job.prior_depth(&v)?);
            own.insert(v.image_id, inverse_depth::own_scale(&inv));
        }
    }
    Ok(own)
}

/// One view's model entries, kept by the encoder for the model written at the end.
struct ModelView {
    camera: Camera,
    image: Image,
}

/// Encodes one view's files and remembers its camera and image.
struct Encoder<'a> {
    job: &'a Job<'a>,
    /// The scene model, whose observations each image carries.
    scene: &'a Reconstruction,
    depth: BTreeMap<u32, DepthParams>,
    model: Mutex<BTreeMap<u32, ModelView>>,
}

/// What this layout's readers do with a camera that is not a pinhole.
const READERS: &str = "graphdeco's 3D Gaussian Splatting loader, which reads this layout \
     beside gsplat's Parser, accepts only PINHOLE and SIMPLE_PINHOLE cameras";

impl ViewEncoder for Encoder<'_> {
    fn check_view(&self, v: &ViewRow) -> Result<()> {
        crate::nerfw::pinhole(v, READERS).map(|_| ())
    }

    fn encode(&self, v: &ViewRow, _split: &str, _index: &str) -> Result<Encoded> {
        let file = crate::nerfw::file_name(&v.name);
        let camera = crate::nerfw::pinhole(v, READERS)?;
        let mut image = crate::nerfw::model_image(v, &file)?;
        image.points2d = crate::colmap_model::observations(v, self.scene, &camera)?;
        let mut out: Encoded = vec![(format!("images/{file}"), v.photo_png.clone())];
        let photo = v.photo()?;
        for f in FACTORS {
            level_ok(v, f)?;
            let level = pyramid::box_rgb(&photo, f);
            out.push((
                format!("{}/{file}", pyramid::level_dir("images", f)),
                encode_rgb(&v.name, &level)?,
            ));
        }
        out.extend(mask_files(v, &file)?);
        let prior = self.job.prior(v)?;
        let scale = self.depth[&v.image_id].scale;
        out.extend(depth_files(v, &prior.depth, &file, scale)?);
        out.extend(depth_trust_files(v, &prior, &file)?);
        self.model
            .lock()
            .expect("no encoder panicked")
            .insert(v.image_id, ModelView { camera, image });
        Ok(out)
    }
}

/// Refuse a view too small for level `f` (a level of zero pixels).
fn level_ok(v: &ViewRow, f: u32) -> Result<()> {
    let (w, h) = pyramid::level_size(v.width, v.height, f);
    if w == 0 || h == 0 {
        return Err(ExportError::Value {
            path: v.name.clone().into(),
            record: format!("image {}", v.image_id),
            field: "width".into(),
            problem: format!(
                "{}×{} has no level {f} (images_{f} needs at least {f}×{f} pixels)",
                v.width, v.height
            ),
        });
    }
    Ok(())
}

/// A view's use-mask (255 = use, 0 = a transient object), when the view has labels.
pub fn use_mask(v: &ViewRow) -> Result<Option<Vec<u8>>> {
    Ok(v.transient()?
        .map(|t| t.as_raw().iter().map(|t| 255 - t).collect()))
}

/// The use-mask at every level (both names at level 0) and the sky mask, when the view has
/// labels.
fn mask_files(v: &ViewRow, file: &str) -> Result<Encoded> {
    let (Some(usable), Some(labels)) = (use_mask(v)?, v.labels()?) else {
        return Ok(Vec::new());
    };
    let (w, h) = (v.width, v.height);
    let level0 = encode_gray(&v.name, w, h, &usable)?;
    let mut out = vec![
        (format!("masks/{file}"), level0.clone()),
        (format!("masks/{file}.png"), level0),
    ];
    for f in FACTORS {
        let (lw, lh) = pyramid::level_size(w, h, f);
        let m = pyramid::min_mask(&usable, w, h, f);
        out.push((
            format!("{}/{file}", pyramid::level_dir("masks", f)),
            encode_gray(&v.name, lw, lh, &m)?,
        ));
    }
    let sky: Vec<u8> = labels
        .as_raw()
        .iter()
        .map(|&l| if l == ADE_SKY { 255 } else { 0 })
        .collect();
    out.push((format!("sky/{file}"), encode_gray(&v.name, w, h, &sky)?));
    Ok(out)
}

/// The inverse-depth PNG at every level, at the view's one scale.
fn depth_files(v: &ViewRow, depth: &DepthMap, file: &str, scale: f64) -> Result<Encoded> {
    let inv = inverse_depth::inverse_depth(depth);
    let (w, h) = (v.width, v.height);
    let mut out = vec![(
        format!("depths/{file}"),
        encode_gray16(&v.name, w, h, &inverse_depth::quantise(&inv, scale))?,
    )];
    for f in FACTORS {
        let (lw, lh) = pyramid::level_size(w, h, f);
        let level = pyramid::mean_inverse_depth(&inv, w, h, f);
        out.push((
            format!("{}/{file}", pyramid::level_dir("depths", f)),
            encode_gray16(&v.name, lw, lh, &inverse_depth::quantise(&level, scale))?,
        ));
    }
    Ok(out)
}

/// The depth prior's validity mask (255 = the prior has depth there) and, when the source
/// has one, its confidence (0–255 for 0–1).
fn depth_trust_files(v: &ViewRow, prior: &Prior, file: &str) -> Result<Encoded> {
    let (w, h) = (v.width, v.height);
    let valid: Vec<u8> = prior
        .depth
        .data
        .iter()
        .map(|z| if *z > 0.0 { 255 } else { 0 })
        .collect();
    let mut out = vec![(
        format!("depth_masks/{file}"),
        encode_gray(&v.name, w, h, &valid)?,
    )];
    if let Some(c) = &prior.confidence {
        // Precision given up here: confidence in steps of 1/255.
        let c: Vec<u8> = c
            .iter()
            .map(|c| (c.clamp(0.0, 1.0) * 255.0).round() as u8)
            .collect();
        out.push((
            format!("depth_confidence/{file}"),
            encode_gray(&v.name, w, h, &c)?,
        ));
    }
    Ok(out)
}

/// `sparse/0`: one PINHOLE camera per image, the images with their observations, the SfM
/// points they observe with their tracks.
fn write_model(
    model: &BTreeMap<u32, ModelView>,
    scene: &Reconstruction,
    staged: &Staged,
) -> Result<()> {
    let views = model.values().map(|m| (m.camera.clone(), m.image.clone()));
    let rec = crate::colmap_model::with_tracks(views, scene);
    crate::colmap_model::write(&rec, staged, "sparse/0", nrw_colmap::Format::Binary)
}

/// `sparse/0/points3D.ply` with the cloud's normals, which graphdeco reads in preference to
/// `points3D.bin` (whose points carry none); only when the cloud has normals.
fn write_init_ply(points: &[ScenePoint], staged: &Staged) -> Result<()> {
    let Some(normals) = points.iter().map(|p| p.normal).collect::<Option<Vec<_>>>() else {
        return Ok(());
    };
    let path = staged.claim("sparse/0/points3D.ply")?;
    let cloud = nrw_colmap::PointCloud {
        path: path.clone(),
        positions: points.iter().map(|p| p.xyz.into()).collect(),
        colors: Some(points.iter().map(|p| p.rgb).collect()),
        normals: Some(normals),
    };
    nrw_colmap::write_ply(&cloud, &path).map_err(|e| ExportError::io(&path, e))
}

/// graphdeco's key of an image: its name without the extension (`extr.name[:-n_remove]`).
fn graphdeco_key(file: &str) -> &str {
    file.rsplit_once('.').map_or(file, |(stem, _)| stem)
}

/// `sparse/0/depth_params.json`, keyed as graphdeco looks views up.
fn write_depth_params(
    model: &BTreeMap<u32, ModelView>,
    depth: &BTreeMap<u32, DepthParams>,
    staged: &Staged,
) -> Result<()> {
    let entries: BTreeMap<&str, DepthParams> = model
        .iter()
        .map(|(id, m)| (graphdeco_key(&m.image.name), depth[id]))
        .collect();
    staged.write(
        "sparse/0/depth_params.json",
        &serde_json::to_vec_pretty(&entries).expect("json"),
    )
}

/// `train_list.txt` and `test_list.txt` (our val), one image name a line, as nerfbaselines'
/// colmap loader reads the split.
pub(crate) fn write_split_lists(splits: &[crate::SplitExport], staged: &Staged) -> Result<()> {
    for (split, file) in [(TRAIN, "train_list.txt"), (VAL, "test_list.txt")] {
        let Some(s) = splits.iter().find(|s| s.split == split) else {
            continue;
        };
        let names: String = s
            .names
            .iter()
            .map(|n| format!("{}\n", crate::nerfw::file_name(n)))
            .collect();
        staged.write(file, names.as_bytes())?;
    }
    Ok(())
}

/// Where a known loader would silently misread this export, each naming the loader and rule.
/// (gsplat's parser, which scales every K by the first image's size ratio, cannot: each
/// `images_N` holds ⌊size / N⌋, the size it expects, so that ratio is 1 for every image.)
fn consumer_warnings(model: &BTreeMap<u32, ModelView>, depth_above: &[u32]) -> Vec<String> {
    let mut out = Vec::new();
    let odd: Vec<String> = FACTORS
        .iter()
        .map(|&f| {
            let n = model
                .values()
                .filter(|m| m.camera.width % f as u64 != 0 || m.camera.height % f as u64 != 0)
                .count();
            (f, n)
        })
        .filter(|(_, n)| *n > 0)
        .map(|(f, n)| format!("{n} at images_{f}"))
        .collect();
    if !odd.is_empty() {
        out.push(format!(
            "nerfbaselines' colmap loader given images_path=images_N estimates N as \
             size / (size // N) and re-centres cx, cy, so on images whose size is not a \
             multiple of N ({} of {}) its K is not the exact K / N of these whole-block levels \
             (gsplat's parser uses K / N); with nerfbaselines, load level 0 (images/)",
            odd.join(", "),
            model.len()
        ));
    }
    if !depth_above.is_empty() {
        out.push(format!(
            "graphdeco: {} view(s) have depth 5× nearer than the median view (own scale above \
             5 × med_scale), so its loader marks their depth prior unreliable and skips it",
            depth_above.len()
        ));
    }
    out
}
