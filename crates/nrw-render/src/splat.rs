//! Point splatting with a z-buffer. A point of radius r covers every pixel whose centre lies
//! within r pixels of its projection (r = 0: the pixel that contains it); the nearest point
//! wins, and equal depths go to the lower point index, so renders are deterministic.

use glam::{DVec3, Mat3, Vec3};
use nrw_colmap::{Projection, ProjectionVisitor};

use crate::cloud::{Chunk, RenderCloud, Span, CHUNK_POINTS};
use crate::occlusion::{Lens, Shadow};
use crate::simd;
use crate::view::{pinhole_pixel, View};
use crate::zbuffer::{keep_nearest, key, ZBuffer, EMPTY};

/// A render: per-pixel depth and, where the cloud has them, colour and normal.
#[derive(Debug, Clone, PartialEq)]
pub struct DeepBuffer {
    pub width: u32,
    pub height: u32,
    /// Camera-space z (not ray length), f32; 0 where no point was drawn.
    pub depth: Vec<f32>,
    /// Point colours; `None` when the cloud has none.
    pub color: Option<Vec<[u8; 3]>>,
    /// Point normals rotated into the camera frame; `None` when the cloud has none.
    pub normal: Option<Vec<[f32; 3]>>,
    /// Pixels with a point.
    pub covered: usize,
    /// Statistics: chunks and points the view had to look at.
    pub chunks_visited: usize,
    pub points_tested: usize,
    /// Of those, points skipped unprojected as hidden behind nearer ones (occlusion culling).
    pub points_hidden: usize,
}

impl DeepBuffer {
    /// Fraction of pixels without any point: the paper drops views above 0.85.
    pub fn empty_ratio(&self) -> f64 {
        1.0 - self.covered as f64 / (self.width as f64 * self.height as f64)
    }

    /// Coverage mask (1 where a point was drawn).
    pub fn mask(&self) -> Vec<u8> {
        self.depth.iter().map(|&d| (d > 0.0) as u8).collect()
    }
}

/// `v.floor() as i64` without the libm call that baseline x86-64 (no SSE4.1) makes for
/// `floor`: it was 13% of a render. Same result for every finite `v` and for NaN (0).
#[inline(always)]
fn floor_i(v: f64) -> i64 {
    let t = v as i64;
    t.saturating_sub(((t as f64) > v) as i64)
}

/// `floor(v)` for `v` that is an f32 (any, including ±∞ and NaN) widened to f64, clamped to
/// ±2^30 (far outside any image, so still outside after clamping; NaN becomes -2^30).
///
/// One truncating conversion instead of `floor_i`'s fix-up: v + 2^30 is exact in f64 for
/// |v| ≤ 2^30 with 24 significant bits, and non-negative, so truncation is the floor.
#[inline(always)]
fn floor_f32(v: f64) -> i64 {
    const OFF: f64 = (1u64 << 30) as f64;
    // Not `clamp`, which keeps NaN.
    #[allow(clippy::manual_clamp)]
    let c = v.max(-OFF).min(OFF);
    // SAFETY: c + OFF is finite and in [0, 2^31], which i64 holds.
    let t: i64 = unsafe { (c + OFF).to_int_unchecked() };
    t - (1 << 30)
}

/// Which code draws the splats. The kernels give bit-identical renders (tested); the
/// choice only exists so that tests and benchmarks can run the portable code on any CPU.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kernel {
    /// AVX2 where the CPU has it (checked once per render), else portable.
    Auto,
    /// Baseline x86-64 (SSE2) or whatever the target offers without run-time detection.
    Portable,
}

/// Camera-space depth and pixel of each point (see `pinhole_pixel`), written to `out`.
#[inline(always)]
fn project(out: &mut [[f32; 3]], pts: Span, r: Mat3, t: Vec3, k: [f32; 4]) {
    for (i, out) in out.iter_mut().enumerate() {
        let c = r * pts.get(i) + t;
        let (x, y) = pinhole_pixel(k, c);
        *out = [x, y, c.z];
    }
}

struct Splat<'a> {
    view: &'a View,
    cloud: &'a RenderCloud,
    radius: f32,
    zbuf: &'a mut ZBuffer,
    kernel: Kernel,
    chunks: usize,
    tested: usize,
    hidden: usize,
}

