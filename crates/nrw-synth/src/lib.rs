//! A synthetic photo collection of a landmark, in the same on-disk form as a real COLMAP
//! scene (`images/`, `sparse/0/` in both encodings, `dense/fused.ply`) plus ground truth
//! (`ground_truth/`: true depth, ADE20K labels, each photo's appearance). Photos are ray-cast
//! from the true surface; the COLMAP model is genuine (keypoints are projections plus
//! Gaussian noise, so stored reprojection errors are honest). Only effects the spec lists are
//! simulated. Deterministic: same spec and seed, same bytes, whatever the thread count.

pub mod cameras;
pub mod copies;
pub mod error;
pub mod geometry;
pub mod look;
pub mod render;
pub mod spec;
pub mod texture;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;

use glam::{DVec2, DVec3};
use nrw_colmap::pose::dot3_plus;
use nrw_colmap::{
    Format, Image, Point2D, Point3D, PointCloud, Reconstruction, TrackElement, NO_POINT3D,
};
use nrw_dataset::atomic::write_bytes_atomic;
use nrw_dataset::depth::{write_exr, DepthMap};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::Serialize;

pub use error::{Result, SynthError};
pub use render::Counters;
pub use spec::{Appearance, SceneSpec, MAX_POINTS};

use crate::cameras::Shot;
use crate::geometry::{Landmark, SurfacePoint};
use crate::look::{gauss, Look};
use crate::render::{render, Person, Sensor};
use crate::texture::{hash64, to_srgb8};

/// What a generated scene holds, and which simulation stages ran how often.
#[derive(Debug, Clone, Serialize)]
pub struct SynthReport {
    /// Where the scene was written (left out of report.json so bytes do not depend on it).
    #[serde(skip)]
    pub out: PathBuf,
    pub photos: usize,
    pub small_photos: usize,
    pub away_photos: usize,
    pub sparse_points: usize,
    pub observations: usize,
    pub dense_points: usize,
    /// Mean over observations of the keypoint noise actually added (px).
    pub mean_reprojection_error_px: Option<f64>,
    pub counters: BTreeMap<&'static str, u64>,
}

/// Where a synthetic scene keeps its ground truth, relative to the scene folder: one name for
/// the generator, the pipeline files that read the labels and the QA report.
pub mod truth {
    /// True depth per photo, `STEM.exr`.
    pub const DEPTH: &str = "ground_truth/depth";
    /// ADE20K label maps per photo, `STEM.png` (what `ingest --semantics` reads).
    pub const SEMANTICS: &str = "ground_truth/semantics";
    /// Each photo's true appearance ([`super::PhotoTruth`]).
    pub const APPEARANCE: &str = "ground_truth/appearance.json";
    /// The floating points the generator added ([`super::spec`]'s outliers).
    pub const OUTLIERS: &str = "ground_truth/outliers.json";
    /// The generator's report.
    pub const REPORT: &str = "ground_truth/report.json";
}

/// Ground truth of one photo, as written to ground_truth/appearance.json.
#[derive(Debug, Clone, Serialize)]
pub struct PhotoTruth {
    pub image_id: u32,
    pub name: String,
    /// Time of day, or "neutral" when the spec simulates none.
    pub label: String,
    pub look: Look,
    pub people: Vec<Person>,
    pub small: bool,
    pub away: bool,
    pub width: u64,
    pub height: u64,
}

struct PhotoResult {
    truth: PhotoTruth,
    /// (feature index, keypoint, |noise|)
    observed: Vec<(usize, DVec2, f64)>,
    extras: Vec<DVec2>,
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> SynthError + '_ {
    move |e| SynthError::Io {
        path: path.to_path_buf(),
        source: e,
    }
}

