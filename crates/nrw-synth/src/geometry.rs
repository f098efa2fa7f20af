//! The landmark: a façade of stone blocks with recessed windows, an optional portico of
//! columns on steps, and a paved ground. Geometry is analytic (boxes, vertical cylinders,
//! a plane), so photos are ray-cast from the true surface and the dense cloud is sampled on
//! it exactly. World frame: x along the façade, y into it (the front face is y = 0), z up.

use glam::DVec3;
use rand::Rng;

use crate::spec::GeometrySpec;

/// Surface materials; each maps to an albedo texture and an ADE20K class.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Material {
    Stone,
    Glass,
    Marble,
    Pavement,
}

impl Material {
    /// ADE20K class id (1-based, SceneParsing 150): building 2, windowpane 9, sidewalk 12, column 43.
    pub fn ade20k(self) -> u8 {
        match self {
            Material::Stone => 2,
            Material::Glass => 9,
            Material::Pavement => 12,
            Material::Marble => 43,
        }
    }
}

/// ADE20K ids of what is not a static surface.
pub const ADE_SKY: u8 = 3;
/// ADE20K id of a person.
pub const ADE_PERSON: u8 = 13;

/// An axis-aligned box.
#[derive(Debug, Clone, Copy)]
pub struct Cuboid {
    pub min: DVec3,
    pub max: DVec3,
    pub material: Material,
    /// Faces at y = min.y inside a window opening show glass (the back slab).
    pub glazed_front: bool,
}

/// A vertical cylinder (axis parallel to z), without caps.
#[derive(Debug, Clone, Copy)]
pub struct Column {
    pub x: f64,
    pub y: f64,
    pub radius: f64,
    pub z0: f64,
    pub z1: f64,
}

/// A ray hit: distance along the (unit) ray, outward normal, what was hit.
#[derive(Debug, Clone, Copy)]
pub struct Hit {
    pub t: f64,
    pub normal: DVec3,
    pub material: Material,
    /// ADE20K class of the hit surface.
    pub class: u8,
    /// Window cell for glass (night lighting chooses lit windows by cell).
    pub cell: (i32, i32),
}

/// The static scene.
#[derive(Debug, Clone)]
pub struct Landmark {
    pub boxes: Vec<Cuboid>,
    pub columns: Vec<Column>,
    /// Half size of the paved ground square around the façade.
    pub ground_half: f64,
    /// Bounding box of boxes and columns, to skip them for rays that miss it.
    pub bounds: (DVec3, DVec3),
    pub spec: GeometrySpec,
    /// Strength of the fine surface texture (`effects.texture`), `None` when not simulated.
    pub texture: Option<f64>,
}

/// The building's depth behind the façade (m).
const BODY_DEPTH: f64 = 4.0;

/// The depth of the façade's front layer, the window reveals (m).
const FRONT_DEPTH: f64 = 0.3;

/// The façade's front layer (0 ≤ y ≤ [`FRONT_DEPTH`]): the complement of the window
/// openings, row by row of windows.
fn front_layer(spec: &GeometrySpec) -> Vec<Cuboid> {
    let (w, h) = (spec.facade_width, spec.facade_height);
    let x0 = -w / 2.0;
    let bay = w / spec.bays as f64;
    let floor = h / spec.floors as f64;
    let (ww, wh) = (bay * 0.45, floor * 0.5);
    let front = |xa: f64, xb: f64, za: f64, zb: f64| Cuboid {
        min: DVec3::new(xa, 0.0, za),
        max: DVec3::new(xb, FRONT_DEPTH, zb),
        material: Material::Stone,
        glazed_front: false,
    };
    let mut boxes = Vec::new();
    let mut z = 0.0;
    for j in 0..spec.floors {
        let zc = (j as f64 + 0.55) * floor;
        let (za, zb) = (zc - wh / 2.0, zc + wh / 2.0);
        boxes.push(front(x0, -x0, z, za));
        let mut x = x0;
        for i in 0..spec.bays {
            let xc = x0 + (i as f64 + 0.5) * bay;
            boxes.push(front(x, xc - ww / 2.0, za, zb));
            x = xc + ww / 2.0;
        }
        boxes.push(front(x, -x0, za, zb));
        z = zb;
    }
    boxes.push(front(x0, -x0, z, h));
    boxes
}

