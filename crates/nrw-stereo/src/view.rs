//! What stereo knows of a view: its grey image, its pinhole lens and its pose.

use glam::{DMat3, DVec2, DVec3};

/// A PINHOLE lens (COLMAP's convention: the top-left pixel's centre is at (0.5, 0.5)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pinhole {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
}

impl Pinhole {
    /// The image point of a camera-space point (z > 0 is the caller's to check).
    pub fn project(&self, p: DVec3) -> DVec2 {
        DVec2::new(self.fx * p.x / p.z + self.cx, self.fy * p.y / p.z + self.cy)
    }

    /// The camera-space ray (z = 1) through an image point.
    pub fn ray(&self, u: DVec2) -> DVec3 {
        DVec3::new((u.x - self.cx) / self.fx, (u.y - self.cy) / self.fy, 1.0)
    }

    /// The ray through the centre of pixel (col, row).
    pub fn pixel_ray(&self, col: usize, row: usize) -> DVec3 {
        self.ray(DVec2::new(col as f64 + 0.5, row as f64 + 0.5))
    }

    /// K as a matrix.
    pub fn matrix(&self) -> DMat3 {
        DMat3::from_cols(
            DVec3::new(self.fx, 0.0, 0.0),
            DVec3::new(0.0, self.fy, 0.0),
            DVec3::new(self.cx, self.cy, 1.0),
        )
    }

    /// K⁻¹ as a matrix.
    pub fn inverse(&self) -> DMat3 {
        DMat3::from_cols(
            DVec3::new(1.0 / self.fx, 0.0, 0.0),
            DVec3::new(0.0, 1.0 / self.fy, 0.0),
            DVec3::new(-self.cx / self.fx, -self.cy / self.fy, 1.0),
        )
    }

    /// The lens of the image scaled by `s` (COLMAP's pixel convention: the image's corners,
    /// not its first pixel centre, scale).
    pub fn scaled(&self, sx: f64, sy: f64) -> Pinhole {
        Pinhole {
            fx: self.fx * sx,
            fy: self.fy * sy,
            cx: self.cx * sx,
            cy: self.cy * sy,
        }
    }
}

/// A grey image, intensities in [0, 1], row-major. Precision given up here: intensities
/// are f32 (8-bit photos carry less).
#[derive(Debug, Clone, PartialEq)]
pub struct GrayImage {
    pub width: usize,
    pub height: usize,
    pub data: Vec<f32>,
}

impl GrayImage {
    /// The grey image of 8-bit sRGB pixels (Rec. 601 luma, as COLMAP's `Bitmap::CloneAsGrey`).
    pub fn from_rgb8(width: usize, height: usize, rgb: &[u8]) -> GrayImage {
        let data = rgb
            .chunks_exact(3)
            .map(|p| (0.299 * p[0] as f32 + 0.587 * p[1] as f32 + 0.114 * p[2] as f32) / 255.0)
            .collect();
        GrayImage {
            width,
            height,
            data,
        }
    }

    /// The value at pixel (x, y).
    #[inline]
    pub fn at(&self, x: usize, y: usize) -> f32 {
        self.data[y * self.width + x]
    }

    /// Bilinear value at image point `u` (pixel centres at +0.5), or `None` outside the
    /// pixel centres' hull.
    #[inline]
    pub fn sample(&self, ux: f64, uy: f64) -> Option<f32> {
        let (x, y) = (ux - 0.5, uy - 0.5);
        let (last_x, last_y) = ((self.width - 1) as f64, (self.height - 1) as f64);
        if !(x >= 0.0 && y >= 0.0 && x <= last_x && y <= last_y) {
            return None;
        }
        Some(self.bilinear(x, y))
    }

    /// [`GrayImage::bilinear`] in f32, for the stereo kernel's window warps.
    #[inline]
    pub fn bilinear_f32(&self, x: f32, y: f32) -> f32 {
        // Through i32: the caller's range check keeps x, y far below 2³¹, and the 32-bit
        // conversion is the cheaper one.
        let x0 = (x as i32 as usize).min(self.width.saturating_sub(2));
        let y0 = (y as i32 as usize).min(self.height.saturating_sub(2));
        let (x1, y1) = ((x0 + 1).min(self.width - 1), (y0 + 1).min(self.height - 1));
        let (fx, fy) = (x - x0 as f32, y - y0 as f32);
        let (r0, r1) = (y0 * self.width, y1 * self.width);
        let top = self.data[r0 + x0] + (self.data[r0 + x1] - self.data[r0 + x0]) * fx;
        let bottom = self.data[r1 + x0] + (self.data[r1 + x1] - self.data[r1 + x0]) * fx;
        top + (bottom - top) * fy
    }

