//! Triplets as the paper's published code samples them: for an anchor, a positive drawn
//! uniformly among its `pos_k` nearest photos in style and a negative among its `neg_k`
//! furthest (defaults 5 and 13).

use std::collections::HashSet;

use nrw_dataset::triplets::TripletRow;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::error::{Result, TrainError};

/// (anchor, positive, negative) image ids.
pub type Triplet = (u32, u32, u32);

/// Draws triplets from the triplet table, keeping a held-out set of photos apart.
pub struct TripletSampler {
    train: Vec<(u32, Vec<u32>, Vec<u32>)>,
    held_out: Vec<(u32, Vec<u32>, Vec<u32>)>,
    rng: ChaCha8Rng,
}

/// Whether a photo is held out for evaluation: every `every`-th by a hash of its id, so the
/// choice does not depend on table order.
pub fn is_held_out(id: u32, every: u32) -> bool {
    every > 0 && (id.wrapping_mul(2_654_435_761) >> 7).is_multiple_of(every)
}

impl TripletSampler {
    /// `hold_out_every` = 5 keeps about a fifth of the photos out of training: they are never
    /// anchor, positive or negative of a training triplet, and serve as evaluation anchors.
    pub fn new(
        rows: &[TripletRow],
        pos_k: usize,
        neg_k: usize,
        hold_out_every: u32,
        seed: u64,
    ) -> Result<TripletSampler> {
        let k_near = rows.iter().map(|r| r.nearest_ids.len()).min().unwrap_or(0);
        let k_far = rows.iter().map(|r| r.furthest_ids.len()).min().unwrap_or(0);
        for (setting, k, held, which) in [
            ("pos_k", pos_k, k_near, "nearest"),
            ("neg_k", neg_k, k_far, "furthest"),
        ] {
            if k == 0 || k > held {
                return Err(TrainError::Setting {
                    setting,
                    problem: format!(
                        "{k}: the triplet table holds {held} {which} per anchor, and it must be between 1 and that; rerun `nrw-etl triplets --k` with a larger k or lower it"
                    ),
                });
            }
        }
        let held: HashSet<u32> = rows
            .iter()
            .map(|r| r.anchor_id)
            .filter(|id| is_held_out(*id, hold_out_every))
            .collect();
        let mut train = Vec::new();
        let mut held_out = Vec::new();
        for r in rows {
            let near = r.nearest_ids[..pos_k].to_vec();
            let far = r.furthest_ids[..neg_k].to_vec();
            if held.contains(&r.anchor_id) {
                held_out.push((r.anchor_id, near, far));
            } else {
                let keep = |v: Vec<u32>| -> Vec<u32> {
                    v.into_iter().filter(|i| !held.contains(i)).collect()
                };
                let (near, far) = (keep(near), keep(far));
                if !near.is_empty() && !far.is_empty() {
                    train.push((r.anchor_id, near, far));
                }
            }
        }
        if train.is_empty() {
            return Err(TrainError::NoTriplets {
                anchors: rows.len(),
                held_out: held.len(),
            });
        }
        Ok(TripletSampler {
            train,
            held_out,
            rng: ChaCha8Rng::seed_from_u64(seed),
        })
    }

    /// `n` training triplets drawn with replacement.
    pub fn sample(&mut self, n: usize) -> Vec<Triplet> {
        (0..n)
            .map(|_| {
                let (a, near, far) = &self.train[self.rng.random_range(0..self.train.len())];
                let p = near[self.rng.random_range(0..near.len())];
                let q = far[self.rng.random_range(0..far.len())];
                (*a, p, q)
            })
            .collect()
    }

    /// Every (anchor, positive, negative) combination of the held-out anchors.
    pub fn held_out_triplets(&self) -> Vec<Triplet> {
        let mut out = Vec::new();
        for (a, near, far) in &self.held_out {
            for p in near {
                for q in far {
                    out.push((*a, *p, *q));
                }
            }
        }
        out
    }

    /// Anchors used for training.
    pub fn train_anchors(&self) -> usize {
        self.train.len()
    }
}
