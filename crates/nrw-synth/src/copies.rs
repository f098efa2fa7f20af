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
    /// A quarter turn clockwise (a landscape photo uploaded as a portrait): its camera is
    /// the original's turned about the optical axis, where SfM registers such a copy.
    Rotated,
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
fn make(photo: &RgbImage, cam: &Camera, kind: CopyKind) -> Result<(RgbImage, Camera)> {
    let (w, h) = (photo.width(), photo.height());
    let same = |img: RgbImage| {
        let c = cam.scaled(1.0, 1.0, w as u64, h as u64);
        (img, c)
    };
    Ok(match kind {
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
        CopyKind::Rotated => (
            image::imageops::rotate90(photo),
            quarter_turned(&cam.scaled(1.0, 1.0, w as u64, h as u64))?,
        ),
    })
}

/// The camera of a photo turned a quarter clockwise: pixel (x, y) goes to (h − y, x) (pixel
/// centres at half integers), so the focal lengths swap and the principal point moves with
/// the pixels. Only a lens whose distortion is the same in every direction turns this way;
/// the others (tangential or thin-prism terms, panoramas) are refused.
fn quarter_turned(cam: &Camera) -> Result<Camera> {
    use nrw_colmap::CameraModel as M;
    if matches!(
        cam.model,
        M::OpenCv
            | M::FullOpenCv
            | M::ThinPrismFisheye
            | M::RadTanThinPrismFisheye
            | M::Equirectangular
    ) {
        return Err(SynthError::Spec {
            file: format!("camera {}", cam.id),
            problem: format!(
                "the {} lens model is not the same in every direction, so a rotated copy's camera is not its turned original",
                cam.model.name()
            ),
        });
    }
    let mut c = cam.clone();
    (c.width, c.height) = (cam.height, cam.width);
    let at = if cam.model.single_focal() {
        1
    } else {
        c.params.swap(0, 1);
        2
    };
    let (cx, cy) = (cam.params[at], cam.params[at + 1]);
    c.params[at] = cam.height as f64 - cy;
    c.params[at + 1] = cx;
    Ok(c)
}

/// The pose of a camera turned a quarter about its optical axis as [`quarter_turned`] turns
/// its pixels: camera coordinates (x, y, z) become (−y, x, z).
fn quarter_turned_pose(pose: &nrw_colmap::pose::Rigid3) -> nrw_colmap::pose::Rigid3 {
    let turn = DQuat::from_rotation_z(std::f64::consts::FRAC_PI_2);
    nrw_colmap::pose::Rigid3 {
        rotation: turn * pose.rotation,
        translation: turn * pose.translation,
    }
}

/// Where SfM registers a copy of this kind of a photo at `pose`: there, turned for a
/// rotated copy.
fn posed(pose: &nrw_colmap::pose::Rigid3, kind: CopyKind) -> nrw_colmap::pose::Rigid3 {
    match kind {
        CopyKind::Rotated => quarter_turned_pose(pose),
        _ => *pose,
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
    plant_copies_of(scene, every, depth, seed, &KINDS)
}

/// [`plant_copies`] with the kinds taken in turn from `kinds` (never empty), such as
/// [`KINDS`] and [`CopyKind::Rotated`].
pub fn plant_copies_of(
    scene: &Path,
    every: usize,
    depth: f64,
    seed: u64,
    kinds: &[CopyKind],
) -> Result<Vec<Planted>> {
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
        let kind = kinds[k % kinds.len()];
        let path = scene.join("images").join(&img.name);
        let photo = image::open(&path)
            .map_err(|source| SynthError::Image {
                path: path.clone(),
                source,
            })?
            .to_rgb8();
        let (pixels, mut camera) = make(&photo, &rec.cameras[&img.camera_id], kind)?;
        camera.id = next_camera;
        let copy = write_copy(scene, &img.name, &path, &pixels, kind)?;
        rec.images.insert(
            next_image,
            Image {
                id: next_image,
                name: copy.clone(),
                camera_id: next_camera,
                cam_from_world: nudged(&posed(&img.cam_from_world, kind), depth, &mut rng),
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

/// Write a copy of `original` (its file at `path`, `pixels` the copy's) into the scene's
/// `images/` as its kind makes it: the same file, a JPEG, or a PNG. Returns its name.
fn write_copy(
    scene: &Path,
    original: &str,
    path: &Path,
    pixels: &RgbImage,
    kind: CopyKind,
) -> Result<String> {
    let stem = Path::new(original)
        .file_stem()
        .map_or("", |s| s.to_str().unwrap_or(""));
    let copy = match kind {
        CopyKind::Identical => format!("copy_{original}"),
        CopyKind::Reencoded(_) => format!("copy_{stem}.jpg"),
        _ => format!("copy_{stem}.png"),
    };
    let out = scene.join("images").join(&copy);
    match kind {
        CopyKind::Identical => {
            std::fs::copy(path, &out)
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
                .encode_image(pixels)
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
    Ok(copy)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nrw_colmap::CameraModel;

    /// A world point lands, in the turned copy, where the turned photo's pixels put it:
    /// (x, y) in the original goes to (h − y, x), for a lens with one focal length and
    /// distortion, and for one with two focal lengths.
    #[test]
    fn a_quarter_turned_copy_sees_each_point_where_its_turned_pixels_are() {
        let pose = nrw_colmap::pose::Rigid3 {
            rotation: DQuat::from_euler(glam::EulerRot::XYZ, 0.3, -0.2, 0.1),
            translation: DVec3::new(0.4, -1.0, 5.0),
        };
        let cameras = [
            (CameraModel::SimpleRadial, vec![700.0, 310.0, 205.0, -0.12]),
            (CameraModel::Pinhole, vec![700.0, 650.0, 310.0, 205.0]),
            (
                CameraModel::OpenCvFisheye,
                vec![500.0, 520.0, 300.0, 210.0, 0.05, -0.01, 0.0, 0.0],
            ),
        ];
        for (model, params) in cameras {
            let cam = Camera {
                id: 1,
                model,
                width: 640,
                height: 400,
                params,
            };
            let turned = quarter_turned(&cam).unwrap();
            let turned_pose = quarter_turned_pose(&pose);
            assert_eq!((turned.width, turned.height), (400, 640));
            for p in [
                DVec3::new(0.0, 0.0, 0.0),
                DVec3::new(1.0, 0.5, -0.3),
                DVec3::new(-0.8, -0.4, 0.6),
            ] {
                let a = cam.img_from_cam(pose.transform(p)).unwrap();
                let b = turned.img_from_cam(turned_pose.transform(p)).unwrap();
                let want = glam::DVec2::new(cam.height as f64 - a.y, a.x);
                assert!((b - want).length() < 1e-9, "{model:?}: {b} against {want}");
            }
        }
    }

    /// A lens with tangential terms is refused, naming the model.
    #[test]
    fn a_lens_not_the_same_in_every_direction_is_not_turned() {
        let cam = Camera {
            id: 3,
            model: CameraModel::OpenCv,
            width: 640,
            height: 400,
            params: vec![700.0, 700.0, 320.0, 200.0, 0.1, 0.0, 0.01, 0.0],
        };
        let err = quarter_turned(&cam).unwrap_err().to_string();
        assert!(err.contains("camera 3") && err.contains("OPENCV"), "{err}");
    }
}