/// `key` when `d2 <= r2`, else NaN (which `keep_nearest` never keeps); without a branch.
#[inline(always)]
fn inside_or_nan(key: f64, d2: f64, r2: f64) -> f64 {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_cmpnle_sd, _mm_cvtsd_f64, _mm_or_pd, _mm_set_sd};
        // SAFETY: SSE2 is part of every x86_64 target; these touch registers only.
        unsafe {
            _mm_cvtsd_f64(_mm_or_pd(
                _mm_set_sd(key),
                _mm_cmpnle_sd(_mm_set_sd(d2), _mm_set_sd(r2)),
            ))
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        if d2 <= r2 {
            key
        } else {
            f64::NAN
        }
    }
}

/// A splat's radius, as the footprint loop uses it.
struct Footprint {
    r2: f64,
}

impl Footprint {
    fn of(radius: f32) -> Footprint {
        let r = radius as f64;
        Footprint { r2: r * r }
    }

    /// Draw one point centred at pixel coordinates (px, py), which lie in pixel (xc, yc)
    /// (their floors), with z-buffer `key`. `R` is the buffer's reach when it is 0 or 1 (the
    /// fixed square unrolls), `DYNAMIC` otherwise.
    #[inline(always)]
    fn draw<const R: i64>(
        &self,
        z: &mut ZBuffer,
        (px, py): (f64, f64),
        (xc, yc): (i64, i64),
        key: f64,
    ) {
        let reach = if R == DYNAMIC { z.reach } else { R };
        // A splat whose centre pixel is more than `reach` outside touches no pixel; any
        // other lies within the border, so its square is drawn whole. As unsigned
        // comparisons: -reach <= xc < w + reach (the same for y).
        let (xs, ys) = ((xc + reach) as u64, (yc + reach) as u64);
        if xs >= (z.width + 2 * reach) as u64 || ys >= (z.height + 2 * reach) as u64 {
            return;
        }
        let stride = z.stride as usize;
        // Index of the square's top-left pixel (xc - reach, yc - reach), shifted by the border.
        let corner = ys as usize * stride + xs as usize;
        // r = 0 is the pixel that contains the point (not a disc of radius 0).
        if R == 0 || (R == DYNAMIC && self.r2 == 0.0) {
            keep_nearest(&mut z.keys[corner], key);
            return;
        }
        let side = (2 * reach + 1) as usize;
        let square = &mut z.keys[corner..corner + (side - 1) * stride + side];
        if R != DYNAMIC {
            // Pinhole path (px, py are f32 values): the offsets from the pixel's corner are
            // exact, so (i - R + 0.5) - fx rounds the same real number as the definition's
            // (xc - R + i + 0.5) - px: bit-identical distances, fewer conversions. (Exact
            // except for px within 2^-30 below 0, whose px + 1 needs over 53 bits: a centre
            // that close to the image's left or top edge may round its offsets differently
            // from the definition, by an ulp; the AVX2 kernel rounds it the same way as this.)
            let (fx, fy) = (px - xc as f64, py - yc as f64);
            let d = |i: usize, f: f64| {
                let t = (i as i64 - R) as f64 + 0.5 - f;
                t * t
            };
            for j in 0..side {
                let dy2 = d(j, fy);
                let row = &mut square[j * stride..j * stride + side];
                for (i, slot) in row.iter_mut().enumerate() {
                    keep_nearest(slot, inside_or_nan(key, d(i, fx) + dy2, self.r2));
                }
            }
            return;
        }
        for j in 0..side {
            let dy = (yc - reach + j as i64) as f64 + 0.5 - py;
            let dy2 = dy * dy;
            let row = &mut square[j * stride..j * stride + side];
            for (i, slot) in row.iter_mut().enumerate() {
                let dx = (xc - reach + i as i64) as f64 + 0.5 - px;
                keep_nearest(slot, inside_or_nan(key, dx * dx + dy2, self.r2));
            }
        }
    }
}

/// `Footprint::draw`'s reach parameter when the reach is only known at run time.
const DYNAMIC: i64 = -1;

