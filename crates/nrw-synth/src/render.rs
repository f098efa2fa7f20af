//! Photos ray-cast from the true surface, with true depth and ADE20K labels per pixel, and
//! each effect applied only when the photo's [`Look`] carries it. [`Counters`] record how
//! often each effect ran, so tests can prove that an effect not asked for costs nothing.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, Ordering};

use glam::{DVec2, DVec3};
use rand::Rng;
use serde::Serialize;

use crate::cameras::Shot;
use crate::geometry::{Landmark, Material, ADE_PERSON, ADE_SKY};
use crate::look::Look;
use crate::texture::{hash64, to_srgb8};

/// How many times each simulation stage ran (pixels, rays or photos).
#[derive(Debug, Default)]
pub struct Counters {
    pub primary_rays: AtomicU64,
    /// Pixels whose ray needed the iterative inverse of a distortion model.
    pub distortion_inversions: AtomicU64,
    pub sun_shading: AtomicU64,
    pub shadow_rays: AtomicU64,
    pub window_glow: AtomicU64,
    pub haze: AtomicU64,
    pub exposure: AtomicU64,
    pub white_balance: AtomicU64,
    pub transient_tests: AtomicU64,
    pub sensor_noise: AtomicU64,
    pub jpeg_photos: AtomicU64,
    pub png_photos: AtomicU64,
}

impl Counters {
    /// A name → count map for reports and tests.
    pub fn snapshot(&self) -> BTreeMap<&'static str, u64> {
        let g = |a: &AtomicU64| a.load(Ordering::Relaxed);
        BTreeMap::from([
            ("primary_rays", g(&self.primary_rays)),
            ("distortion_inversions", g(&self.distortion_inversions)),
            ("sun_shading", g(&self.sun_shading)),
            ("shadow_rays", g(&self.shadow_rays)),
            ("window_glow", g(&self.window_glow)),
            ("haze", g(&self.haze)),
            ("exposure", g(&self.exposure)),
            ("white_balance", g(&self.white_balance)),
            ("transient_tests", g(&self.transient_tests)),
            ("sensor_noise", g(&self.sensor_noise)),
            ("jpeg_photos", g(&self.jpeg_photos)),
            ("png_photos", g(&self.png_photos)),
        ])
    }
}

/// A person-like transient: a body cylinder and a head sphere standing on the ground.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Person {
    pub x: f64,
    pub y: f64,
    pub height: f64,
    pub color: [f64; 3],
}

impl Person {
    const BODY_R: f64 = 0.24;
    const HEAD_R: f64 = 0.12;

    fn intersect(&self, o: DVec3, d: DVec3, t_max: f64) -> Option<(f64, DVec3)> {
        let mut best: Option<(f64, DVec3)> = None;
        let top = self.height - 2.0 * Self::HEAD_R;
        // Body: a cylinder from the ground to the shoulders.
        let (ox, oy) = (o.x - self.x, o.y - self.y);
        let a = d.x * d.x + d.y * d.y;
        if a > 1e-18 {
            let b = ox * d.x + oy * d.y;
            let c = ox * ox + oy * oy - Self::BODY_R * Self::BODY_R;
            let disc = b * b - a * c;
            if disc >= 0.0 && c > 0.0 {
                let t = (-b - disc.sqrt()) / a;
                let z = o.z + d.z * t;
                if t > 1e-6 && t < t_max && (0.0..=top).contains(&z) {
                    best = Some((t, DVec3::new(ox + d.x * t, oy + d.y * t, 0.0).normalize()));
                }
            }
        }
        // Head: a sphere on top.
        let centre = DVec3::new(self.x, self.y, self.height - Self::HEAD_R);
        let oc = o - centre;
        let b = oc.dot(d);
        let c = oc.length_squared() - Self::HEAD_R * Self::HEAD_R;
        let disc = b * b - c;
        if disc >= 0.0 && c > 0.0 {
            let t = -b - disc.sqrt();
            if t > 1e-6 && t < best.map_or(t_max, |b| b.0) {
                best = Some((t, (o + d * t - centre).normalize()));
            }
        }
        best
    }

