//! Near-duplicates planted on purpose: copies of a scene's photos made as the wild makes
//! them (the same upload twice, resized, re-encoded, cropped, recoloured), each added to the
//! model where COLMAP would register it — its original's pose, nudged by SfM-sized noise,
//! with the camera the copy's pixels imply. The ground truth (which photo copies which) is
//! what near-duplicate search is measured against.

use std::path::Path;

use glam::{DQuat, DVec3};
use image::RgbImage;
use nrw_colmap::{Camera, Format, Image, Reconstruction};
use rand::{Rng, SeedableRng};

use crate::error::{Result, SynthError};

/// How a copy differs from its original.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum CopyKind {
    /// The same file under another name.
    Identical,
    /// Scaled to this many hundredths of the original's size.
    Resized(u32),
    /// Re-encoded as JPEG at this quality.
    Reencoded(u8),
    /// This many hundredths of the original's width and height, off centre.
    Cropped(u32),
    /// Other white balance and tone curve.
    Recoloured,
}

/// Every kind, in the order originals take them.
pub const KINDS: [CopyKind; 5] = [
    CopyKind::Identical,
    CopyKind::Resized(60),
    CopyKind::Reencoded(30),
    CopyKind::Cropped(70),
    CopyKind::Recoloured,
];

/// One planted copy.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Planted {
    pub original: String,
    pub copy: String,
    pub kind: CopyKind,
}

/// The copy's pixels and the camera they imply: the original's lens, scaled or shifted as
/// the pixels were (distortion, in normalised coordinates, unchanged), so a copy of a real
/// photo with a distorting lens is planted as faithfully as a synthetic PINHOLE one.
fn make(photo: &RgbImage, cam: &Camera, kind: CopyKind) -> (RgbImage, Camera) {
    let (w, h) = (photo.width(), photo.height());
    let same = |img: RgbImage| {
        let c = cam.scaled(1.0, 1.0, w as u64, h as u64);
        (img, c)
    };
    match kind {
        CopyKind::Identical | CopyKind::Reencoded(_) => same(photo.clone()),
        CopyKind::Resized(p) => {
            let (nw, nh) = (w * p / 100, h * p / 100);
            let (sx, sy) = (nw as f64 / w as f64, nh as f64 / h as f64);
            let img = image::imageops::resize(photo, nw, nh, image::imageops::FilterType::Triangle);
            (img, cam.scaled(sx, sy, nw as u64, nh as u64))
        }
        CopyKind::Cropped(p) => {
            let (nw, nh) = (w * p / 100, h * p / 100);
            let (x0, y0) = ((w - nw) / 4, (h - nh) * 3 / 4);
            let img = image::imageops::crop_imm(photo, x0, y0, nw, nh).to_image();
            let mut c = cam.scaled(1.0, 1.0, nw as u64, nh as u64);
            let at = if cam.model.single_focal() { 1 } else { 2 };
            c.params[at] -= x0 as f64;
            c.params[at + 1] -= y0 as f64;
            (img, c)
        }
        CopyKind::Recoloured => {
            let gains = [1.15, 1.0, 0.8];
            let img = RgbImage::from_fn(w, h, |x, y| {
                let p = photo.get_pixel(x, y).0;
                image::Rgb(std::array::from_fn(|k| {
                    (255.0 * (p[k] as f64 / 255.0).powf(0.8) * gains[k]).clamp(0.0, 255.0) as u8
                }))
            });
            same(img)
        }
    }
}

/// SfM-sized registration noise: the centre moved by 0.2% of `depth`, the rotation by 0.2°.
fn nudged(
    pose: &nrw_colmap::pose::Rigid3,
    depth: f64,
    rng: &mut impl Rng,
) -> nrw_colmap::pose::Rigid3 {
    let mut unit = || {
        DVec3::new(
            rng.random::<f64>() - 0.5,
            rng.random::<f64>() - 0.5,
            rng.random::<f64>() - 0.5,
        )
        .normalize_or_zero()
    };
    let centre = pose.centre() + unit() * 0.002 * depth;
    let rotation = DQuat::from_axis_angle(unit(), 0.2f64.to_radians()) * pose.rotation;
    nrw_colmap::pose::Rigid3 {
        rotation,
        translation: -(rotation * centre),
    }
}

/// The same scene at other moments: the spec's cameras (they are drawn from its seed alone)
/// under the times of day rotated by one and twice the people, so each photo has a twin
/// taken from its very place that is another picture — what near-duplicate search must not
/// group.
pub fn other_moments(spec: &crate::SceneSpec) -> crate::SceneSpec {
    let mut other = spec.clone();
    if let Some(a) = other.effects.appearance.as_mut() {
        a.rotate_left(1);
    }
    other.effects.transients = Some(other.effects.transients.unwrap_or(1.0) * 2.0);
    other
}

