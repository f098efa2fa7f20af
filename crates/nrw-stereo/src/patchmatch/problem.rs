//! One reference view's matching problem: its sources posed relative to it, the window, and
//! the per-pixel bookkeeping the cost and the sweeps share.

use glam::{DMat3, DVec3};

use crate::ncc::Samples;
use crate::rng::PixelRng;
use crate::view::StereoView;

use super::options::{PatchMatchOptions, Source, MAX_COST, MAX_SOURCES};

/// A pixel's new hypothesis: depth, normal, cost, selected views.
pub(super) type Update = (f32, [f32; 3], f32, u32);

/// Source costs already computed for one hypothesis at one pixel (bit j of `mask`: source
/// j's cost is `costs[j]`).
pub(super) struct Known {
    pub(super) mask: u32,
    pub(super) costs: [f64; MAX_SOURCES],
}

impl Known {
    /// Nothing computed yet.
    pub(super) const NONE: Known = Known {
        mask: 0,
        costs: [MAX_COST as f64; MAX_SOURCES],
    };
}

/// The four directions a pixel takes hypotheses from.
pub(super) const DIRECTIONS: [(isize, isize); 4] = [(-1, 0), (1, 0), (0, -1), (0, 1)];

/// The distances along a direction a neighbour is picked from: odd, so a pixel never reads
/// one of its own colour.
pub(super) const NEIGHBOUR_STEPS: [isize; 3] = [1, 3, 5];

/// A source as the kernel uses it: its pose relative to the reference.
pub(super) struct Rel<'a> {
    pub(super) view: &'a StereoView,
    /// x_src = r · x_ref + t.
    pub(super) r: DMat3,
    pub(super) t: DVec3,
    /// The source's centre in reference-camera coordinates.
    pub(super) centre: DVec3,
    /// K_src · R · K_ref⁻¹ and K_src · t: the homography of every plane into this source is
    /// the first plus the second times a row that depends on the plane only.
    pub(super) krk: DMat3,
    pub(super) kt: DVec3,
    pub(super) depth: Option<&'a [f32]>,
}

/// A plane hypothesis at one pixel, as each source's cost reads it.
pub(super) struct Plane {
    pub(super) x: usize,
    pub(super) y: usize,
    /// The pixel's point on the plane, in reference-camera coordinates.
    pub(super) point: DVec3,
    /// K⁻ᵀ n / (n · point): the row every source's homography adds; `None` when the plane
    /// passes through the reference centre.
    pub(super) row: Option<DVec3>,
}

/// One reference view's matching problem.
pub(super) struct Problem<'a> {
    pub(super) reference: &'a StereoView,
    pub(super) sources: Vec<Rel<'a>>,
    pub(super) opts: &'a PatchMatchOptions,
    /// Window samples: (dx, dy, spatial weight).
    pub(super) window: Vec<(f64, f64, f64)>,
    pub(super) range: (f64, f64),
    pub(super) geometric: bool,
    /// The reference's K⁻ᵀ, which turns a plane's normal into its homographies' row.
    pub(super) k_inv_t: DMat3,
}

/// The reference window around one pixel: offsets, bilateral weights and centred grey
/// values, one run of `len` f32 per field in one buffer (the warp loop runs over them in f32).
/// The runs are padded to a multiple of [`LANES`] with weight 0 (and a real sample's offset,
/// so a padded sample is never outside when the real ones are inside).
pub(super) struct Patch {
    /// dx, dy, weight, and weight × (grey value minus the weighted mean): `stride` apart.
    /// Taken from this thread's [`POOL`] and given back on drop.
    pub(super) buf: Vec<f32>,
    pub(super) stride: usize,
    /// The samples with their padding.
    pub(super) len: usize,
    /// The real samples (the first `count` of each run).
    pub(super) count: usize,
    pub(super) sum_w: f64,
    pub(super) var: f64,
}

impl Patch {
    /// Field `field`'s run (0 dx, 1 dy, 2 weight, 3 weight × centred value).
    pub(super) fn run(&self, field: usize) -> &[f32] {
        &self.buf[field * self.stride..field * self.stride + self.len]
    }

