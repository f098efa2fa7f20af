//! Activations: channels-last f32 tensors with a zero border, the one layout every layer of
//! the VGG trunk reads and writes.

use nrw_gemm::Parallelism;

use crate::matmul::gram;

/// An activation in channels-last layout with a one-pixel zero border: pixel (y, x) of the
/// image is at padded (y + 1, x + 1), its c values contiguous. The border lets a 3×3
/// convolution read its input as strided matrices (no im2col copy) and adds nothing to Grams.
#[derive(Debug, Clone)]
pub struct Activation {
    pub c: usize,
    pub h: usize,
    pub w: usize,
    /// (h + 2) × (w + 2) × c values.
    pub data: Vec<f32>,
}

impl Activation {
    /// From a planar CHW input (the preprocessed photo).
    pub fn from_chw(x: &[f32], c: usize, h: usize, w: usize) -> Activation {
        let pw = w + 2;
        let mut data = vec![0f32; (h + 2) * pw * c];
        for ch in 0..c {
            for y in 0..h {
                for xx in 0..w {
                    data[((y + 1) * pw + xx + 1) * c + ch] = x[(ch * h + y) * w + xx];
                }
            }
        }
        Activation { c, h, w, data }
    }

    /// Planar CHW copy (torch's layout, for comparisons).
    pub fn to_chw(&self) -> Vec<f32> {
        let (c, h, w, pw) = (self.c, self.h, self.w, self.w + 2);
        let mut out = vec![0f32; c * h * w];
        for y in 0..h {
            for xx in 0..w {
                let px = &self.data[((y + 1) * pw + xx + 1) * c..][..c];
                for (ch, v) in px.iter().enumerate() {
                    out[(ch * h + y) * w + xx] = *v;
                }
            }
        }
        out
    }

    /// Its Gram matrix, f64 (see [`gram`]); the zero border adds nothing.
    pub fn gram(&self, par: Parallelism) -> Vec<f64> {
        gram(self.c, self.h * self.w, &self.data, par)
    }
}