    /// Draw people standing in view of a shot, on open ground in front of the landmark.
    pub fn draw<R: Rng>(mean: f64, shot: &Shot, rng: &mut R) -> Vec<Person> {
        // Poisson count by inversion (small means only).
        let (mut n, mut p, l) = (0usize, rng.random::<f64>(), (-mean).exp());
        while p > l && n < 64 {
            p *= rng.random::<f64>();
            n += 1;
        }
        let r = shot.pose.matrix().transpose();
        let fwd = r * DVec3::Z;
        let right = r * DVec3::X;
        let mut out = Vec::new();
        for _ in 0..n {
            let ahead = rng.random_range(4.0..18.0);
            let side = rng.random_range(-0.35..0.35) * ahead;
            let flat = DVec3::new(fwd.x, fwd.y, 0.0).normalize_or_zero();
            let flat_r = DVec3::new(right.x, right.y, 0.0).normalize_or_zero();
            let pos = shot.centre + flat * ahead + flat_r * side;
            // Keep clear of the building, steps and columns.
            if pos.y > -4.2 && pos.x.abs() < 40.0 {
                continue;
            }
            out.push(Person {
                x: pos.x,
                y: pos.y,
                height: rng.random_range(1.55..1.9),
                color: [
                    rng.random_range(0.05..0.8),
                    rng.random_range(0.05..0.8),
                    rng.random_range(0.05..0.8),
                ],
            });
        }
        out
    }
}

/// A rendered photo with its ground truth.
pub struct PhotoBuffers {
    pub width: usize,
    pub height: usize,
    /// sRGB, 3 bytes per pixel, row-major.
    pub rgb: Vec<u8>,
    /// Camera-space z of the visible surface; 0 where nothing is (sky, outside the lens).
    pub depth: Vec<f32>,
    /// ADE20K class per pixel; 0 where the lens sees nothing.
    pub semantics: Vec<u8>,
}