/// Append round(`fraction` · n) floating points to a cloud of n surface points: uniform in
/// the cloud's bounding box grown by a tenth on every side, white (the "floating white
/// geometry" of multi-view stereo), random unit normals. Returns how many were added.
fn add_outliers(cloud: &mut PointCloud, fraction: f64, rng: &mut ChaCha8Rng) -> usize {
    let n = (fraction.max(0.0) * cloud.len() as f64).round() as usize;
    if n == 0 || cloud.positions.is_empty() {
        return 0;
    }
    let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    for p in &cloud.positions {
        lo = lo.min(*p);
        hi = hi.max(*p);
    }
    let pad = (hi - lo) * 0.1;
    let (lo, hi) = (lo - pad, hi + pad);
    for _ in 0..n {
        let t = DVec3::new(rng.random(), rng.random(), rng.random());
        cloud.positions.push(lo + (hi - lo) * t);
        let d = DVec3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        )
        .normalize_or(DVec3::Z);
        if let Some(c) = cloud.colors.as_mut() {
            c.push([245, 245, 245]);
        }
        if let Some(nm) = cloud.normals.as_mut() {
            nm.push(d.as_vec3().to_array());
        }
    }
    n
}

fn seed_for(seed: u64, stream: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(hash64(seed ^ hash64(stream)))
}

fn encode(
    path: &Path,
    w: usize,
    h: usize,
    data: &[u8],
    color: image::ExtendedColorType,
    jpeg: Option<u8>,
) -> Result<()> {
    use image::ImageEncoder;
    let mut bytes = Vec::new();
    let err = |e| SynthError::Image {
        path: path.to_path_buf(),
        source: e,
    };
    match jpeg {
        Some(q) => image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, q)
            .write_image(data, w as u32, h as u32, color)
            .map_err(err)?,
        None => image::codecs::png::PngEncoder::new(&mut bytes)
            .write_image(data, w as u32, h as u32, color)
            .map_err(err)?,
    }
    write_bytes_atomic(path, &bytes)?;
    Ok(())
}

/// Which features a photo sees (unoccluded, in frame) and their noisy keypoints.
fn observe<R: Rng>(
    shot: &Shot,
    depth: &[f32],
    features: &[SurfacePoint],
    noise_px: f64,
    rng: &mut R,
) -> Vec<(usize, DVec2, f64)> {
    let (w, h) = (shot.camera.width as f64, shot.camera.height as f64);
    let mut out = Vec::new();
    let fold = shot.camera.injective_radius();
    for (k, f) in features.iter().enumerate() {
        let cam = shot.pose.transform(f.p);
        if cam.z <= 0.0 || shot.camera.normalized_radius(cam) > fold {
            continue; // beyond the lens's fold: its pixel belongs to another direction
        }
        let Some(px) = shot.camera.img_from_cam(cam) else {
            continue;
        };
        if !(px.x >= 1.0 && px.y >= 1.0 && px.x < w - 1.0 && px.y < h - 1.0) {
            continue;
        }
        let d = depth[px.y as usize * shot.camera.width as usize + px.x as usize] as f64;
        // Visible when the true depth at its pixel is the point's own (else occluded).
        if !(d > 0.0 && (d - cam.z).abs() <= 0.01 * cam.z + 0.02) {
            continue;
        }
        let noise = DVec2::new(gauss(rng), gauss(rng)) * noise_px;
        out.push((k, px + noise, noise.length()));
    }
    out
}