/// The portico: its steps and entablature pushed to `boxes`, its columns returned.
fn portico(spec: &GeometrySpec, boxes: &mut Vec<Cuboid>) -> Vec<Column> {
    let (w, h) = (spec.facade_width, spec.facade_height);
    let x0 = -w / 2.0;
    let col_h = (h * 0.42).max(2.5);
    boxes.push(Cuboid {
        min: DVec3::new(x0 - 1.0, -3.6, 0.0),
        max: DVec3::new(-x0 + 1.0, 0.0, 0.3),
        material: Material::Marble,
        glazed_front: false,
    });
    boxes.push(Cuboid {
        min: DVec3::new(x0 + 0.2, -2.7, col_h),
        max: DVec3::new(-x0 - 0.2, 0.0, col_h + 0.9),
        material: Material::Stone,
        glazed_front: false,
    });
    (0..=spec.bays)
        .map(|i| Column {
            x: x0 + 0.7 + i as f64 * (w - 1.4) / spec.bays as f64,
            y: -2.0,
            radius: 0.42,
            z0: 0.3,
            z1: col_h,
        })
        .collect()
}

impl Landmark {
    /// Build the landmark a spec describes.
    pub fn new(spec: &GeometrySpec) -> Landmark {
        let (w, h) = (spec.facade_width, spec.facade_height);
        let x0 = -w / 2.0;
        let mut boxes = vec![Cuboid {
            min: DVec3::new(x0, FRONT_DEPTH, 0.0),
            max: DVec3::new(-x0, BODY_DEPTH, h),
            material: Material::Stone,
            glazed_front: true,
        }];
        boxes.extend(front_layer(spec));
        // Cornice.
        boxes.push(Cuboid {
            min: DVec3::new(x0 - 0.5, -0.6, h),
            max: DVec3::new(-x0 + 0.5, BODY_DEPTH + 0.3, h + 0.8),
            material: Material::Stone,
            glazed_front: false,
        });
        let mut columns = Vec::new();
        if spec.columns {
            columns = portico(spec, &mut boxes);
        }
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        for b in &boxes {
            lo = lo.min(b.min);
            hi = hi.max(b.max);
        }
        for c in &columns {
            lo = lo.min(DVec3::new(c.x - c.radius, c.y - c.radius, c.z0));
            hi = hi.max(DVec3::new(c.x + c.radius, c.y + c.radius, c.z1));
        }
        Landmark {
            boxes,
            columns,
            ground_half: 80.0,
            bounds: (lo, hi),
            spec: spec.clone(),
            texture: None,
        }
    }

    /// A point aimed at by photographers: somewhere on the front of the façade.
    pub fn facade_target<R: Rng>(&self, rng: &mut R) -> DVec3 {
        let (w, h) = (self.spec.facade_width, self.spec.facade_height);
        DVec3::new(
            rng.random_range(-0.35..0.35) * w,
            0.0,
            rng.random_range(0.2..0.7) * h,
        )
    }

    /// Window cell (column, row) of a point on the façade front.
    fn window_cell(&self, p: DVec3) -> (i32, i32) {
        let bay = self.spec.facade_width / self.spec.bays as f64;
        let floor = self.spec.facade_height / self.spec.floors as f64;
        (
            ((p.x + self.spec.facade_width / 2.0) / bay).floor() as i32,
            (p.z / floor).floor() as i32,
        )
    }