    /// Bilinear value at pixel coordinates (x, y) (pixel centres at integers), which the
    /// caller has checked lie within [0, width − 1] × [0, height − 1].
    #[inline]
    pub fn bilinear(&self, x: f64, y: f64) -> f32 {
        let x0 = (x as usize).min(self.width.saturating_sub(2));
        let y0 = (y as usize).min(self.height.saturating_sub(2));
        let (x1, y1) = ((x0 + 1).min(self.width - 1), (y0 + 1).min(self.height - 1));
        let (fx, fy) = ((x - x0 as f64) as f32, (y - y0 as f64) as f32);
        let (r0, r1) = (y0 * self.width, y1 * self.width);
        let top = self.data[r0 + x0] * (1.0 - fx) + self.data[r0 + x1] * fx;
        let bottom = self.data[r1 + x0] * (1.0 - fx) + self.data[r1 + x1] * fx;
        top * (1.0 - fy) + bottom * fy
    }

    /// The image halved in each dimension (2×2 box filter; an odd last row or column is
    /// averaged with itself), for the coarse scales.
    pub fn halved(&self) -> GrayImage {
        let (w, h) = (self.width.div_ceil(2), self.height.div_ceil(2));
        let mut data = Vec::with_capacity(w * h);
        for y in 0..h {
            for x in 0..w {
                let (x0, y0) = (2 * x, 2 * y);
                let (x1, y1) = ((x0 + 1).min(self.width - 1), (y0 + 1).min(self.height - 1));
                data.push(
                    (self.at(x0, y0) + self.at(x1, y0) + self.at(x0, y1) + self.at(x1, y1)) / 4.0,
                );
            }
        }
        GrayImage {
            width: w,
            height: h,
            data,
        }
    }
}

/// A view as stereo sees it: grey image, lens, and its world→camera pose in the scene-local
/// frame (re-centred in f64 by the caller, so UTM-sized coordinates keep their digits).
#[derive(Debug, Clone)]
pub struct StereoView {
    /// The view's identity (its image id): it seeds the view's random draws, so a view draws
    /// the same numbers whatever frame its pose is given in.
    pub id: u64,
    pub image: GrayImage,
    pub lens: Pinhole,
    pub rotation: DMat3,
    pub translation: DVec3,
}

impl StereoView {
    /// The camera centre in the local frame.
    pub fn centre(&self) -> DVec3 {
        -(self.rotation.transpose() * self.translation)
    }

    /// The view at half the size, its lens scaled by the sizes' true ratio.
    pub fn halved(&self) -> StereoView {
        let image = self.image.halved();
        let sx = image.width as f64 / self.image.width as f64;
        let sy = image.height as f64 / self.image.height as f64;
        StereoView {
            id: self.id,
            lens: self.lens.scaled(sx, sy),
            image,
            rotation: self.rotation,
            translation: self.translation,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bilinear_sampling_reads_pixel_centres_exactly_and_refuses_outside() {
        let img = GrayImage {
            width: 3,
            height: 2,
            data: vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0],
        };
        assert_eq!(img.sample(0.5, 0.5), Some(0.0));
        assert_eq!(img.sample(1.5, 1.5), Some(4.0));
        assert_eq!(img.sample(1.0, 0.5), Some(0.5));
        assert_eq!(img.sample(1.0, 1.0), Some(2.0));
        assert_eq!(img.sample(0.4, 0.5), None);
        assert_eq!(img.sample(3.2, 0.5), None);
        assert_eq!(img.sample(f64::NAN, 0.5), None);
    }

    #[test]
    fn a_point_projects_back_onto_its_pixel_ray() {
        let k = Pinhole {
            fx: 500.0,
            fy: 480.0,
            cx: 320.0,
            cy: 240.0,
        };
        let r = k.pixel_ray(10, 20) * 7.0;
        let u = k.project(r);
        assert!((u.x - 10.5).abs() < 1e-12 && (u.y - 20.5).abs() < 1e-12);
        let m = k.matrix() * k.inverse();
        assert!((m - DMat3::IDENTITY).abs_diff_eq(DMat3::ZERO, 1e-15));
    }
}
