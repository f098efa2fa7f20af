//! COLMAP 3.8's stereo fusion (`StereoFusion`): starting from each unfused pixel of each
//! image in order, a depth-first walk over the pixels its point projects to in the
//! overlapping images gathers the pixels that agree with the first one (reprojection error,
//! relative depth, normal angle); a walk of at least `min_num_pixels` becomes one point at the
//! per-coordinate median, with the median normal and colour, seen by the images it visited.
//!
//! Differences from COLMAP, each deliberate: positions and projections in f64 (COLMAP's are
//! f32), pixel centres at +0.5 (the model's convention; COLMAP's fusion uses (col, row)).
//!
//! Memory: maps are read through a [`MapReader`] in bands of [`BAND_ROWS`] rows into a
//! least-recently-used cache of a given byte budget (COLMAP's `cache_size`, used only with its
//! `use_cache`, holds whole views), so fusion holds the cache, one bit per pixel of every view
//! (fused or not) and the cloud it builds; the cloud is the same whatever the budget.

use std::collections::{BTreeMap, BTreeSet};
use std::ops::Range;

use glam::DVec3;

use crate::view::Pinhole;

/// COLMAP's `StereoFusionOptions` that this fusion reads, with COLMAP's defaults but for
/// `min_num_pixels`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FusionOptions {
    /// Least pixels (of different views) fused into a point: 2, OpenMVS's `nMinViewsFuse`
    /// (COLMAP's 5 drops every surface fewer than five photos see: see docs/densify.md).
    pub min_num_pixels: usize,
    /// Most pixels fused into a point (10000).
    pub max_num_pixels: usize,
    /// Deepest walk (100).
    pub max_traversal_depth: usize,
    /// Largest reprojection error, px (2).
    pub max_reproj_error: f64,
    /// Largest relative depth difference (0.01).
    pub max_depth_error: f64,
    /// Largest normal angle, degrees (10).
    pub max_normal_error_deg: f64,
}

impl Default for FusionOptions {
    fn default() -> Self {
        FusionOptions {
            min_num_pixels: 2,
            max_num_pixels: 10_000,
            max_traversal_depth: 100,
            max_reproj_error: 2.0,
            max_depth_error: 0.01,
            max_normal_error_deg: 10.0,
        }
    }
}

/// Where a view sits and which views a walk may step into from it: what fusion knows of a
/// view before it reads the view's maps.
#[derive(Debug, Clone)]
pub struct FusionView {
    pub lens: Pinhole,
    /// World (scene-local) → camera.
    pub rotation: glam::DMat3,
    pub translation: DVec3,
    pub width: usize,
    pub height: usize,
    /// The views (indices into the view list) a walk may step into from this one.
    pub overlapping: Vec<usize>,
}

/// Rows of a view that fusion reads and holds as one piece: walks from neighbouring pixels
/// step into neighbouring rows of the other views, so a cache of bands keeps what the next
/// walks need where a cache of whole views smaller than the scene reads views again.
pub const BAND_ROWS: usize = 16;

/// The bands of a view `height` rows tall.
pub fn bands_of(height: usize) -> usize {
    height.div_ceil(BAND_ROWS)
}

/// Some whole rows of a view's final maps, read when a walk needs them and dropped when the
/// cache is full.
#[derive(Debug, Clone, Default)]
pub struct FusionMaps {
    /// Depth per pixel (0 = none), row-major.
    pub depth: Vec<f32>,
    /// Unit normal per pixel in camera coordinates.
    pub normal: Vec<[f32; 3]>,
    /// 8-bit RGB per pixel.
    pub rgb: Vec<u8>,
}

impl FusionMaps {
    /// The bytes these maps hold (what the cache budget counts).
    pub fn bytes(&self) -> usize {
        self.depth.len() * 4 + self.normal.len() * 12 + self.rgb.len()
    }

    /// The bytes the maps of a view of `pixels` pixels hold (depth, normal, colour).
    pub fn bytes_for(pixels: usize) -> usize {
        pixels * (4 + 12 + 3)
    }
}