    /// Nearest static hit along a ray with unit direction `d`, beyond `t_min` and before `t_max`.
    pub fn intersect(&self, o: DVec3, d: DVec3, t_min: f64, t_max: f64) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        let mut t_best = t_max;
        // Ground plane z = 0 within the paved square.
        if d.z < 0.0 && o.z > 0.0 {
            let t = -o.z / d.z;
            if t > t_min && t < t_best {
                let p = o + d * t;
                if p.x.abs() < self.ground_half && p.y.abs() < self.ground_half {
                    t_best = t;
                    best = Some(Hit {
                        t,
                        normal: DVec3::Z,
                        material: Material::Pavement,
                        class: Material::Pavement.ade20k(),
                        cell: (0, 0),
                    });
                }
            }
        }
        let inv = d.recip();
        if slab(o, inv, self.bounds.0, self.bounds.1, t_min, t_best).is_none() {
            return best;
        }
        for b in &self.boxes {
            if let Some((t, axis, sign)) = slab(o, inv, b.min, b.max, t_min, t_best) {
                let mut normal = DVec3::ZERO;
                normal[axis] = sign;
                let p = o + d * t;
                let glass = b.glazed_front && axis == 1 && sign < 0.0;
                let material = if glass { Material::Glass } else { b.material };
                t_best = t;
                best = Some(Hit {
                    t,
                    normal,
                    material,
                    class: material.ade20k(),
                    cell: if glass { self.window_cell(p) } else { (0, 0) },
                });
            }
        }
        for c in &self.columns {
            if let Some((t, normal)) = cylinder(o, d, c.x, c.y, c.radius, c.z0, c.z1, t_min, t_best)
            {
                t_best = t;
                best = Some(Hit {
                    t,
                    normal,
                    material: Material::Marble,
                    class: Material::Marble.ade20k(),
                    cell: (0, 0),
                });
            }
        }
        best
    }

    /// Whether anything static lies on the segment (for shadow rays).
    pub fn occluded(&self, o: DVec3, d: DVec3, t_max: f64) -> bool {
        self.intersect(o, d, 1e-6, t_max).is_some()
    }

    /// Whether `p` is strictly inside a solid (boxes, columns).
    fn inside_solid(&self, p: DVec3) -> bool {
        self.boxes
            .iter()
            .any(|b| p.cmpgt(b.min).all() && p.cmplt(b.max).all())
            || self.columns.iter().any(|c| {
                p.z > c.z0
                    && p.z < c.z1
                    && (p.x - c.x).powi(2) + (p.y - c.y).powi(2) < c.radius * c.radius
            })
    }

    /// The exposed surface as sampling patches with their areas.
    fn patches(&self) -> Vec<Patch> {
        let mut out = Vec::new();
        for b in &self.boxes {
            for axis in 0..3 {
                for sign in [-1.0, 1.0] {
                    if axis == 2 && sign < 0.0 {
                        continue; // bottoms rest on the ground or face it
                    }
                    let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
                    let area = (b.max[u] - b.min[u]) * (b.max[v] - b.min[v]);
                    if area > 0.0 {
                        out.push(Patch::Face {
                            b: *b,
                            axis,
                            sign,
                            area,
                        });
                    }
                }
            }
        }
        for c in &self.columns {
            out.push(Patch::Column {
                c: *c,
                area: std::f64::consts::TAU * c.radius * (c.z1 - c.z0),
            });
        }
        let g = 45.0;
        out.push(Patch::Ground {
            half: g,
            area: (2.0 * g) * (2.0 * g),
        });
        out
    }

    /// `n` points on the exposed surface, area-uniform, with outward normals and materials.
    pub fn sample_surface<R: Rng>(&self, n: usize, rng: &mut R) -> Vec<SurfacePoint> {
        let patches = self.patches();
        let mut cdf = Vec::with_capacity(patches.len());
        let mut acc = 0.0;
        for p in &patches {
            acc += p.area();
            cdf.push(acc);
        }
        let mut out = Vec::with_capacity(n);
        // Points on faces hidden inside other solids are rejected; loop until n are kept,
        // with a bound so a degenerate spec cannot spin forever.
        let mut tries = 0usize;
        while out.len() < n && tries < n * 20 + 1000 {
            tries += 1;
            let r = rng.random_range(0.0..acc);
            let k = cdf.partition_point(|&c| c < r).min(patches.len() - 1);
            let (p, normal, material, cell) = patches[k].sample(rng, self);
            if self.inside_solid(p + normal * 1e-4) {
                continue;
            }
            out.push(SurfacePoint {
                p,
                normal,
                material,
                cell,
            });
        }
        out
    }
}

/// A point on the landmark's surface.
#[derive(Debug, Clone, Copy)]
pub struct SurfacePoint {
    pub p: DVec3,
    pub normal: DVec3,
    pub material: Material,
    pub cell: (i32, i32),
}

#[derive(Debug, Clone, Copy)]
enum Patch {
    Face {
        b: Cuboid,
        axis: usize,
        sign: f64,
        area: f64,
    },
    Column {
        c: Column,
        area: f64,
    },
    Ground {
        half: f64,
        area: f64,
    },
}

impl Patch {
    fn area(&self) -> f64 {
        match self {
            Patch::Face { area, .. } | Patch::Column { area, .. } | Patch::Ground { area, .. } => {
                *area
            }
        }
    }

