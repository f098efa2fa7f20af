//! Depth priors in graphdeco 3DGS's convention (`depths/NAME.png` + `sparse/0/depth_params.json`),
//! as its `utils/camera_utils.py` and `scene/cameras.py` read them:
//!
//! ```text
//! invdepth = cv2.imread(png, -1) / 2**16 * params["scale"] + params["offset"]
//! reliable = 0.2 * params["med_scale"] <= params["scale"] <= 5 * params["med_scale"]
//! ```
//!
//! Our depth is in the model's units (no monocular fit), so `offset` is 0 and each view's
//! `scale` is chosen so its nearest depth takes the PNG's top value: the 16 bits are spent on
//! that view's range. A PNG value of 0 means no depth (graphdeco reads it as infinitely far).
//! `med_scale` is the median of the views' own scales; a view whose own scale falls under
//! graphdeco's band (all its depth far away) gets the band's floor instead, which only costs
//! it precision, so its prior is not thrown away as unreliable. A view above the band (its
//! nearest depth 5× nearer than the median's) cannot be lowered without clipping: it is
//! listed so the export can say so.

use std::collections::BTreeMap;

use nrw_dataset::depth::DepthMap;
use serde::Serialize;

/// The PNG value that reads as 1.0 (`/ 2**16`).
const PNG_ONE: f64 = 65536.0;

/// graphdeco's reliability band around `med_scale` (scene/cameras.py).
const BAND: (f64, f64) = (0.2, 5.0);

/// One view's entry of `depth_params.json`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct DepthParams {
    pub scale: f64,
    pub offset: f64,
    pub med_scale: f64,
}

/// 1/z per pixel (0 where there is no depth), in f64.
pub fn inverse_depth(depth: &DepthMap) -> Vec<f64> {
    depth
        .data
        .iter()
        .map(|&z| {
            let z = z as f64;
            if z > 0.0 && z.is_finite() {
                1.0 / z
            } else {
                0.0
            }
        })
        .collect()
}

/// The scale that maps a view's largest inverse depth to the PNG's top value (65535);
/// 0 for a view without depth.
pub fn own_scale(inv: &[f64]) -> f64 {
    let max = inv.iter().copied().fold(0.0, f64::max);
    max * PNG_ONE / (PNG_ONE - 1.0)
}

/// The 16-bit PNG values of an inverse-depth map at `scale` (0 = no depth).
pub fn quantise(inv: &[f64], scale: f64) -> Vec<u16> {
    if scale <= 0.0 {
        return vec![0; inv.len()];
    }
    // Precision is given up here: inverse depth becomes a multiple of scale / 2^16.
    inv.iter()
        .map(|&v| (v / scale * PNG_ONE).round().clamp(0.0, PNG_ONE - 1.0) as u16)
        .collect()
}

/// Every view's parameters from their own scales, and the views graphdeco will still call
/// unreliable (own scale above the band).
pub fn params(own: &BTreeMap<u32, f64>) -> (BTreeMap<u32, DepthParams>, Vec<u32>) {
    let med = median(own.values().copied().filter(|s| *s > 0.0).collect());
    let mut above = Vec::new();
    let out = own
        .iter()
        .map(|(&id, &s)| {
            let floor = BAND.0 * med;
            let scale = if s > 0.0 && s < floor {
                // The floor itself, nudged up so graphdeco's strict `<` keeps the view.
                floor * (1.0 + 1e-12)
            } else {
                s
            };
            if scale > BAND.1 * med {
                above.push(id);
            }
            let p = DepthParams {
                scale,
                offset: 0.0,
                med_scale: med,
            };
            (id, p)
        })
        .collect();
    (out, above)
}

/// The median (mean of the middle two for an even count), 0 for none.
fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        (v[n / 2 - 1] + v[n / 2]) / 2.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_png_reads_back_within_half_a_step() {
        let depth = DepthMap {
            width: 4,
            height: 1,
            data: vec![0.0, 2.0, 7.5, 1000.0],
        };
        let inv = inverse_depth(&depth);
        let s = own_scale(&inv);
        let q = quantise(&inv, s);
        assert_eq!(q[0], 0, "no depth stays 0");
        assert_eq!(q[1], 65535, "the nearest depth takes the top value");
        for (v, i) in q.iter().zip(&inv) {
            let back = *v as f64 / PNG_ONE * s;
            assert!((back - i).abs() <= s / PNG_ONE / 2.0, "{back} vs {i}");
        }
    }

    #[test]
    fn far_views_are_raised_into_the_band_and_near_ones_listed() {
        let own: BTreeMap<u32, f64> =
            [(1, 1.0), (2, 1.1), (3, 0.9), (4, 0.01), (5, 50.0), (6, 0.0)]
                .into_iter()
                .collect();
        let (p, above) = params(&own);
        let med = 1.0;
        assert!(p.values().all(|d| d.med_scale == med && d.offset == 0.0));
        assert!(p[&4].scale >= 0.2 * med, "not unreliable: {}", p[&4].scale);
        assert_eq!(p[&1].scale, 1.0);
        assert_eq!(p[&6].scale, 0.0, "a view without depth stays without");
        assert_eq!(above, vec![5]);
    }
}