/// Reads part of a view's maps on demand, so that fusion holds only the bands its cache has
/// room for.
pub trait MapReader {
    type Error;
    /// The maps of the pixels `pixels` (row-major indices `y × width + x`, whole rows) of view
    /// `view` (an index into the view list).
    fn read(&mut self, view: usize, pixels: Range<usize>) -> Result<FusionMaps, Self::Error>;
}

/// Maps already in memory (tests, small scenes): every read is a copy.
impl MapReader for [FusionMaps] {
    type Error = std::convert::Infallible;
    fn read(&mut self, view: usize, pixels: Range<usize>) -> Result<FusionMaps, Self::Error> {
        let m = &self[view];
        Ok(FusionMaps {
            depth: m.depth[pixels.clone()].to_vec(),
            normal: m.normal[pixels.clone()].to_vec(),
            rgb: m.rgb[3 * pixels.start..3 * pixels.end].to_vec(),
        })
    }
}

/// What fusion's memory came to: band reads (a band read again was evicted in between), the
/// bands there are, and the most map bytes held at once.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct FusionStats {
    pub reads: usize,
    pub bands: usize,
    pub peak_bytes: usize,
}

/// A view's band: (view, band index).
type BandKey = (usize, usize);

/// The bands held, least recently used dropped first when the next read would pass the budget
/// (one band is always held, however small the budget).
struct MapCache<'r, R: MapReader + ?Sized> {
    reader: &'r mut R,
    budget: usize,
    /// Per view, per band: its maps and last use, when held.
    held: Vec<Vec<Option<(FusionMaps, u64)>>>,
    /// Each held band once, at a use no later than its last (a hit only sets the last use;
    /// eviction moves a band used since to its last use before it drops the oldest).
    order: BTreeMap<u64, BandKey>,
    bytes: usize,
    tick: u64,
    stats: FusionStats,
}

impl<'r, R: MapReader + ?Sized> MapCache<'r, R> {
    fn new(reader: &'r mut R, views: &[FusionView], budget: usize) -> Self {
        MapCache {
            reader,
            budget,
            held: views
                .iter()
                .map(|v| (0..bands_of(v.height)).map(|_| None).collect())
                .collect(),
            order: BTreeMap::new(),
            bytes: 0,
            tick: 0,
            stats: FusionStats {
                bands: views.iter().map(|v| bands_of(v.height)).sum(),
                ..FusionStats::default()
            },
        }
    }

    /// The band of view `view` (of width `width`, height `height`) holding pixel `pixel`, read
    /// if not held, and the index of its first pixel.
    fn get(
        &mut self,
        view: usize,
        (width, height): (usize, usize),
        pixel: usize,
    ) -> Result<(&FusionMaps, usize), R::Error> {
        let band = pixel / (width * BAND_ROWS);
        let first = band * width * BAND_ROWS;
        self.tick += 1;
        if self.held[view][band].is_none() {
            let end = ((band + 1) * BAND_ROWS).min(height) * width;
            let maps = self.reader.read(view, first..end)?;
            let size = maps.bytes();
            while !self.order.is_empty() && self.bytes + size > self.budget {
                self.evict_oldest();
            }
            self.stats.reads += 1;
            self.bytes += size;
            self.stats.peak_bytes = self.stats.peak_bytes.max(self.bytes);
            self.held[view][band] = Some((maps, self.tick));
            self.order.insert(self.tick, (view, band));
        }
        let (maps, used) = self.held[view][band].as_mut().expect("held above");
        *used = self.tick;
        Ok((maps, first))
    }

    fn evict_oldest(&mut self) {
        while let Some((at, (view, band))) = self.order.pop_first() {
            let used = self.held[view][band].as_ref().map_or(at, |h| h.1);
            if used > at {
                self.order.insert(used, (view, band));
                continue;
            }
            if let Some((maps, _)) = self.held[view][band].take() {
                self.bytes -= maps.bytes();
            }
            return;
        }
    }
}

/// One bit per pixel of every view: whether the pixel is fused already (what fusion keeps of
/// all views at once).
struct FusedBits(Vec<Vec<u64>>);