/// Standard normal from a 64-bit hash (Box–Muller on its two halves).
fn hashed_gauss(h: u64) -> f64 {
    let u1 = ((h >> 32) as f64 + 1.0) / 4_294_967_297.0;
    let u2 = (h & 0xffff_ffff) as f64 / 4_294_967_296.0;
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// Whether a window cell is lit at night.
fn lit(cell: (i32, i32)) -> bool {
    hash64(((cell.0 as i64 as u64) << 32) ^ cell.1 as i64 as u64 ^ 0x5eed) % 10 < 6
}

/// How a photo's sensor turns light into pixels.
pub struct Sensor {
    /// Noise standard deviation on [0, 1] intensities, `None` when not simulated.
    pub noise: Option<f64>,
    /// Makes sensor noise a pure function of (photo, pixel).
    pub noise_seed: u64,
    /// Rays a pixel per axis whose mean colour the pixel records (1: the centre ray).
    pub pixel_samples: u32,
}

/// Render one photo.
pub fn render(
    landmark: &Landmark,
    shot: &Shot,
    look: &Look,
    people: &[Person],
    sensor: &Sensor,
    counters: &Counters,
) -> PhotoBuffers {
    let (w, h) = (shot.camera.width as usize, shot.camera.height as usize);
    let mut out = PhotoBuffers {
        width: w,
        height: h,
        rgb: vec![0; w * h * 3],
        depth: vec![0.0; w * h],
        semantics: vec![0; w * h],
    };
    let light = Light::of(look);
    let photo = Photo {
        landmark,
        shot,
        look,
        light: &light,
        people,
        sensor_noise: sensor.noise,
        noise_seed: sensor.noise_seed,
        samples: sensor.pixel_samples.max(1),
        cam_to_world: shot.pose.matrix().transpose(),
        distorted: shot.camera.model.has_distortion(),
    };
    let mut tally = Tally::default();
    for y in 0..h {
        for x in 0..w {
            photo.pixel(&mut out, x, y, &mut tally);
        }
    }
    let per_pixel = photo.samples as u64 * photo.samples as u64 + (photo.samples > 1) as u64;
    tally.add_to(counters, (w * h) as u64 * per_pixel);
    out
}

/// A look's light in the form shading uses it.
struct Light {
    sun: Option<DVec3>,
    ambient: DVec3,
    sun_radiance: DVec3,
    gain: Option<f64>,
    white_balance: Option<DVec3>,
    glow: Option<DVec3>,
    horizon: DVec3,
}

impl Light {
    /// The light a photo's look describes.
    fn of(look: &Look) -> Light {
        Light {
            sun: look.sun_direction.map(DVec3::from_array),
            ambient: DVec3::from_array(look.ambient),
            sun_radiance: DVec3::from_array(look.sun),
            gain: look.exposure_ev.map(|ev| 2f64.powf(ev)),
            white_balance: look.white_balance.map(DVec3::from_array),
            glow: look.window_glow.map(DVec3::from_array),
            horizon: DVec3::from_array(look.sky_horizon),
        }
    }
}

/// One photo's counts of each simulation stage, added to [`Counters`] once at its end.
#[derive(Default)]
struct Tally {
    inversions: u64,
    sun: u64,
    shadow: u64,
    glow: u64,
    haze: u64,
    exposure: u64,
    white_balance: u64,
    transients: u64,
    noise: u64,
}

impl Tally {
    /// Add this photo's counts, and its `rays` primary rays, to the scene's counters.
    fn add_to(&self, counters: &Counters, rays: u64) {
        let add = |a: &AtomicU64, v: u64| {
            a.fetch_add(v, Ordering::Relaxed);
        };
        add(&counters.primary_rays, rays);
        add(&counters.distortion_inversions, self.inversions);
        add(&counters.sun_shading, self.sun);
        add(&counters.shadow_rays, self.shadow);
        add(&counters.window_glow, self.glow);
        add(&counters.haze, self.haze);
        add(&counters.exposure, self.exposure);
        add(&counters.white_balance, self.white_balance);
        add(&counters.transient_tests, self.transients);
        add(&counters.sensor_noise, self.noise);
    }
}

/// What a primary ray hits first: distance along the ray, normal, material (none for a
/// person), ADE20K class, window cell and a person's colour.
type Hit = (f64, DVec3, Option<Material>, u8, (i32, i32), DVec3);

/// Everything one photo's pixels share.
struct Photo<'a> {
    landmark: &'a Landmark,
    shot: &'a Shot,
    look: &'a Look,
    light: &'a Light,
    people: &'a [Person],
    sensor_noise: Option<f64>,
    noise_seed: u64,
    /// Rays a pixel per axis (1: the centre ray).
    samples: u32,
    cam_to_world: glam::DMat3,
    /// Whether the lens distorts (its rays are found by iteration).
    distorted: bool,
}

