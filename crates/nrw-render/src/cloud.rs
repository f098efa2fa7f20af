//! The cloud as the renderer holds it: re-centred in f64, then cast to f32 (the one place
//! precision is given up), sorted into spatially compact chunks with bounds so that views
//! skip the chunks outside their frustum.

use glam::{DVec3, Vec3};
use nrw_colmap::{PointCloud, Reconstruction};

/// Points per chunk: small enough to cull finely, large enough that bounds tests are cheap.
pub const CHUNK_POINTS: usize = 2048;

/// A run of points with its bounding box (local frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Chunk {
    pub start: u32,
    pub end: u32,
    pub min: Vec3,
    pub max: Vec3,
}

/// Some of a cloud's points, one slice per axis (see `RenderCloud::xyz`).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Span<'a>(pub(crate) [&'a [f32]; 3]);

impl<'a> Span<'a> {
    /// No point.
    pub(crate) const EMPTY: Span<'static> = Span([&[], &[], &[]]);

    pub(crate) fn len(&self) -> usize {
        self.0[0].len()
    }

    /// Point `i` of the span.
    #[inline(always)]
    pub(crate) fn get(&self, i: usize) -> Vec3 {
        Vec3::new(self.0[0][i], self.0[1][i], self.0[2][i])
    }

    /// The span in consecutive pieces of at most `n` points.
    pub(crate) fn pieces(self, n: usize) -> impl Iterator<Item = Span<'a>> {
        (0..self.len())
            .step_by(n.max(1))
            .map(move |s| Span(self.0.map(|a| &a[s..(s + n).min(a.len())])))
    }
}

/// A cloud ready to render: local f32 positions around `origin`, optional channels, chunks.
#[derive(Debug, Clone, Default)]
pub struct RenderCloud {
    /// World point that local coordinates are relative to (f64, exact).
    pub origin: DVec3,
    /// Local f32 positions, one array per axis (x, y, z): the pinhole projection loads 8
    /// points per axis per instruction instead of de-interleaving x, y, z (docs/rendering.md has
    /// the figures). `position` gives one point.
    pub xyz: [Vec<f32>; 3],
    pub colors: Option<Vec<[u8; 3]>>,
    pub normals: Option<Vec<Vec3>>,
    pub chunks: Vec<Chunk>,
    /// Points nearer the camera plane than this (local units) are never drawn.
    pub near: f32,
}

/// Spread the low 21 bits of `v` to every third bit (for Morton codes).
fn spread(mut v: u64) -> u64 {
    v &= 0x1f_ffff;
    v = (v | v << 32) & 0x1f_0000_0000_ffff;
    v = (v | v << 16) & 0x1f_0000_ff00_00ff;
    v = (v | v << 8) & 0x100f_00f0_0f00_f00f;
    v = (v | v << 4) & 0x10c3_0c30_c30c_30c3;
    v = (v | v << 2) & 0x1249_2492_4924_9249;
    v
}

/// A cloud's points re-centred and cast to f32 as they are read (a [`nrw_colmap::VertexSink`]),
/// so a PLY becomes a [`RenderCloud`] without ever holding its f64 positions: 12 bytes a
/// point, 15 with colour, 27 with normals, plus 16 while [`LocalPoints::finish`] sorts.
#[derive(Debug, Default)]
pub struct LocalPoints {
    origin: DVec3,
    xyz: [Vec<f32>; 3],
    colors: Option<Vec<[u8; 3]>>,
    normals: Option<Vec<Vec3>>,
}

impl LocalPoints {
    /// No point yet; positions will be relative to `origin`.
    pub fn new(origin: DVec3) -> LocalPoints {
        LocalPoints {
            origin,
            ..Default::default()
        }
    }

    /// Add one world point.
    pub fn push(&mut self, p: DVec3, color: Option<[u8; 3]>, normal: Option<[f32; 3]>) {
        // Precision is given up here: positions become f32 only after subtracting the
        // origin in f64, so georeferenced clouds keep millimetres.
        let l = (p - self.origin).as_vec3();
        for a in 0..3 {
            self.xyz[a].push(l[a]);
        }
        if let (Some(c), Some(v)) = (self.colors.as_mut(), color) {
            c.push(v);
        }
        if let (Some(n), Some(v)) = (self.normals.as_mut(), normal) {
            n.push(Vec3::from_array(v));
        }
    }

    /// The cloud in Morton order with its chunks (the arrays are permuted in place).
    pub fn finish(self) -> RenderCloud {
        RenderCloud::from_local(self)
    }
}

impl nrw_colmap::VertexSink for LocalPoints {
    fn begin(&mut self, capacity: usize, normals: bool, colors: bool) {
        self.xyz.iter_mut().for_each(|a| a.reserve_exact(capacity));
        self.colors = colors.then(|| Vec::with_capacity(capacity));
        self.normals = normals.then(|| Vec::with_capacity(capacity));
    }
    fn push(&mut self, xyz: DVec3, normal: Option<[f32; 3]>, color: Option<[u8; 3]>) {
        LocalPoints::push(self, xyz, color, normal);
    }
}