    fn sample<R: Rng>(&self, rng: &mut R, lm: &Landmark) -> (DVec3, DVec3, Material, (i32, i32)) {
        match *self {
            Patch::Face { b, axis, sign, .. } => {
                let mut p = DVec3::ZERO;
                for k in 0..3 {
                    p[k] = if k == axis {
                        if sign < 0.0 {
                            b.min[k]
                        } else {
                            b.max[k]
                        }
                    } else {
                        rng.random_range(b.min[k]..b.max[k])
                    };
                }
                let mut n = DVec3::ZERO;
                n[axis] = sign;
                let glass = b.glazed_front && axis == 1 && sign < 0.0;
                let m = if glass { Material::Glass } else { b.material };
                (p, n, m, if glass { lm.window_cell(p) } else { (0, 0) })
            }
            Patch::Column { c, .. } => {
                let a = rng.random_range(0.0..std::f64::consts::TAU);
                let n = DVec3::new(a.cos(), a.sin(), 0.0);
                let p = DVec3::new(
                    c.x + c.radius * n.x,
                    c.y + c.radius * n.y,
                    rng.random_range(c.z0..c.z1),
                );
                (p, n, Material::Marble, (0, 0))
            }
            Patch::Ground { half, .. } => {
                let p = DVec3::new(
                    rng.random_range(-half..half),
                    rng.random_range(-half..half),
                    0.0,
                );
                (p, DVec3::Z, Material::Pavement, (0, 0))
            }
        }
    }
}

/// Ray–box slab test: (t, axis, sign of the entered face) of the entry point.
#[inline]
fn slab(
    o: DVec3,
    inv: DVec3,
    lo: DVec3,
    hi: DVec3,
    t_min: f64,
    t_max: f64,
) -> Option<(f64, usize, f64)> {
    let mut t0 = t_min;
    let mut t1 = t_max;
    let mut axis = usize::MAX;
    let mut sign = 0.0;
    for k in 0..3 {
        let (a, b) = ((lo[k] - o[k]) * inv[k], (hi[k] - o[k]) * inv[k]);
        let (near, far, s) = if a <= b { (a, b, -1.0) } else { (b, a, 1.0) };
        // NaN (ray parallel to a slab it lies on) compares false and is skipped.
        if near > t0 {
            t0 = near;
            axis = k;
            sign = s;
        }
        if far < t1 {
            t1 = far;
        }
        if t0 > t1 {
            return None;
        }
    }
    (axis != usize::MAX).then_some((t0, axis, sign))
}

/// Ray against the side of a vertical cylinder, outside hits only.
#[allow(clippy::too_many_arguments)]
#[inline]
fn cylinder(
    o: DVec3,
    d: DVec3,
    cx: f64,
    cy: f64,
    r: f64,
    z0: f64,
    z1: f64,
    t_min: f64,
    t_max: f64,
) -> Option<(f64, DVec3)> {
    let (ox, oy) = (o.x - cx, o.y - cy);
    let a = d.x * d.x + d.y * d.y;
    if a < 1e-18 {
        return None;
    }
    let b = ox * d.x + oy * d.y;
    let c = ox * ox + oy * oy - r * r;
    let disc = b * b - a * c;
    if disc < 0.0 || c < 0.0 {
        return None;
    }
    let t = (-b - disc.sqrt()) / a;
    if t <= t_min || t >= t_max {
        return None;
    }
    let z = o.z + d.z * t;
    if z < z0 || z > z1 {
        return None;
    }
    Some((t, DVec3::new((ox + d.x * t) / r, (oy + d.y * t) / r, 0.0)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::texture::albedo;

    #[test]
    fn surface_texture_changes_the_albedo_only_when_asked() {
        let mut l = Landmark::new(&GeometrySpec::default());
        let (p, n) = (DVec3::new(1.3, 0.2, 4.7), DVec3::new(0.0, -1.0, 0.0));
        let plain = albedo(Material::Stone, p, n);
        assert_eq!(l.albedo(Material::Stone, p, n), plain);
        l.texture = Some(0.4);
        let ratios: Vec<f64> = (0..200)
            .map(|k| {
                let q = p + DVec3::new(k as f64 * 0.013, 0.0, 0.0);
                l.albedo(Material::Stone, q, n).x / albedo(Material::Stone, q, n).x
            })
            .collect();
        let (lo, hi) = ratios
            .iter()
            .fold((f64::MAX, f64::MIN), |(a, b), v| (a.min(*v), b.max(*v)));
        assert!(lo >= 0.6 - 1e-12 && hi <= 1.4 + 1e-12, "{lo} {hi}");
        assert!(
            hi - lo > 0.1,
            "the texture varies within centimetres: {lo} … {hi}"
        );
    }
}