impl Photo<'_> {
    /// One pixel's colour, depth and label.
    fn pixel(&self, out: &mut PhotoBuffers, x: usize, y: usize, tally: &mut Tally) {
        let i = y * out.width + x;
        let Some((ray, d, hit)) = self.primary(DVec2::new(x as f64 + 0.5, y as f64 + 0.5), tally)
        else {
            return;
        };
        match hit {
            None => out.semantics[i] = ADE_SKY,
            Some(hit) => {
                out.depth[i] = (hit.0 * ray.z) as f32;
                out.semantics[i] = hit.3;
            }
        }
        let mut c = match self.samples {
            1 => self.radiance(d, hit, tally),
            _ => self.box_filtered(x, y, tally),
        };
        if let Some(g) = self.light.gain {
            tally.exposure += 1;
            c *= g;
        }
        if let Some(g) = self.light.white_balance {
            tally.white_balance += 1;
            c *= g;
        }
        for k in 0..3 {
            let mut v = to_srgb8(c[k]) as f64;
            if let Some(s) = self.sensor_noise {
                tally.noise += 1;
                v += 255.0
                    * s
                    * hashed_gauss(hash64(
                        self.noise_seed ^ ((i as u64) * 3 + k as u64).wrapping_mul(0x9e37_79b9),
                    ));
            }
            out.rgb[i * 3 + k] = v.round().clamp(0.0, 255.0) as u8;
        }
    }

    /// The ray through image point `px` (camera frame, then world frame) and what it hits;
    /// `None` where the lens has no ray for the point.
    fn primary(&self, px: DVec2, tally: &mut Tally) -> Option<(DVec3, DVec3, Option<Hit>)> {
        // Pinhole models invert in closed form; only distortion models iterate.
        tally.inversions += self.distorted as u64;
        let ray = self.shot.camera.cam_ray_from_img(px)?;
        let d = self.cam_to_world * ray;
        Some((ray, d, self.hit(d, tally)))
    }

    /// The linear colour arriving along world direction `d`, which hits `hit`.
    fn radiance(&self, d: DVec3, hit: Option<Hit>, tally: &mut Tally) -> DVec3 {
        match hit {
            None => self.look.sky(d),
            Some(hit) => self.shade(d, hit, tally),
        }
    }

    /// The mean linear colour of `samples × samples` rays spread evenly over pixel (x, y):
    /// the box filter of a sensor's pixel (rays the lens has none for are left out).
    fn box_filtered(&self, x: usize, y: usize, tally: &mut Tally) -> DVec3 {
        let n = self.samples as usize;
        let (mut sum, mut count) = (DVec3::ZERO, 0u32);
        for (j, k) in (0..n).flat_map(|j| (0..n).map(move |k| (j, k))) {
            let px = DVec2::new(
                x as f64 + (k as f64 + 0.5) / n as f64,
                y as f64 + (j as f64 + 0.5) / n as f64,
            );
            if let Some((_, d, hit)) = self.primary(px, tally) {
                sum += self.radiance(d, hit, tally);
                count += 1;
            }
        }
        sum / count.max(1) as f64
    }

    /// The first surface or person along direction `d` from the camera centre.
    fn hit(&self, d: DVec3, tally: &mut Tally) -> Option<Hit> {
        let o = self.shot.centre;
        let mut hit = self.landmark.intersect(o, d, 1e-6, 1e5).map(|h| {
            (
                h.t,
                h.normal,
                Some(h.material),
                h.class,
                h.cell,
                DVec3::ZERO,
            )
        });
        if !self.people.is_empty() {
            tally.transients += 1;
            for p in self.people {
                let t_max = hit.map_or(1e5, |h| h.0);
                if let Some((t, n)) = p.intersect(o, d, t_max) {
                    hit = Some((t, n, None, ADE_PERSON, (0, 0), DVec3::from_array(p.color)));
                }
            }
        }
        hit
    }

    /// The linear colour of a hit: albedo under ambient and (unless shadowed) sun, a lit
    /// window's glow, haze.
    fn shade(&self, d: DVec3, hit: Hit, tally: &mut Tally) -> DVec3 {
        let (t, n, material, _, cell, person_color) = hit;
        let light = self.light;
        let p = self.shot.centre + d * t;
        let alb = match material {
            Some(m) => self.landmark.albedo(m, p, n),
            None => person_color,
        };
        let mut c = alb * light.ambient;
        if let Some(l) = light.sun {
            tally.sun += 1;
            let ndl = n.dot(l);
            if ndl > 0.0 {
                tally.shadow += 1;
                if !self.landmark.occluded(p + n * 1e-4, l, 1e4) {
                    c += alb * light.sun_radiance * ndl;
                }
            }
        }
        if let (Some(g), Some(Material::Glass)) = (light.glow, material) {
            tally.glow += 1;
            if lit(cell) {
                c += g;
            }
        }
        if let Some(beta) = self.look.haze_density {
            tally.haze += 1;
            let f = (-beta * t).exp();
            c = c * f + light.horizon * (1.0 - f);
        }
        c
    }
}