impl FusedBits {
    fn new(views: &[FusionView]) -> Self {
        FusedBits(
            views
                .iter()
                .map(|v| vec![0; (v.width * v.height).div_ceil(64)])
                .collect(),
        )
    }

    fn get(&self, view: usize, pixel: usize) -> bool {
        self.0[view][pixel / 64] >> (pixel % 64) & 1 == 1
    }

    fn set(&mut self, view: usize, pixel: usize) {
        self.0[view][pixel / 64] |= 1 << (pixel % 64);
    }
}

/// The fused cloud: positions in the scene-local frame, unit normals, colours, and for each
/// point the images (input indices, ascending) whose pixels it fused.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FusedCloud {
    pub positions: Vec<DVec3>,
    pub normals: Vec<[f32; 3]>,
    pub colors: Vec<[u8; 3]>,
    pub visibility: Vec<Vec<u32>>,
}

/// The angle (radians) between two vectors, from atan2 (exact for nearly parallel ones).
pub(crate) fn angle_between(a: DVec3, b: DVec3) -> f64 {
    let angle = a.cross(b).length().atan2(a.dot(b));
    angle.min(std::f64::consts::PI - angle)
}

/// COLMAP's `internal::Median`: the middle element, or the mean of the two middle ones.
fn median(values: &mut [f64]) -> f64 {
    values.sort_unstable_by(f64::total_cmp);
    let mid = values.len() / 2;
    if values.len().is_multiple_of(2) {
        (values[mid - 1] + values[mid]) / 2.0
    } else {
        values[mid]
    }
}

/// The pixels gathered by one walk.
#[derive(Default)]
struct Cluster {
    x: Vec<f64>,
    y: Vec<f64>,
    z: Vec<f64>,
    n: [Vec<f64>; 3],
    rgb: [Vec<f64>; 3],
    seen: BTreeSet<u32>,
}

/// One fused point: its position in the scene-local frame, unit normal, colour, and the
/// images (input indices, ascending) whose pixels it fused.
#[derive(Debug, Clone, PartialEq)]
pub struct FusedPoint {
    pub position: DVec3,
    pub normal: [f32; 3],
    pub colour: [u8; 3],
    pub images: Vec<u32>,
}

impl FusedCloud {
    /// Append a point.
    pub fn push(&mut self, p: FusedPoint) {
        self.positions.push(p.position);
        self.normals.push(p.normal);
        self.colors.push(p.colour);
        self.visibility.push(p.images);
    }
}

/// Fuse the views' maps into one cloud held in memory (tests, small scenes): [`fuse_into`]
/// collected.
pub fn fuse<R: MapReader + ?Sized>(
    views: &[FusionView],
    reader: &mut R,
    cache_bytes: usize,
    opts: &FusionOptions,
) -> Result<(FusedCloud, FusionStats), R::Error> {
    let mut cloud = FusedCloud::default();
    let stats = fuse_into(views, reader, cache_bytes, opts, |p| {
        cloud.push(p);
        Ok(())
    })?;
    Ok((cloud, stats))
}

/// Fuse the views' maps COLMAP's way, handing each point to `sink` as it is made, holding at
/// most `cache_bytes` of maps (and one bit per pixel of every view): the points do not depend
/// on the budget, only the reads do.
pub fn fuse_into<R: MapReader + ?Sized>(
    views: &[FusionView],
    reader: &mut R,
    cache_bytes: usize,
    opts: &FusionOptions,
    mut sink: impl FnMut(FusedPoint) -> Result<(), R::Error>,
) -> Result<FusionStats, R::Error> {
    let mut fused = FusedBits::new(views);
    let mut cache = MapCache::new(reader, views, cache_bytes);
    let mut queue: Vec<(usize, usize, usize, usize)> = Vec::new();
    for (start, view) in views.iter().enumerate() {
        for row in 0..view.height {
            for col in 0..view.width {
                if fused.get(start, row * view.width + col) {
                    continue;
                }
                queue.clear();
                queue.push((start, row, col, 0));
                let cluster = walk(views, &mut cache, &mut fused, &mut queue, opts)?;
                if let Some(point) = point_of(cluster, opts) {
                    sink(point)?;
                }
            }
        }
    }
    Ok(cache.stats)
}