impl<'a> Splat<'a> {
    /// The chunks the view may see, counted, front to back, each with its shadow when the
    /// lens allows occlusion culling (chunks without one come first: at the camera, or wide
    /// on screen).
    fn visible(&mut self) -> Vec<(Option<Shadow>, &'a Chunk)> {
        let (v, near) = (self.view, self.cloud.near);
        let cloud: &'a RenderCloud = self.cloud;
        let mut out: Vec<(Option<Shadow>, &'a Chunk)> = cloud
            .chunks
            .iter()
            .filter(|c| v.may_see(c.min, c.max, near))
            .map(|c| (None, c))
            .collect();
        let points: usize = out.iter().map(|(_, c)| (c.end - c.start) as usize).sum();
        self.chunks += out.len();
        self.tested += points;
        // Culling pays where splats pile up: below ~8 footprints per pixel few chunks are
        // wholly hidden, and drawing front to back instead of in the cloud's (Morton) order
        // costs z-buffer locality (10⁶ points, whole views: 1-4% slower with it).
        let footprint = (std::f64::consts::PI * (self.radius as f64).powi(2)).max(1.0);
        let pixels = v.width as f64 * v.height as f64;
        let Some(lens) = Lens::of(v).filter(|_| points as f64 * footprint >= 8.0 * pixels) else {
            return out;
        };
        let reach = self.zbuf.reach;
        for (shadow, c) in &mut out {
            *shadow = Shadow::of(v, &lens, c, reach);
        }
        // (A stable sort: equal floors keep the cloud's order.)
        out.sort_by(|a, b| {
            let floor = |s: &Option<Shadow>| s.map_or(0.0, |s| s.floor);
            floor(&a.0).total_cmp(&floor(&b.0))
        });
        out
    }

    /// Whether a chunk (or a piece of one) of `points` is hidden behind what is drawn
    /// already; hidden points are counted.
    fn hidden(&mut self, shadow: &Option<Shadow>, points: usize) -> bool {
        let hidden = shadow.is_some_and(|s| s.hidden(self.zbuf));
        self.hidden += if hidden { points } else { 0 };
        hidden
    }

    /// The splat loop over visible chunks, generic over how a camera-space point projects.
    fn run<F: Fn(Vec3) -> Option<(f64, f64)>>(mut self, project: F) -> (usize, usize, usize) {
        let v = self.view;
        let near = self.cloud.near;
        let fp = Footprint::of(self.radius);
        let cloud: &'a RenderCloud = self.cloud;
        let avx2 = self.kernel == Kernel::Auto && simd::fits(self.zbuf);
        let mut placed = Vec::with_capacity(CHUNK_POINTS);
        for (shadow, chunk) in self.visible() {
            if self.hidden(&shadow, (chunk.end - chunk.start) as usize) {
                continue;
            }
            for i in chunk.start as usize..chunk.end as usize {
                let c: Vec3 = v.rotation * cloud.position(i) + v.translation;
                // On or behind the camera plane (z ≈ 0 included): never drawn.
                if c.z <= near {
                    continue;
                }
                let Some((px, py)) = project(c) else { continue };
                let at = (floor_i(px), floor_i(py));
                let key = key(c.z, i);
                if avx2 {
                    placed.push(simd::Placed::new(self.zbuf, (px, py), at, key));
                } else {
                    fp.draw::<DYNAMIC>(self.zbuf, (px, py), at, key);
                }
            }
            if avx2 {
                // The projection stays scalar (COLMAP's f64 formulas); the drawing is vectors.
                simd::draw_placed(self.zbuf, &placed, fp.r2);
                placed.clear();
            }
        }
        (self.chunks, self.tested, self.hidden)
    }

    /// Lenses with distortion whose projection is straight-line arithmetic (SIMPLE_RADIAL,
    /// RADIAL, OPENCV), on AVX2: projection and placement in a branch-free loop, then the
    /// vector footprints.
    fn run_straight<P: Projection>(mut self, params: &[f64]) -> (usize, usize, usize) {
        let v = self.view;
        let near = self.cloud.near;
        let r2 = Footprint::of(self.radius).r2;
        let fold = v.check_fold.then_some(v.fold);
        let cloud: &'a RenderCloud = self.cloud;
        let mut placed = Vec::with_capacity(CHUNK_POINTS);
        for (shadow, chunk) in self.visible() {
            let all = cloud.span(chunk.start as usize..chunk.end as usize);
            for (piece, pts) in all.pieces(CHUNK_POINTS).enumerate() {
                if self.hidden(&shadow, pts.len()) {
                    continue;
                }
                let first = chunk.start as usize + piece * CHUNK_POINTS;
                let lens = (v.rotation, v.translation, params);
                simd::place::<P>(self.zbuf, pts, first, lens, (near, fold), &mut placed);
                simd::draw_placed(self.zbuf, &placed, r2);
            }
        }
        (self.chunks, self.tested, self.hidden)
    }

    /// Undistorted lenses: each chunk is transformed and projected in a branch-free pass
    /// that the compiler vectorises, then drawn (4× fewer instructions per point than `run`).
    /// `R` as in `Footprint::draw`; with AVX2 the drawing is `simd::draw`.
    fn run_pinhole<const R: i64>(mut self, k: [f32; 4]) -> (usize, usize, usize) {
        let v = self.view;
        let near = self.cloud.near;
        let fp = Footprint::of(self.radius);
        let (r, t) = (v.rotation, v.translation);
        let mut proj = vec![[0f32; 3]; CHUNK_POINTS];
        let cloud: &'a RenderCloud = self.cloud;
        let avx2 = self.kernel == Kernel::Auto && simd::fits(self.zbuf);
        let mut batch = simd::Batch::default();
        // Chunks built by hand may be longer than CHUNK_POINTS: taken in pieces, each with its
        // first point's index, listed ahead so that drawing one can prefetch the next.
        let pieces: Vec<(usize, Span, Option<Shadow>)> = self
            .visible()
            .into_iter()
            .flat_map(|(shadow, chunk)| {
                let all = cloud.span(chunk.start as usize..chunk.end as usize);
                let first = move |piece: usize| chunk.start as usize + piece * CHUNK_POINTS;
                all.pieces(CHUNK_POINTS)
                    .enumerate()
                    .map(move |(piece, pts)| (first(piece), pts, shadow))
            })
            .collect();
        for (n, &(first, pts, shadow)) in pieces.iter().enumerate() {
            if self.hidden(&shadow, pts.len()) {
                continue;
            }
            if avx2 {
                let next = pieces.get(n + 1).map_or(Span::EMPTY, |p| p.1);
                // The same arithmetic, 8 points or a footprint row per instruction.
                simd::splat(
                    self.zbuf,
                    pts,
                    first,
                    (r, t, k),
                    near,
                    fp.r2,
                    &mut batch,
                    next,
                );
                continue;
            }
            let proj = &mut proj[..pts.len()];
            project(proj, pts, r, t, k);
            for (i, &[x, y, z]) in proj.iter().enumerate() {
                // On or behind the camera plane (z ≈ 0 included): never drawn.
                if z > near {
                    let (px, py) = (x as f64, y as f64);
                    fp.draw::<R>(
                        self.zbuf,
                        (px, py),
                        (floor_f32(px), floor_f32(py)),
                        key(z, first + i),
                    );
                }
            }
        }
        (self.chunks, self.tested, self.hidden)
    }
}

impl ProjectionVisitor for Splat<'_> {
    type Output = (usize, usize, usize);