/// Add every `every`-th photo of `twin` (a scene made by [`other_moments`] from this scene's
/// spec) to the scene at `scene` as `moment_NAME`, at its counterpart's pose nudged as SfM
/// would: distinct pictures from one place. Returns the (counterpart, twin) name pairs.
pub fn plant_other_moments(
    scene: &Path,
    twin: &Path,
    every: usize,
    depth: f64,
    seed: u64,
) -> Result<Vec<(String, String)>> {
    let sparse = scene.join("sparse/0");
    let mut rec = read(scene)?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let originals = generated(&rec, every);
    let first = rec.images.keys().max().copied().unwrap_or(0) + 1;
    let mut pairs = Vec::new();
    for (next_image, img) in (first..).zip(originals) {
        let name = format!("moment_{}", img.name);
        let (from, to) = (
            twin.join("images").join(&img.name),
            scene.join("images").join(&name),
        );
        std::fs::copy(&from, &to).map_err(|source| SynthError::Io {
            path: from.clone(),
            source,
        })?;
        rec.images.insert(
            next_image,
            Image {
                id: next_image,
                name: name.clone(),
                camera_id: img.camera_id,
                cam_from_world: nudged(&img.cam_from_world, depth, &mut rng),
                stored_quat_norm: 1.0,
                points2d: Vec::new(),
            },
        );
        pairs.push((img.name.clone(), name));
    }
    write(&rec, &sparse)?;
    Ok(pairs)
}

/// Every `every`-th photo the generator made (never one planted here).
fn generated(rec: &Reconstruction, every: usize) -> Vec<Image> {
    rec.images
        .values()
        .filter(|i| !PLANTED.iter().any(|p| i.name.starts_with(p)))
        .step_by(every.max(1))
        .cloned()
        .collect()
}

/// Name prefixes of planted photos.
const PLANTED: [&str; 2] = ["copy_", "moment_"];

fn read(scene: &Path) -> Result<Reconstruction> {
    nrw_colmap::read_scene(scene).map_err(|e| SynthError::Spec {
        file: scene.join("sparse/0").display().to_string(),
        problem: e.to_string(),
    })
}

fn write(rec: &Reconstruction, sparse: &Path) -> Result<()> {
    for f in [Format::Binary, Format::Text] {
        nrw_colmap::write_model(rec, sparse, f).map_err(|source| SynthError::Io {
            path: sparse.to_path_buf(),
            source,
        })?;
    }
    Ok(())
}

/// Plant one copy of every `every`-th image of the scene at `scene` (its
/// `sparse/0` and `images/`), kinds in [`KINDS`] order; `depth` is the scene's typical
/// viewing distance (the scale of the pose noise). Returns what was planted.
pub fn plant_copies(scene: &Path, every: usize, depth: f64, seed: u64) -> Result<Vec<Planted>> {
    let sparse = scene.join("sparse/0");
    let mut rec = read(scene)?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let originals = generated(&rec, every);
    let (mut next_image, mut next_camera) = (
        rec.images.keys().max().copied().unwrap_or(0) + 1,
        rec.cameras.keys().max().copied().unwrap_or(0) + 1,
    );
    let mut planted = Vec::new();
    for (k, img) in originals.iter().enumerate() {
        let kind = KINDS[k % KINDS.len()];
        let path = scene.join("images").join(&img.name);
        let photo = image::open(&path)
            .map_err(|source| SynthError::Image {
                path: path.clone(),
                source,
            })?
            .to_rgb8();
        let (pixels, mut camera) = make(&photo, &rec.cameras[&img.camera_id], kind);
        camera.id = next_camera;
        let stem = Path::new(&img.name)
            .file_stem()
            .map_or("", |s| s.to_str().unwrap_or(""));
        let copy = match kind {
            CopyKind::Identical => format!("copy_{}", img.name),
            CopyKind::Reencoded(_) => format!("copy_{stem}.jpg"),
            _ => format!("copy_{stem}.png"),
        };
        let out = scene.join("images").join(&copy);
        match kind {
            CopyKind::Identical => {
                std::fs::copy(&path, &out)
                    .map(|_| ())
                    .map_err(|source| SynthError::Io {
                        path: out.clone(),
                        source,
                    })?
            }
            CopyKind::Reencoded(q) => {
                let file = std::fs::File::create(&out).map_err(|source| SynthError::Io {
                    path: out.clone(),
                    source,
                })?;
                image::codecs::jpeg::JpegEncoder::new_with_quality(file, q)
                    .encode_image(&pixels)
                    .map_err(|source| SynthError::Image {
                        path: out.clone(),
                        source,
                    })?;
            }
            _ => pixels.save(&out).map_err(|source| SynthError::Image {
                path: out.clone(),
                source,
            })?,
        }
        rec.images.insert(
            next_image,
            Image {
                id: next_image,
                name: copy.clone(),
                camera_id: next_camera,
                cam_from_world: nudged(&img.cam_from_world, depth, &mut rng),
                stored_quat_norm: 1.0,
                points2d: Vec::new(),
            },
        );
        rec.cameras.insert(next_camera, camera);
        planted.push(Planted {
            original: img.name.clone(),
            copy,
            kind,
        });
        next_image += 1;
        next_camera += 1;
    }
    write(&rec, &sparse)?;
    Ok(planted)
}