/// Generate the scene a spec describes into `out`; `progress` is called once per finished photo.
pub fn generate(spec: &SceneSpec, out: &Path, progress: &(dyn Fn() + Sync)) -> Result<SynthReport> {
    spec.validate("scene spec")?;
    let mut landmark = Landmark::new(&spec.geometry);
    landmark.texture = spec.effects.texture;
    let ext = if spec.effects.jpeg_quality.is_some() {
        "jpg"
    } else {
        "png"
    };
    let shots = cameras::shots(&spec.cameras, &landmark, ext, &mut seed_for(spec.seed, 1));
    let features = landmark.sample_surface(spec.observations.features, &mut seed_for(spec.seed, 2));
    for d in [
        "images",
        "sparse/0",
        "dense",
        truth::DEPTH,
        truth::SEMANTICS,
    ] {
        let p = out.join(d);
        std::fs::create_dir_all(&p).map_err(io(&p))?;
    }
    let scene = Scene {
        spec,
        landmark: &landmark,
        features: &features,
        out,
    };
    let counters = Counters::default();
    let results: Vec<PhotoResult> = shots
        .par_iter()
        .enumerate()
        .map(|(i, shot)| {
            let r = scene.photo(i, shot, &counters)?;
            progress();
            Ok(r)
        })
        .collect::<Result<Vec<_>>>()?;
    let (rec, observations) = scene.sparse_model(&shots, &results)?;
    let dense_points = scene.dense_cloud()?;
    let report = SynthReport {
        out: out.to_path_buf(),
        photos: shots.len(),
        small_photos: shots.iter().filter(|s| s.small).count(),
        away_photos: shots.iter().filter(|s| s.away).count(),
        sparse_points: rec.points.len(),
        observations: observations.count,
        dense_points,
        mean_reprojection_error_px: (observations.count > 0)
            .then(|| observations.error_sum / observations.count as f64),
        counters: counters.snapshot(),
    };
    scene.write_truth(&results, &report)?;
    Ok(report)
}

/// What every step of [`generate`] reads: the spec, its landmark, the features SfM may
/// observe, and the scene folder.
struct Scene<'a> {
    spec: &'a SceneSpec,
    landmark: &'a Landmark,
    features: &'a [SurfacePoint],
    out: &'a Path,
}

/// The observations that became track elements: how many, and the sum of their noise (px).
struct Observations {
    count: usize,
    error_sum: f64,
}

