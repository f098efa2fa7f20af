//! Near-duplicates: kept photos that are one picture — the same upload twice, resized,
//! re-encoded, cropped or recoloured copies. Where the model puts two cameras at one place
//! looking one way, their pixels aligned through those cameras decide (a crop's hash is
//! another picture's, but COLMAP registers a crop where its original is; a photo from the
//! same spot at another moment can hash close but does not correlate); elsewhere perceptual
//! hashes a few bits apart do. Pairs join into groups (union-find); split keeps a group on
//! one side. The defaults come from docs/bench/duplicates.md's synthetic collection.

use std::collections::BTreeMap;
use std::path::Path;

use nrw_colmap::{Camera, Reconstruction};
use nrw_dataset::duplicates::Member;
use nrw_dataset::{ImageOutcome, PhotoSignals};
use rayon::prelude::*;

use super::signals::{area_resize, grey, Grey};
use crate::error::Result;

/// Where two photos count as one picture; the defaults are what `ingest` uses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DuplicateOptions {
    /// Hashes at most this many bits apart (of 64) are one picture.
    pub phash_bits: u32,
    /// Cameras whose centres are closer than this fraction of their nearer view's mean
    /// rendered depth, and
    pub centre_fraction: f64,
    /// whose optical axes are within this many degrees, are compared pixel by pixel;
    pub max_degrees: f64,
    /// one picture when the aligned grey levels correlate at least this much
    pub min_ncc: f64,
    /// over at least this fraction of the smaller view's pixels,
    pub min_overlap: f64,
    /// compared at this longest side in pixels (each photo averaged down to it).
    pub working_side: usize,
}

impl Default for DuplicateOptions {
    fn default() -> Self {
        DuplicateOptions {
            phash_bits: 6,
            centre_fraction: 0.05,
            max_degrees: 5.0,
            min_ncc: 0.87,
            min_overlap: 0.5,
            working_side: 80,
        }
    }
}

/// Grey level spread under which a photo is flat (black, white, one colour): its hash says
/// nothing, and it is in no group.
pub const FLAT_STD: f64 = 1.0;

/// One kept photo as the search sees it.
#[derive(Debug, Clone)]
pub struct Photo<'a> {
    pub image_id: u32,
    pub name: &'a str,
    pub signals: PhotoSignals,
    pub camera: &'a Camera,
    pub pose: &'a nrw_colmap::pose::Rigid3,
    /// Mean of the view's rendered depth range (the scale of "the same place").
    pub depth: f64,
}

/// What the search measured for one candidate pair (the benchmark's curve reads these).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PairScore {
    pub a: u32,
    pub b: u32,
    pub phash_distance: u32,
    /// The cameras are at one place looking one way (by the options' gate).
    pub same_place: bool,
    /// Correlation and overlap of the aligned pixels, when compared.
    pub ncc: Option<(f64, f64)>,
}

impl PairScore {
    /// Whether the pair is one picture under these options: where the cameras are at one
    /// place the aligned pixels decide (they see what the hash cannot: a crop is a copy, a
    /// photo from the same spot at another moment is not); elsewhere the hashes do.
    pub fn is_duplicate(&self, o: &DuplicateOptions) -> bool {
        match self.ncc {
            Some((ncc, overlap)) => ncc >= o.min_ncc && overlap >= o.min_overlap,
            None => self.phash_distance <= o.phash_bits,
        }
    }
}

/// The kept photos with what the search needs, from the model and ingest's outcomes.
pub fn photos<'a>(
    rec: &'a Reconstruction,
    outcomes: &'a BTreeMap<u32, ImageOutcome>,
) -> Vec<Photo<'a>> {
    outcomes
        .iter()
        .filter(|(_, o)| o.verdict == nrw_dataset::VERDICT_KEPT)
        .filter_map(|(id, o)| {
            let img = rec.images.get(id)?;
            let signals = o.signals?;
            (signals.luma_std >= FLAT_STD).then_some(())?;
            Some(Photo {
                image_id: *id,
                name: &img.name,
                signals,
                camera: rec.cameras.get(&img.camera_id)?,
                pose: &img.cam_from_world,
                // An empty render has no depth: then only one exact place counts as the same.
                depth: o.depth_range.map_or(0.0, |(lo, hi)| (lo + hi) / 2.0),
            })
        })
        .collect()
}

/// Whether two cameras are at one place looking one way.
fn same_place(a: &Photo, b: &Photo, o: &DuplicateOptions) -> bool {
    let d = (a.pose.centre() - b.pose.centre()).length();
    let axis = |p: &Photo| p.pose.rotation.inverse() * glam::DVec3::Z;
    let cos = axis(a).dot(axis(b)).clamp(-1.0, 1.0);
    d <= o.centre_fraction * a.depth.min(b.depth) && cos.acos().to_degrees() <= o.max_degrees
}