/// One depth-first walk from the pixel on the queue: the pixels that agree with the first.
fn walk<R: MapReader + ?Sized>(
    views: &[FusionView],
    cache: &mut MapCache<R>,
    fused: &mut FusedBits,
    queue: &mut Vec<(usize, usize, usize, usize)>,
    opts: &FusionOptions,
) -> Result<Cluster, R::Error> {
    let min_cos_normal = opts.max_normal_error_deg.to_radians().cos();
    let max_sq_reproj = opts.max_reproj_error * opts.max_reproj_error;
    let mut cluster = Cluster::default();
    let mut reference: Option<(DVec3, DVec3)> = None;
    while let Some((i, r, c, depth_level)) = queue.pop() {
        let img = &views[i];
        let p = r * img.width + c;
        if fused.get(i, p) {
            continue;
        }
        let (maps, first) = cache.get(i, (img.width, img.height), p)?;
        let q = p - first;
        let d = maps.depth[q] as f64;
        if d.is_nan() || d <= 0.0 {
            continue;
        }
        if let Some((ref_point, _)) = reference {
            let proj = img.rotation * ref_point + img.translation;
            if ((proj.z - d) / d).abs() > opts.max_depth_error {
                continue;
            }
            let u = img.lens.project(proj);
            let (dc, dr) = (u.x - (c as f64 + 0.5), u.y - (r as f64 + 0.5));
            if dc * dc + dr * dr > max_sq_reproj {
                continue;
            }
        }
        let nc = maps.normal[q];
        let normal =
            img.rotation.transpose() * DVec3::new(nc[0] as f64, nc[1] as f64, nc[2] as f64);
        if let Some((_, ref_normal)) = reference {
            if ref_normal.dot(normal) < min_cos_normal {
                continue;
            }
        }
        let cam = img.lens.pixel_ray(c, r) * d;
        let xyz = img.rotation.transpose() * (cam - img.translation);
        fused.set(i, p);
        cluster.x.push(xyz.x);
        cluster.y.push(xyz.y);
        cluster.z.push(xyz.z);
        for k in 0..3 {
            cluster.n[k].push(normal[k]);
            cluster.rgb[k].push(maps.rgb[3 * q + k] as f64);
        }
        cluster.seen.insert(i as u32);
        if reference.is_none() {
            reference = Some((xyz, normal));
        }
        if cluster.x.len() >= opts.max_num_pixels {
            break;
        }
        let next_level = depth_level + 1;
        if next_level >= opts.max_traversal_depth {
            continue;
        }
        for &j in &img.overlapping {
            let next = &views[j];
            let proj = next.rotation * xyz + next.translation;
            if proj.z <= 0.0 {
                continue;
            }
            let u = next.lens.project(proj);
            // The pixel whose centre is nearest (centres at +0.5).
            let (nc, nr) = (u.x.floor(), u.y.floor());
            if nc < 0.0 || nr < 0.0 || nc >= next.width as f64 || nr >= next.height as f64 {
                continue;
            }
            queue.push((j, nr as usize, nc as usize, next_level));
        }
    }
    Ok(cluster)
}

/// A walk's point, if it gathered enough pixels and its normals do not cancel.
fn point_of(mut cl: Cluster, opts: &FusionOptions) -> Option<FusedPoint> {
    if cl.x.len() < opts.min_num_pixels.max(1) {
        return None;
    }
    let n = DVec3::new(
        median(&mut cl.n[0]),
        median(&mut cl.n[1]),
        median(&mut cl.n[2]),
    );
    let norm = n.length();
    if norm < f32::EPSILON as f64 {
        return None;
    }
    let n = n / norm;
    let colour = |v: &mut Vec<f64>| median(v).round().clamp(0.0, 255.0) as u8;
    let [r, g, b] = &mut cl.rgb;
    Some(FusedPoint {
        position: DVec3::new(median(&mut cl.x), median(&mut cl.y), median(&mut cl.z)),
        normal: [n.x as f32, n.y as f32, n.z as f32],
        colour: [colour(r), colour(g), colour(b)],
        images: cl.seen.into_iter().collect(),
    })
}
