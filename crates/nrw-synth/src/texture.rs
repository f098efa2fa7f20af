//! The surfaces' colours: deterministic hashing and value noise, each material's albedo, the
//! fine texture a spec may ask for, and the sRGB encoding of a photo's pixels.

use glam::DVec3;

use crate::geometry::{Landmark, Material};

/// Deterministic 64-bit hash (SplitMix64 finaliser) for procedural textures and noise.
#[inline]
pub fn hash64(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    x ^ (x >> 31)
}

/// Uniform value in [0, 1) from integer lattice coordinates.
#[inline]
fn lattice(i: i64, j: i64, k: i64, salt: u64) -> f64 {
    let h = hash64(
        (i as u64).wrapping_mul(0x8da6_b343)
            ^ (j as u64).wrapping_mul(0xd816_3841)
            ^ (k as u64).wrapping_mul(0xcb1a_b31f)
            ^ salt,
    );
    (h >> 11) as f64 / (1u64 << 53) as f64
}

/// Smooth value noise in [0, 1].
fn value_noise(p: DVec3, salt: u64) -> f64 {
    let f = p.floor();
    let t = p - f;
    let s = t * t * (DVec3::splat(3.0) - 2.0 * t);
    let (i, j, k) = (f.x as i64, f.y as i64, f.z as i64);
    let mut acc = 0.0;
    for (di, wx) in [(0, 1.0 - s.x), (1, s.x)] {
        for (dj, wy) in [(0, 1.0 - s.y), (1, s.y)] {
            for (dk, wz) in [(0, 1.0 - s.z), (1, s.z)] {
                acc += wx * wy * wz * lattice(i + di, j + dj, k + dk, salt);
            }
        }
    }
    acc
}

impl Landmark {
    /// The albedo photos and points share at a surface point: the material's, times the fine
    /// texture when the spec asks for it.
    pub fn albedo(&self, m: Material, p: DVec3, normal: DVec3) -> DVec3 {
        let a = albedo(m, p, normal);
        match self.texture {
            Some(t) if t > 0.0 => a * (1.0 + t * (2.0 * fine_texture(p) - 1.0)).max(0.0),
            _ => a,
        }
    }
}

/// Fine surface texture in [0, 1]: three octaves of value noise at 6, 12 and 24 cycles per
/// metre (weathering, grain, joints: what stereo matches on a wall a few pixels wide).
fn fine_texture(p: DVec3) -> f64 {
    (0.5 * value_noise(p * 6.0, 21)
        + 0.3 * value_noise(p * 12.0, 22)
        + 0.2 * value_noise(p * 24.0, 23))
    .clamp(0.0, 1.0)
}

/// Linear albedo of a material at a world point: the "paint" photos and points share.
pub fn albedo(m: Material, p: DVec3, normal: DVec3) -> DVec3 {
    // Face coordinates: (along, up) on vertical faces, (x, y) on horizontal ones.
    let (u, v) = if normal.z.abs() > 0.5 {
        (p.x, p.y)
    } else if normal.x.abs() > 0.5 {
        (p.y, p.z)
    } else {
        (p.x, p.z)
    };
    match m {
        Material::Stone => {
            let course = (v / 0.5).floor();
            let offset = if course as i64 % 2 == 0 { 0.0 } else { 0.6 };
            let (fu, fv) = ((u + offset) / 1.2, v / 0.5);
            let mortar = fu - fu.floor() < 0.03 || fv - fv.floor() < 0.07;
            let block = lattice((u + offset).div_euclid(1.2) as i64, course as i64, 7, 11);
            let grain = value_noise(p * 3.0, 1);
            let base = DVec3::new(0.62, 0.55, 0.44) * (0.8 + 0.25 * block + 0.15 * grain);
            if mortar {
                DVec3::new(0.38, 0.36, 0.33)
            } else {
                base
            }
        }
        Material::Glass => DVec3::new(0.05, 0.07, 0.10) * (0.8 + 0.4 * value_noise(p * 2.0, 2)),
        Material::Marble => {
            let vein = (value_noise(p * 1.7, 3) * 9.0 + p.z * 0.8).sin().abs();
            DVec3::new(0.80, 0.78, 0.74) * (0.85 + 0.15 * vein)
        }
        Material::Pavement => {
            let (fu, fv) = (u / 1.0, v / 1.0);
            let grout = fu - fu.floor() < 0.04 || fv - fv.floor() < 0.04;
            let tile = lattice(fu.floor() as i64, fv.floor() as i64, 3, 5);
            if grout {
                DVec3::new(0.18, 0.17, 0.16)
            } else {
                DVec3::new(0.40, 0.38, 0.35)
                    * (0.75 + 0.4 * tile)
                    * (0.9 + 0.2 * value_noise(p * 4.0, 4))
            }
        }
    }
}

/// Linear [0, 1] to 8-bit sRGB.
pub fn to_srgb8(c: f64) -> u8 {
    let c = c.clamp(0.0, 1.0);
    let s = if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0 + 0.5) as u8
}