/// A candidate pair: indices `i < j` into the photos, their hashes' distance in bits and
/// whether the cameras are at one place.
type Candidate = (usize, usize, u32, bool);

/// Pairs of photo `i` with a later photo worth a look: hashes within twice the accepting
/// distance, or one place. Made as they are needed, never held: candidates can be a share of
/// all N² pairs.
fn candidates_of<'p>(
    photos: &'p [Photo],
    i: usize,
    o: &'p DuplicateOptions,
) -> impl Iterator<Item = Candidate> + 'p {
    (i + 1..photos.len()).filter_map(move |j| {
        let (a, b) = (&photos[i], &photos[j]);
        let bits = (a.signals.phash ^ b.signals.phash).count_ones();
        let place = same_place(a, b, o);
        (bits <= 2 * o.phash_bits || place).then_some((i, j, bits, place))
    })
}

/// A grey image averaged down so its longest side is at most `side`.
fn shrink(g: &Grey, side: usize) -> (Vec<f32>, usize, usize) {
    let f = (g.width.max(g.height) as f64 / side.max(1) as f64).max(1.0);
    let (w, h) = (
        ((g.width as f64 / f).round() as usize).max(1),
        ((g.height as f64 / f).round() as usize).max(1),
    );
    let v = area_resize(g, w, h).into_iter().map(|v| v as f32).collect();
    (v, w, h)
}

/// A photo at working size, with its camera and pose.
struct Working<'a> {
    grey: Vec<f32>,
    w: usize,
    h: usize,
    photo: &'a Photo<'a>,
}

impl Working<'_> {
    /// Bilinear grey level at a full-size pixel position, if inside.
    fn sample(&self, full: glam::DVec2) -> Option<f64> {
        let x = full.x * self.w as f64 / self.photo.camera.width as f64 - 0.5;
        let y = full.y * self.h as f64 / self.photo.camera.height as f64 - 0.5;
        if !(x >= 0.0 && y >= 0.0 && x <= (self.w - 1) as f64 && y <= (self.h - 1) as f64) {
            return None;
        }
        let (x0, y0) = (x.floor() as usize, y.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(self.w - 1), (y0 + 1).min(self.h - 1));
        let (fx, fy) = (x - x0 as f64, y - y0 as f64);
        let g = |x: usize, y: usize| self.grey[y * self.w + x] as f64;
        Some(
            (g(x0, y0) * (1.0 - fx) + g(x1, y0) * fx) * (1.0 - fy)
                + (g(x0, y1) * (1.0 - fx) + g(x1, y1) * fx) * fy,
        )
    }
}

/// Correlation of `from`'s pixels with where they land in `to` (a rotation between the two
/// cameras, the centres taken as one), and the fraction of `from`'s pixels that land in it.
/// The pixel pairs are made twice (count and sums, then co-moments) rather than held: a
/// group of m copies compares m² pairs, and nothing a comparison makes outlives it.
fn aligned_ncc(from: &Working, to: &Working) -> (f64, f64) {
    let (mut n, mut sum_a, mut sum_b) = (0usize, 0.0, 0.0);
    aligned_pairs(from, to, &mut |a, b| {
        n += 1;
        sum_a += a;
        sum_b += b;
    });
    let overlap = n as f64 / (from.w * from.h) as f64;
    if n < 16 {
        return (0.0, overlap);
    }
    let (ma, mb) = (sum_a / n as f64, sum_b / n as f64);
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    aligned_pairs(from, to, &mut |a, b| {
        sab += (a - ma) * (b - mb);
        saa += (a - ma) * (a - ma);
        sbb += (b - mb) * (b - mb);
    });
    (pearson(sab, saa, sbb), overlap)
}

/// Calls `f` with each of `from`'s grey levels and the level where it lands in `to`, in
/// `from`'s row order.
fn aligned_pairs(from: &Working, to: &Working, f: &mut dyn FnMut(f64, f64)) {
    let rel = to.photo.pose.rotation * from.photo.pose.rotation.inverse();
    for v in 0..from.h {
        for u in 0..from.w {
            let full = glam::DVec2::new(
                (u as f64 + 0.5) * from.photo.camera.width as f64 / from.w as f64,
                (v as f64 + 0.5) * from.photo.camera.height as f64 / from.h as f64,
            );
            let hit = from
                .photo
                .camera
                .cam_ray_from_img(full)
                .and_then(|ray| to.photo.camera.img_from_cam(rel * ray))
                .and_then(|p| to.sample(p));
            if let Some(t) = hit {
                f(from.grey[v * from.w + u] as f64, t);
            }
        }
    }
}

/// Pearson correlation from the co-moments about the means; 0 when either side is flat.
fn pearson(sab: f64, saa: f64, sbb: f64) -> f64 {
    if saa <= 1e-9 || sbb <= 1e-9 {
        return 0.0;
    }
    sab / (saa * sbb).sqrt()
}