/// Move element `order[i].1` to position i for every i, in place, cycle by cycle (`order`
/// is consumed as the visited marks: u64::MAX is never a Morton key of 63 bits).
fn permute(order: &mut [(u64, u32)], mv: &mut dyn FnMut(Move)) {
    for start in 0..order.len() {
        if order[start].0 == u64::MAX {
            continue;
        }
        mv(Move::Save(start));
        let mut j = start;
        loop {
            let src = order[j].1 as usize;
            order[j].0 = u64::MAX;
            if src == start {
                mv(Move::Restore(j));
                break;
            }
            mv(Move::Copy { from: src, to: j });
            j = src;
        }
    }
}

/// One step of [`permute`]'s cycle walk.
#[derive(Clone, Copy)]
enum Move {
    /// Keep element i aside (the cycle's first).
    Save(usize),
    Copy {
        from: usize,
        to: usize,
    },
    /// Put the kept element at i.
    Restore(usize),
}

/// Apply a [`Move`] to one array with its one-element stash.
fn apply<T: Copy + Default>(v: &mut [T], stash: &mut T, m: Move) {
    match m {
        Move::Save(i) => *stash = v[i],
        Move::Copy { from, to } => v[to] = v[from],
        Move::Restore(i) => v[i] = *stash,
    }
}

impl RenderCloud {
    /// Build from world positions (f64) and optional channels, re-centred on `origin`.
    pub fn new(
        origin: DVec3,
        world: &[DVec3],
        colors: Option<&[[u8; 3]]>,
        normals: Option<&[[f32; 3]]>,
    ) -> RenderCloud {
        let mut local = LocalPoints::new(origin);
        nrw_colmap::VertexSink::begin(&mut local, world.len(), normals.is_some(), colors.is_some());
        for (i, p) in world.iter().enumerate() {
            local.push(*p, colors.map(|c| c[i]), normals.map(|n| n[i]));
        }
        local.finish()
    }

    /// Sort local points into Morton order (in place: one 16-byte key a point beside them)
    /// and cut them into chunks with bounds.
    fn from_local(points: LocalPoints) -> RenderCloud {
        let LocalPoints {
            origin,
            mut xyz,
            mut colors,
            mut normals,
        } = points;
        let n = xyz[0].len();
        let at = |xyz: &[Vec<f32>; 3], i: usize| Vec3::new(xyz[0][i], xyz[1][i], xyz[2][i]);
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for i in 0..n {
            lo = lo.min(at(&xyz, i));
            hi = hi.max(at(&xyz, i));
        }
        let extent = if n > 0 {
            (hi - lo).max_element().max(1e-6)
        } else {
            1.0
        };
        // Morton order on a 2^21 grid keeps chunks compact; ties keep input order.
        let scale = ((1u64 << 21) - 1) as f32 / extent;
        let mut order: Vec<(u64, u32)> = (0..n)
            .map(|i| {
                let q = ((at(&xyz, i) - lo) * scale).max(Vec3::ZERO);
                (
                    spread(q.x as u64) | spread(q.y as u64) << 1 | spread(q.z as u64) << 2,
                    i as u32,
                )
            })
            .collect();
        order.sort_unstable();
        let (mut sx, mut sc, mut sn) = ([0f32; 3], [0u8; 3], Vec3::ZERO);
        permute(&mut order, &mut |m| {
            for (a, s) in xyz.iter_mut().zip(sx.iter_mut()) {
                apply(a, s, m);
            }
            if let Some(c) = colors.as_mut() {
                apply(c, &mut sc, m);
            }
            if let Some(v) = normals.as_mut() {
                apply(v, &mut sn, m);
            }
        });
        drop(order);
        let chunks = (0..n)
            .step_by(CHUNK_POINTS)
            .map(|s| {
                let e = (s + CHUNK_POINTS).min(n);
                let (mut mn, mut mx) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
                for i in s..e {
                    mn = mn.min(at(&xyz, i));
                    mx = mx.max(at(&xyz, i));
                }
                Chunk {
                    start: s as u32,
                    end: e as u32,
                    min: mn,
                    max: mx,
                }
            })
            .collect();
        RenderCloud {
            origin,
            xyz,
            colors,
            normals,
            chunks,
            near: 1e-5 * extent,
        }
    }

    /// A dense cloud read from PLY.
    pub fn from_ply(origin: DVec3, cloud: &PointCloud) -> RenderCloud {
        RenderCloud::new(
            origin,
            &cloud.positions,
            cloud.colors.as_deref(),
            cloud.normals.as_deref(),
        )
    }

    /// The sparse points of a COLMAP model (colour, no normals).
    pub fn from_sparse(origin: DVec3, rec: &Reconstruction) -> RenderCloud {
        let pos: Vec<DVec3> = rec.points.values().map(|p| p.xyz).collect();
        let col: Vec<[u8; 3]> = rec.points.values().map(|p| p.rgb).collect();
        RenderCloud::new(origin, &pos, Some(&col), None)
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.xyz[0].len()
    }

    /// Whether the cloud has no point.
    pub fn is_empty(&self) -> bool {
        self.xyz[0].is_empty()
    }

    /// Point `i` (local frame).
    pub fn position(&self, i: usize) -> Vec3 {
        Vec3::new(self.xyz[0][i], self.xyz[1][i], self.xyz[2][i])
    }

    /// Every point (local frame), in index order.
    pub fn positions(&self) -> impl Iterator<Item = Vec3> + '_ {
        (0..self.len()).map(|i| self.position(i))
    }

    /// Points `range` as one slice per axis.
    pub(crate) fn span(&self, range: std::ops::Range<usize>) -> Span<'_> {
        Span(self.xyz.each_ref().map(|a| &a[range.clone()]))
    }
}
