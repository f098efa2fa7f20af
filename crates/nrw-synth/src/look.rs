//! Per-photo appearance: light, sky, exposure, white balance, haze. Only the effects the
//! spec lists are drawn and applied; the others keep neutral values and are never computed.

use glam::DVec3;
use rand::Rng;
use serde::Serialize;

use crate::spec::{Appearance, EffectsSpec};

/// Everything that decides how a photo looks, recorded as ground truth.
#[derive(Debug, Clone, Serialize)]
pub struct Look {
    /// Time of day, or `None` for the flat neutral light of a spec without appearance.
    pub appearance: Option<Appearance>,
    /// Unit direction towards the sun, when there is one.
    pub sun_direction: Option<[f64; 3]>,
    pub sun: [f64; 3],
    pub ambient: [f64; 3],
    pub sky_zenith: [f64; 3],
    pub sky_horizon: [f64; 3],
    /// Night: windows glow with this radiance (per-window on/off by hash).
    pub window_glow: Option<[f64; 3]>,
    pub exposure_ev: Option<f64>,
    /// Multipliers on (r, g, b).
    pub white_balance: Option<[f64; 3]>,
    pub haze_density: Option<f64>,
}

/// A standard normal draw.
pub(crate) fn gauss<R: Rng>(rng: &mut R) -> f64 {
    // Box–Muller; one value is enough here.
    let u1: f64 = rng.random_range(f64::MIN_POSITIVE..1.0);
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

fn sun_dir(elevation_deg: f64, azimuth_deg: f64) -> DVec3 {
    let (e, a) = (elevation_deg.to_radians(), azimuth_deg.to_radians());
    // Azimuth measured from -y (the side photographers stand on) towards +x.
    DVec3::new(e.cos() * a.sin(), -e.cos() * a.cos(), e.sin())
}

impl Look {
    /// Draw a photo's look from the effects the spec lists.
    pub fn draw<R: Rng>(effects: &EffectsSpec, rng: &mut R) -> Look {
        let mut look = match &effects.appearance {
            None => Look {
                appearance: None,
                sun_direction: None,
                sun: [0.0; 3],
                ambient: [1.0; 3],
                sky_zenith: [0.62, 0.70, 0.80],
                sky_horizon: [0.62, 0.70, 0.80],
                window_glow: None,
                exposure_ev: None,
                white_balance: None,
                haze_density: None,
            },
            Some(list) => {
                let a = list[rng.random_range(0..list.len())];
                Look::of(a, rng)
            }
        };
        if let Some(s) = effects.exposure_ev {
            look.exposure_ev = Some(s * gauss(rng));
        }
        if let Some(s) = effects.white_balance {
            look.white_balance =
                Some([1.0 + s * gauss(rng), 1.0, 1.0 + s * gauss(rng)].map(|v| v.max(0.2)));
        }
        if let Some(h) = effects.haze {
            look.haze_density = Some(h * rng.random_range(0.5..1.5));
        }
        look
    }

    fn of<R: Rng>(a: Appearance, rng: &mut R) -> Look {
        let base = Look {
            appearance: Some(a),
            sun_direction: None,
            sun: [0.0; 3],
            ambient: [0.0; 3],
            sky_zenith: [0.0; 3],
            sky_horizon: [0.0; 3],
            window_glow: None,
            exposure_ev: None,
            white_balance: None,
            haze_density: None,
        };
        match a {
            Appearance::Day => Look {
                sun_direction: Some(
                    sun_dir(rng.random_range(35.0..65.0), rng.random_range(-70.0..70.0)).to_array(),
                ),
                sun: [1.25, 1.18, 1.05],
                ambient: [0.30, 0.34, 0.42],
                sky_zenith: [0.22, 0.40, 0.85],
                sky_horizon: [0.65, 0.78, 0.95],
                ..base
            },
            Appearance::Overcast => Look {
                ambient: [0.60, 0.62, 0.66],
                sky_zenith: [0.72, 0.74, 0.78],
                sky_horizon: [0.82, 0.83, 0.85],
                ..base
            },
            Appearance::Sunset => Look {
                sun_direction: Some(
                    sun_dir(rng.random_range(3.0..12.0), rng.random_range(-80.0..80.0)).to_array(),
                ),
                sun: [1.45, 0.72, 0.32],
                ambient: [0.22, 0.16, 0.20],
                sky_zenith: [0.20, 0.18, 0.42],
                sky_horizon: [0.98, 0.55, 0.28],
                ..base
            },
            Appearance::Night => Look {
                ambient: [0.020, 0.024, 0.040],
                sky_zenith: [0.005, 0.008, 0.02],
                sky_horizon: [0.02, 0.025, 0.05],
                window_glow: Some([1.1, 0.78, 0.42]),
                ..base
            },
        }
    }

    /// Sky radiance seen along a world direction.
    pub fn sky(&self, d: DVec3) -> DVec3 {
        let t = d.z.max(0.0).sqrt();
        DVec3::from_array(self.sky_horizon).lerp(DVec3::from_array(self.sky_zenith), t)
    }
}