    fn visit<P: Projection>(self, params: &[f64]) -> (usize, usize, usize) {
        let v = self.view;
        let camera = &v.camera;
        let (check_fold, fold) = (v.check_fold, v.fold);
        if P::STRAIGHT && self.kernel == Kernel::Auto && simd::fits(self.zbuf) {
            return self.run_straight::<P>(params);
        }
        if let Some(k) = v.pinhole {
            return match (self.radius, self.zbuf.reach) {
                (0.0, _) => self.run_pinhole::<0>(k),
                (_, 1) => self.run_pinhole::<1>(k),
                _ => self.run_pinhole::<DYNAMIC>(k),
            };
        }
        self.run(|c: Vec3| {
            let cd = DVec3::new(c.x as f64, c.y as f64, c.z as f64);
            if check_fold && camera.normalized_radius(cd) > fold {
                return None;
            }
            P::project(params, cd).map(|p| (p.x, p.y))
        })
    }
}

/// Render `cloud` into `view` with splats of the view's radius (`View::radius`).
pub fn render(view: &View, cloud: &RenderCloud) -> DeepBuffer {
    render_with(view, cloud, Kernel::Auto)
}

/// `render` with the splat code chosen by the caller (tests compare the kernels).
pub fn render_with(view: &View, cloud: &RenderCloud, kernel: Kernel) -> DeepBuffer {
    let n = view.width as usize * view.height as usize;
    let radius = view.radius();
    let mut zbuf = ZBuffer::new(view.width, view.height, radius);
    let splat = Splat {
        view,
        cloud,
        radius,
        zbuf: &mut zbuf,
        kernel,
        chunks: 0,
        tested: 0,
        hidden: 0,
    };
    let (chunks_visited, points_tested, points_hidden) = view.camera.visit_projection(splat);
    // One pass per channel: the depth pass is branch-free and vectorises; the gathers of
    // colour and normal only run for channels the cloud has.
    let mut depth = Vec::with_capacity(n);
    // Pixels drawn per row: the gathers below skip empty rows.
    let mut hits = Vec::with_capacity(view.height as usize);
    for row in (0..view.height as i64).map(|y| zbuf.row(y)) {
        hits.push(row.iter().filter(|&&k| k != EMPTY).count());
        depth.extend(row.iter().map(|&k| {
            if k == EMPTY {
                0.0
            } else {
                f32::from_bits((k.to_bits() >> 32) as u32)
            }
        }));
    }
    let color = cloud
        .colors
        .as_deref()
        .map(|src| gather_colors(&zbuf, &hits, src, view.width as usize));
    let normal = cloud
        .normals
        .as_deref()
        .map(|src| gather_normals(&zbuf, &hits, src, view));
    DeepBuffer {
        width: view.width,
        height: view.height,
        depth,
        color,
        normal,
        covered: hits.iter().sum(),
        chunks_visited,
        points_tested,
        points_hidden,
    }
}