/// Score every candidate pair; photos are read from `photos_dir` (the one checked join of a
/// model's name into a path) only when a pair needs their pixels.
pub fn score_pairs(
    photos: &[Photo],
    photos_dir: &Path,
    o: &DuplicateOptions,
) -> Result<Vec<PairScore>> {
    scored(photos, photos_dir, o, &|_| true)
}

/// The candidate pairs that are one picture ([`PairScore::is_duplicate`]): what
/// [`groups`] joins, kept without holding the other candidates.
pub fn duplicate_pairs(
    photos: &[Photo],
    photos_dir: &Path,
    o: &DuplicateOptions,
) -> Result<Vec<PairScore>> {
    scored(photos, photos_dir, o, &|s| s.is_duplicate(o))
}

/// The candidate pairs' scores that `keep` keeps, each pair scored as it is made.
fn scored(
    photos: &[Photo],
    photos_dir: &Path,
    o: &DuplicateOptions,
    keep: &(dyn Fn(&PairScore) -> bool + Sync),
) -> Result<Vec<PairScore>> {
    let working = working_photos(photos, photos_dir, o)?;
    Ok((0..photos.len())
        .into_par_iter()
        .flat_map_iter(|i| {
            candidates_of(photos, i, o)
                .map(|c| score(photos, &working, c))
                .filter(|s| keep(s))
        })
        .collect())
}

/// The photos some pair at one place compares pixel by pixel, at working size.
fn working_photos<'a>(
    photos: &'a [Photo],
    photos_dir: &Path,
    o: &DuplicateOptions,
) -> Result<BTreeMap<usize, Working<'a>>> {
    let mut needed: Vec<usize> = (0..photos.len())
        .into_par_iter()
        .flat_map_iter(|i| {
            candidates_of(photos, i, o)
                .filter(|p| p.3)
                .flat_map(|p| [p.0, p.1])
        })
        .collect();
    needed.sort_unstable();
    needed.dedup();
    needed
        .par_iter()
        .map(|&i| -> Result<(usize, Working)> {
            let path = nrw_colmap::names::photo_path(photos_dir, photos[i].name, false)
                .map_err(|e| crate::error::PipelineError::input(photos_dir, e))?;
            let photo = nrw_dataset::codec::load_photo(&path)?;
            let (grey, w, h) = shrink(&grey(&photo), o.working_side);
            Ok((
                i,
                Working {
                    grey,
                    w,
                    h,
                    photo: &photos[i],
                },
            ))
        })
        .collect()
}

/// One candidate's score: its hash distance, and at one place the aligned correlation.
fn score(photos: &[Photo], working: &BTreeMap<usize, Working>, c: Candidate) -> PairScore {
    let (i, j, bits, place) = c;
    let ncc = place.then(|| {
        let (a, b) = (&working[&i], &working[&j]);
        let (ab, ba) = (aligned_ncc(a, b), aligned_ncc(b, a));
        if ab.1 >= ba.1 {
            ab
        } else {
            ba
        }
    });
    PairScore {
        a: photos[i].image_id,
        b: photos[j].image_id,
        phash_distance: bits,
        same_place: place,
        ncc,
    }
}

/// Groups of photos joined by duplicate pairs, each member with the pair that joined it.
pub fn groups(photos: &[Photo], scores: &[PairScore], o: &DuplicateOptions) -> Vec<Member> {
    let mut parent: BTreeMap<u32, u32> = BTreeMap::new();
    fn root(parent: &mut BTreeMap<u32, u32>, x: u32) -> u32 {
        let p = *parent.get(&x).unwrap_or(&x);
        if p == x {
            return x;
        }
        let r = root(parent, p);
        parent.insert(x, r);
        r
    }
    let mut evidence: BTreeMap<u32, &PairScore> = BTreeMap::new();
    for s in scores.iter().filter(|s| s.is_duplicate(o)) {
        let (ra, rb) = (root(&mut parent, s.a), root(&mut parent, s.b));
        if ra != rb {
            parent.insert(ra.max(rb), ra.min(rb));
        }
        let (lo, hi) = (s.a.min(s.b), s.a.max(s.b));
        evidence.entry(hi).or_insert(s);
        evidence.entry(lo).or_insert(s);
    }
    let names: BTreeMap<u32, &str> = photos.iter().map(|p| (p.image_id, p.name)).collect();
    let ids: Vec<u32> = evidence.keys().copied().collect();
    ids.into_iter()
        .map(|id| {
            let s = evidence[&id];
            let other = if s.a == id { s.b } else { s.a };
            let group = root(&mut parent, id);
            Member {
                image_id: id,
                name: names[&id].to_string(),
                group,
                matched_with: Some(other),
                phash_distance: Some(s.phash_distance),
                ncc: s.ncc.map(|(n, _)| n),
            }
        })
        .collect()
}