impl Scene<'_> {
    /// One photo: rendered with its look and people, its photo, true depth and labels written,
    /// the features it observes.
    fn photo(&self, i: usize, shot: &Shot, counters: &Counters) -> Result<PhotoResult> {
        let (spec, fx) = (self.spec, &self.spec.effects);
        let mut rng = seed_for(spec.seed, 0x1000 + i as u64);
        let look = Look::draw(fx, &mut rng);
        let people = match fx.transients {
            Some(mean) => Person::draw(mean, shot, &mut rng),
            None => Vec::new(),
        };
        let buf = render(
            self.landmark,
            shot,
            &look,
            &people,
            &Sensor {
                noise: fx.noise,
                noise_seed: hash64(spec.seed ^ (i as u64 + 1)),
                pixel_samples: spec.cameras.pixel_samples.max(1),
            },
            counters,
        );
        let observed = observe(
            shot,
            &buf.depth,
            self.features,
            spec.observations.noise_px,
            &mut rng,
        );
        let n_extra = (observed.len() as f64 * spec.observations.extra_keypoints).round() as usize;
        let extras = (0..n_extra)
            .map(|_| {
                DVec2::new(
                    rng.random_range(0.0..buf.width as f64),
                    rng.random_range(0.0..buf.height as f64),
                )
            })
            .collect();
        self.write_photo(shot, buf)?;
        if fx.jpeg_quality.is_some() {
            counters.jpeg_photos.fetch_add(1, Ordering::Relaxed);
        } else {
            counters.png_photos.fetch_add(1, Ordering::Relaxed);
        }
        let label = look.appearance.map_or("neutral", |a| a.label()).to_string();
        Ok(PhotoResult {
            truth: PhotoTruth {
                image_id: shot.image_id,
                name: shot.name.clone(),
                label,
                look,
                people,
                small: shot.small,
                away: shot.away,
                width: shot.camera.width,
                height: shot.camera.height,
            },
            observed,
            extras,
        })
    }

    /// A rendered photo's three files: the photo, its true depth (EXR) and its labels (PNG).
    fn write_photo(&self, shot: &Shot, buf: render::PhotoBuffers) -> Result<()> {
        let out = self.out;
        encode(
            &out.join("images").join(&shot.name),
            buf.width,
            buf.height,
            &buf.rgb,
            image::ExtendedColorType::Rgb8,
            self.spec.effects.jpeg_quality,
        )?;
        let stem = Path::new(&shot.name).with_extension("");
        let stem = stem.to_string_lossy();
        write_exr(
            &out.join(truth::DEPTH).join(format!("{stem}.exr")),
            &DepthMap {
                width: buf.width,
                height: buf.height,
                data: buf.depth,
            },
        )?;
        encode(
            &out.join(truth::SEMANTICS).join(format!("{stem}.png")),
            buf.width,
            buf.height,
            &buf.semantics,
            image::ExtendedColorType::L8,
            None,
        )
    }

    /// The COLMAP model, written in both encodings: a feature seen by two or more photos
    /// becomes a 3D point, and every photo an image with its keypoints.
    fn sparse_model(
        &self,
        shots: &[Shot],
        results: &[PhotoResult],
    ) -> Result<(Reconstruction, Observations)> {
        let point_id = self.point_ids(results);
        let origin = DVec3::from_array(self.spec.geometry.origin);
        let mut rec = Reconstruction::default();
        let mut points: BTreeMap<u64, Point3D> = BTreeMap::new();
        let mut seen = Observations {
            count: 0,
            error_sum: 0.0,
        };
        for (shot, r) in shots.iter().zip(results) {
            rec.cameras
                .entry(shot.camera_id)
                .or_insert_with(|| shot.camera.clone());
            let mut points2d = Vec::with_capacity(r.observed.len() + r.extras.len());
            for (k, xy, e) in &r.observed {
                let pid = point_id[*k];
                if pid != NO_POINT3D {
                    let p = points
                        .entry(pid)
                        .or_insert_with(|| self.point(pid, &self.features[*k], origin));
                    p.track.push(TrackElement {
                        image_id: shot.image_id,
                        point2d_idx: points2d.len() as u32,
                    });
                    p.error += e; // summed here, divided by track length below
                    seen.error_sum += e;
                    seen.count += 1;
                }
                points2d.push(Point2D {
                    xy: *xy,
                    point3d_id: pid,
                });
            }
            points2d.extend(r.extras.iter().map(|xy| Point2D {
                xy: *xy,
                point3d_id: NO_POINT3D,
            }));
            rec.images
                .insert(shot.image_id, image_of(shot, origin, points2d));
        }
        for p in points.values_mut() {
            p.error /= p.track.len() as f64;
        }
        rec.points = points;
        let sparse = self.out.join("sparse/0");
        for f in [Format::Binary, Format::Text] {
            nrw_colmap::write_model(&rec, &sparse, f).map_err(io(&sparse))?;
        }
        Ok((rec, seen))
    }

    /// Each feature's 3D point id: ids from 1 in feature order for those two or more photos
    /// observe, `NO_POINT3D` for the rest.
    fn point_ids(&self, results: &[PhotoResult]) -> Vec<u64> {
        let mut seen = vec![0usize; self.features.len()];
        for r in results {
            for (k, _, _) in &r.observed {
                seen[*k] += 1;
            }
        }
        let mut point_id = vec![NO_POINT3D; self.features.len()];
        let mut next = 1u64;
        for (k, n) in seen.iter().enumerate() {
            if *n >= 2 {
                point_id[k] = next;
                next += 1;
            }
        }
        point_id
    }

    /// A feature's 3D point, in world coordinates shifted by `origin`, its track still empty.
    fn point(&self, id: u64, f: &SurfacePoint, origin: DVec3) -> Point3D {
        let a = self.landmark.albedo(f.material, f.p, f.normal);
        Point3D {
            id,
            xyz: f.p + origin,
            rgb: [to_srgb8(a.x), to_srgb8(a.y), to_srgb8(a.z)],
            error: 0.0,
            track: Vec::new(),
        }
    }

    /// The dense cloud (`dense/fused.ply`): the surface sampled, then the spec's outliers;
    /// how many outliers it holds goes to the ground truth. Returns the cloud's size.
    fn dense_cloud(&self) -> Result<usize> {
        let (spec, landmark, origin) = (
            self.spec,
            self.landmark,
            DVec3::from_array(self.spec.geometry.origin),
        );
        let dense = landmark.sample_surface(spec.geometry.points, &mut seed_for(spec.seed, 3));
        let mut cloud = PointCloud {
            path: self.out.join("dense/fused.ply"),
            positions: dense.iter().map(|s| s.p + origin).collect(),
            colors: Some(
                dense
                    .iter()
                    .map(|s| {
                        let a = landmark.albedo(s.material, s.p, s.normal);
                        [to_srgb8(a.x), to_srgb8(a.y), to_srgb8(a.z)]
                    })
                    .collect(),
            ),
            normals: Some(
                dense
                    .iter()
                    .map(|s| s.normal.as_vec3().to_array())
                    .collect(),
            ),
        };
        let outliers = spec.effects.outliers.map_or(0, |f| {
            add_outliers(&mut cloud, f, &mut seed_for(spec.seed, 4))
        });
        nrw_colmap::write_ply(&cloud, &cloud.path).map_err(io(&cloud.path))?;
        write_bytes_atomic(
            &self.out.join(truth::OUTLIERS),
            format!(
                "{{\"surface_points\": {}, \"outliers\": {outliers}, \"note\": \"outliers are the last vertices of dense/fused.ply\"}}\n",
                cloud.len() - outliers
            )
            .as_bytes(),
        )?;
        Ok(cloud.len())
    }

    /// Each photo's true appearance, the report and the spec itself, beside the scene.
    fn write_truth(&self, results: &[PhotoResult], report: &SynthReport) -> Result<()> {
        let truths: Vec<&PhotoTruth> = results.iter().map(|r| &r.truth).collect();
        let json = |v: &dyn erased::Json, rel: &str| -> Result<()> {
            let mut text = v.to_json();
            text.push('\n');
            write_bytes_atomic(&self.out.join(rel), text.as_bytes())?;
            Ok(())
        };
        json(&truths, truth::APPEARANCE)?;
        json(report, truth::REPORT)?;
        let spec_text = toml::to_string(self.spec).expect("a spec serialises");
        write_bytes_atomic(&self.out.join("scene.toml"), spec_text.as_bytes())?;
        Ok(())
    }
}

/// A shot's COLMAP image: world→camera for world coordinates shifted by `origin`
/// (t' = t − R·origin, summed with compensated arithmetic so a georeferenced scene keeps its
/// digits).
fn image_of(shot: &Shot, origin: DVec3, points2d: Vec<Point2D>) -> Image {
    let rows = shot.pose.matrix().transpose();
    let t = shot.pose.translation;
    let mut pose = shot.pose;
    pose.translation = DVec3::new(
        dot3_plus(rows.x_axis, -origin, t.x),
        dot3_plus(rows.y_axis, -origin, t.y),
        dot3_plus(rows.z_axis, -origin, t.z),
    );
    Image {
        id: shot.image_id,
        name: shot.name.clone(),
        camera_id: shot.camera_id,
        cam_from_world: pose,
        stored_quat_norm: 1.0,
        points2d,
    }
}

mod erased {
    /// Pretty JSON of any serialisable value, behind a trait object.
    pub trait Json {
        fn to_json(&self) -> String;
    }
    impl<T: serde::Serialize> Json for T {
        fn to_json(&self) -> String {
            serde_json::to_string_pretty(self).expect("plain data serialises")
        }
    }
}