/// Each pixel's point colour, black where nothing was drawn. The gathers run row by row over
/// the z-buffer: a pixel's point index is its key's low bits. Empty rows are skipped; in rows
/// at least 1/8 drawn colour is gathered for every pixel, empty ones from point 0 and then
/// zeroed, so that the loads do not wait on a branch (the gather is bound by cache misses);
/// sparser rows branch.
fn gather_colors(zbuf: &ZBuffer, hits: &[usize], src: &[[u8; 3]], width: usize) -> Vec<[u8; 3]> {
    let mut out = vec![[0u8; 3]; hits.len() * width];
    // (An empty cloud drew nothing, and has no point 0 to read.)
    let rows = out
        .chunks_exact_mut(width)
        .enumerate()
        .filter(|(y, _)| hits[*y] > 0 && !src.is_empty());
    for (y, orow) in rows {
        let keys = zbuf.row(y as i64);
        if hits[y] < width / 8 {
            // A sparse row: the branch is mostly "empty", and predicted.
            for (o, &k) in orow.iter_mut().zip(keys).filter(|(_, k)| **k != EMPTY) {
                *o = src[k.to_bits() as u32 as usize];
            }
            continue;
        }
        for (o, &k) in orow.iter_mut().zip(keys) {
            let hit = k != EMPTY;
            let c = src[(k.to_bits() as u32 as usize) * hit as usize];
            let m = (hit as u8).wrapping_neg();
            *o = [c[0] & m, c[1] & m, c[2] & m];
        }
    }
    out
}

/// Each pixel's point normal in camera coordinates, zero where nothing was drawn.
fn gather_normals(zbuf: &ZBuffer, hits: &[usize], src: &[Vec3], view: &View) -> Vec<[f32; 3]> {
    let width = view.width as usize;
    let mut out = vec![[0f32; 3]; hits.len() * width];
    let rows = out.chunks_exact_mut(width).enumerate();
    for (y, orow) in rows.filter(|(y, _)| hits[*y] > 0) {
        for (o, &k) in orow.iter_mut().zip(zbuf.row(y as i64)) {
            if k != EMPTY {
                *o = (view.rotation * src[k.to_bits() as u32 as usize]).to_array();
            }
        }
    }
    out
}
