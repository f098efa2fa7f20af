//! Logits → label map as `post_process_semantic_segmentation` does it (bilinear upsampling
//! of the logits to the target size, `align_corners=False`, then the arg-max over classes),
//! without ever holding the upsampled logits: a 12-megapixel photo would need 7 GB of them.
//!
//! Per 2 × 2 cell of logits only the classes that can win somewhere inside it are evaluated:
//! an interpolated value is a convex combination of its four corners, so a class whose
//! largest corner is below the best smallest corner of any class can never be the arg-max.
//! The candidates are evaluated with PyTorch's formula in PyTorch's order, in ascending
//! class order (ties go to the lower class, as `argmax` does), so the result is the full
//! evaluation's.

use rayon::prelude::*;

use crate::ops::{taps, Map, Tap};

/// Relative slack of the candidate test: an f32 convex combination can exceed its largest
/// corner by a few ulp; this keeps every class that might win.
const SLACK: f32 = 1e-5;

/// A 2 × 2 cell of logits: (upper row, lower row, left column, right column).
type Cell = (usize, usize, usize, usize);

/// Class ids (arg-max + 1: ADE ids 1…150) of `logits` upsampled to `w × h`, row-major.
pub fn labels(logits: &Map, w: usize, h: usize) -> Vec<u8> {
    let c = logits.c;
    assert!(c <= 255, "at most 255 classes fit a byte");
    let (ty, tx) = (taps(logits.h, h), taps(logits.w, w));
    let mut out = vec![0u8; w * h];
    out.par_chunks_mut(w)
        .zip(ty.par_iter())
        .for_each(|(row, t)| {
            let mut cache: Option<(Cell, Vec<usize>)> = None;
            for (px, s) in row.iter_mut().zip(&tx) {
                let cell = (t.i0, t.i1, s.i0, s.i1);
                if cache.as_ref().map(|c| c.0) != Some(cell) {
                    cache = Some((cell, candidates(logits, t, s)));
                }
                let cands = &cache.as_ref().expect("set above").1;
                *px = best(logits, t, s, cands) as u8 + 1;
            }
        });
    out
}

fn corners<'a>(m: &'a Map, t: &Tap, s: &Tap) -> [&'a [f32]; 4] {
    let at = |y: usize, x: usize| &m.data[(y * m.w + x) * m.c..][..m.c];
    [
        at(t.i0, s.i0),
        at(t.i0, s.i1),
        at(t.i1, s.i0),
        at(t.i1, s.i1),
    ]
}

/// Classes whose largest corner reaches the best smallest corner (less the slack).
fn candidates(m: &Map, t: &Tap, s: &Tap) -> Vec<usize> {
    let [a, b, c, d] = corners(m, t, s);
    let lo = |k: usize| a[k].min(b[k]).min(c[k]).min(d[k]);
    let hi = |k: usize| a[k].max(b[k]).max(c[k]).max(d[k]);
    let floor = (0..m.c).map(lo).fold(f32::NEG_INFINITY, f32::max);
    let mag = (0..m.c)
        .map(|k| hi(k).abs().max(lo(k).abs()))
        .fold(0f32, f32::max);
    let floor = floor - SLACK * mag - f32::MIN_POSITIVE;
    (0..m.c).filter(|&k| hi(k) >= floor).collect()
}

/// The arg-max among `cands` of the interpolated logits, PyTorch's arithmetic:
/// h0·(w0·v00 + w1·v01) + h1·(w0·v10 + w1·v11).
fn best(m: &Map, t: &Tap, s: &Tap, cands: &[usize]) -> usize {
    let [a, b, c, d] = corners(m, t, s);
    let mut arg = cands[0];
    let mut top = f32::NEG_INFINITY;
    for &k in cands {
        let v = t.l0 * (s.l0 * a[k] + s.l1 * b[k]) + t.l1 * (s.l0 * c[k] + s.l1 * d[k]);
        // NaN never wins; ties keep the lower class.
        if v > top {
            top = v;
            arg = k;
        }
    }
    arg
}

/// The same labels by the definition: every class interpolated at every pixel (the
/// reference the pruned arg-max is tested and benchmarked against; memory grows with
/// `w·h·classes`).
pub fn labels_full(logits: &Map, w: usize, h: usize) -> Vec<u8> {
    let up = upsample(logits, w, h);
    up.data
        .par_chunks(up.c)
        .map(|px| {
            let mut arg = 0;
            for (k, v) in px.iter().enumerate() {
                if *v > px[arg] {
                    arg = k;
                }
            }
            arg as u8 + 1
        })
        .collect()
}

/// The upsampled logits themselves (tests and diagnostics; memory grows with `w·h·classes`).
pub fn upsample(logits: &Map, w: usize, h: usize) -> Map {
    let mut out = Map::zeros(h, w, logits.c);
    crate::ops::upsample_add(&mut out, logits);
    out
}
