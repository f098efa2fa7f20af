//! Point splatting with a z-buffer. A point of radius r covers every pixel whose centre lies
//! within r pixels of its projection (r = 0: the pixel that contains it); the nearest point
//! wins, and equal depths go to the lower point index, so renders are deterministic.

use glam::{DVec3, Vec3};
use nrw_colmap::{Projection, ProjectionVisitor};

use crate::cloud::RenderCloud;
use crate::view::View;

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

struct Splat<'a> {
    view: &'a View,
    cloud: &'a RenderCloud,
    radius: f32,
    zbuf: &'a mut [u64],
    chunks: usize,
    tested: usize,
}

impl Splat<'_> {
    /// The splat loop over visible chunks, generic over how a camera-space point projects.
    fn run<F: Fn(Vec3) -> Option<(f64, f64)>>(self, project: F) -> (usize, usize) {
        let v = self.view;
        let (w, h) = (v.width as i64, v.height as i64);
        let near = self.cloud.near;
        let r = self.radius as f64;
        let r2 = r * r;
        let (mut chunks, mut tested) = (self.chunks, self.tested);
        for chunk in &self.cloud.chunks {
            if !v.may_see(chunk.min, chunk.max, near) {
                continue;
            }
            chunks += 1;
            let pts = &self.cloud.positions[chunk.start as usize..chunk.end as usize];
            tested += pts.len();
            for (k, p) in pts.iter().enumerate() {
                let c: Vec3 = v.rotation * *p + v.translation;
                // On or behind the camera plane (z ≈ 0 included): never drawn.
                if c.z <= near {
                    continue;
                }
                let Some((px, py)) = project(c) else { continue };
                // Positive f32 bits order like the values: one u64 min = nearest, then lowest index.
                let key = (c.z.to_bits() as u64) << 32 | (chunk.start as u64 + k as u64);
                if r == 0.0 {
                    let (x, y) = (px.floor() as i64, py.floor() as i64);
                    if x >= 0 && y >= 0 && x < w && y < h {
                        let slot = &mut self.zbuf[(y * w + x) as usize];
                        *slot = (*slot).min(key);
                    }
                    continue;
                }
                let (x0, x1) = ((px - 0.5 - r).ceil() as i64, (px - 0.5 + r).floor() as i64);
                let (y0, y1) = ((py - 0.5 - r).ceil() as i64, (py - 0.5 + r).floor() as i64);
                let (x0, x1) = (x0.max(0), x1.min(w - 1));
                for y in y0.max(0)..=y1.min(h - 1) {
                    let dy = y as f64 + 0.5 - py;
                    let dy2 = dy * dy;
                    let row = &mut self.zbuf[(y * w) as usize..((y + 1) * w) as usize];
                    for x in x0..=x1 {
                        let dx = x as f64 + 0.5 - px;
                        // Branch-free: a pixel outside the disc takes u64::MAX, which never wins.
                        let k = if dx * dx + dy2 <= r2 { key } else { u64::MAX };
                        let slot = &mut row[x as usize];
                        *slot = (*slot).min(k);
                    }
                }
            }
        }
        (chunks, tested)
    }
}

impl ProjectionVisitor for Splat<'_> {
    type Output = (usize, usize);

    fn visit<P: Projection>(self, params: &[f64]) -> (usize, usize) {
        let v = self.view;
        let camera = &v.camera;
        let (check_fold, fold) = (v.check_fold, v.fold);
        self.run(|c: Vec3| {
            let cd = DVec3::new(c.x as f64, c.y as f64, c.z as f64);
            if check_fold && camera.normalized_radius(cd) > fold {
                return None;
            }
            P::project(params, cd).map(|p| (p.x, p.y))
        })
    }
}

/// Render `cloud` into `view` with splats of `radius` output pixels.
pub fn render(view: &View, cloud: &RenderCloud, radius: f32) -> DeepBuffer {
    let n = view.width as usize * view.height as usize;
    let mut zbuf = vec![u64::MAX; n];
    let splat = Splat {
        view,
        cloud,
        radius: radius.max(0.0),
        zbuf: &mut zbuf,
        chunks: 0,
        tested: 0,
    };
    let (chunks_visited, points_tested) = view.camera.visit_projection(splat);
    let mut depth = vec![0.0f32; n];
    let mut color = cloud.colors.as_ref().map(|_| vec![[0u8; 3]; n]);
    let mut normal = cloud.normals.as_ref().map(|_| vec![[0f32; 3]; n]);
    let mut covered = 0;
    for (i, key) in zbuf.iter().enumerate() {
        if *key == u64::MAX {
            continue;
        }
        covered += 1;
        depth[i] = f32::from_bits((key >> 32) as u32);
        let idx = (key & 0xffff_ffff) as usize;
        if let (Some(out), Some(src)) = (color.as_mut(), cloud.colors.as_ref()) {
            out[i] = src[idx];
        }
        if let (Some(out), Some(src)) = (normal.as_mut(), cloud.normals.as_ref()) {
            out[i] = (view.rotation * src[idx]).to_array();
        }
    }
    DeepBuffer {
        width: view.width,
        height: view.height,
        depth,
        color,
        normal,
        covered,
        chunks_visited,
        points_tested,
    }
}