    /// The samples as the NCC kernel reads them.
    pub(super) fn samples(&self) -> Samples<'_> {
        Samples {
            dx: self.run(0),
            dy: self.run(1),
            w: self.run(2),
            wa: self.run(3),
            count: self.count,
        }
    }
}

thread_local! {
    /// Window buffers no patch holds: a pixel's patch reuses one rather than allocating
    /// (and zeroing) its own, each time a sweep visits the pixel.
    pub(super) static POOL: std::cell::RefCell<Vec<Vec<f32>>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// A buffer of `len` f32 from this thread's pool (its contents are whatever the last patch
/// left: [`Problem::patch`] writes every value it reads).
pub(super) fn pooled(len: usize) -> Vec<f32> {
    let mut buf = POOL.with(|p| p.borrow_mut().pop()).unwrap_or_default();
    buf.resize(len, 0.0);
    buf
}

impl Drop for Patch {
    fn drop(&mut self) {
        let buf = std::mem::take(&mut self.buf);
        POOL.with(|p| p.borrow_mut().push(buf));
    }
}

impl<'a> Problem<'a> {
    pub(super) fn new(
        reference: &'a StereoView,
        sources: &[Source<'a>],
        opts: &'a PatchMatchOptions,
        range: (f64, f64),
        geometric: bool,
    ) -> Problem<'a> {
        let r_ref_t = reference.rotation.transpose();
        let sources = sources
            .iter()
            .take(MAX_SOURCES)
            .map(|s| {
                let r = s.view.rotation * r_ref_t;
                let t = s.view.translation - r * reference.translation;
                let k = s.view.lens.matrix();
                Rel {
                    view: s.view,
                    r,
                    t,
                    centre: -(r.transpose() * t),
                    krk: k * r * reference.lens.inverse(),
                    kt: k * t,
                    depth: s.depth,
                }
            })
            .collect();
        let rad = opts.window_radius as isize;
        let step = opts.window_step.max(1);
        let mut window = Vec::new();
        for dy in (-rad..=rad).step_by(step) {
            for dx in (-rad..=rad).step_by(step) {
                let d2 = (dx * dx + dy * dy) as f64;
                let w = (-d2 / (2.0 * opts.sigma_spatial * opts.sigma_spatial)).exp();
                window.push((dx as f64, dy as f64, w));
            }
        }
        Problem {
            reference,
            sources,
            opts,
            window,
            range,
            geometric,
            k_inv_t: reference.lens.inverse().transpose(),
        }
    }

    pub(super) fn in_range(&self, d: f64) -> bool {
        d >= self.range.0 && d <= self.range.1
    }

    pub(super) fn random_depth(&self, rng: &mut PixelRng) -> f64 {
        // Uniform in inverse depth: equal steps in disparity.
        let (lo, hi) = (1.0 / self.range.1, 1.0 / self.range.0);
        1.0 / (lo + (hi - lo) * rng.uniform())
    }

    /// A random unit normal facing the camera along `ray`.
    pub(super) fn random_normal(ray: DVec3, rng: &mut PixelRng) -> DVec3 {
        loop {
            let v = DVec3::new(rng.signed(), rng.signed(), rng.signed());
            let l = v.length_squared();
            if l > 1e-6 && l <= 1.0 {
                return facing(v / l.sqrt(), ray);
            }
        }
    }
}

pub(super) fn to_d(n: [f32; 3]) -> DVec3 {
    DVec3::new(n[0] as f64, n[1] as f64, n[2] as f64)
}

pub(super) fn to_f(n: DVec3) -> [f32; 3] {
    [n.x as f32, n.y as f32, n.z as f32]
}

/// `n` turned to face the camera along `ray` (n · ray < 0).
pub(super) fn facing(n: DVec3, ray: DVec3) -> DVec3 {
    if n.dot(ray) > 0.0 {
        -n
    } else {
        n
    }
}
