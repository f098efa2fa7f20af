//! The paper's filters, each drop recorded with its reason and the value measured.

use serde::{Deserialize, Serialize};

/// Filter thresholds; defaults are the paper's.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Filters {
    /// Drop a view whose render has more than this fraction of empty pixels (paper: 0.85).
    pub max_empty_ratio: f64,
    /// Drop a photo whose shorter side is under this many pixels (paper: 450). The shorter
    /// side, because training crops are square: a photo narrower than the crop's scaled
    /// size cannot give one, whichever way it is oriented.
    pub min_photo_side: u32,
}

impl Default for Filters {
    fn default() -> Self {
        Filters {
            max_empty_ratio: 0.85,
            min_photo_side: 450,
        }
    }
}

/// What happened to a photo, with the measured value behind a drop.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "verdict", rename_all = "snake_case")]
pub enum FilterVerdict {
    Kept { empty_ratio: f64 },
    TooSmall { shorter_side_px: u32 },
    TooSparse { empty_ratio: f64 },
}

impl FilterVerdict {
    /// `kept`, `too_small`, `too_sparse`.
    pub fn name(&self) -> &'static str {
        match self {
            FilterVerdict::Kept { .. } => "kept",
            FilterVerdict::TooSmall { .. } => "too_small",
            FilterVerdict::TooSparse { .. } => "too_sparse",
        }
    }

    /// The number the verdict rests on (empty ratio, or shorter side in pixels).
    pub fn value(&self) -> f64 {
        match *self {
            FilterVerdict::Kept { empty_ratio } | FilterVerdict::TooSparse { empty_ratio } => {
                empty_ratio
            }
            FilterVerdict::TooSmall { shorter_side_px } => shorter_side_px as f64,
        }
    }

    /// Whether the photo stays in the dataset.
    pub fn is_kept(&self) -> bool {
        matches!(self, FilterVerdict::Kept { .. })
    }
}

impl Filters {
    /// The size check, done before rendering (a too-small photo costs no render).
    pub fn check_size(&self, width: u64, height: u64) -> Option<FilterVerdict> {
        let side = width.min(height);
        (side < self.min_photo_side as u64).then_some(FilterVerdict::TooSmall {
            shorter_side_px: side as u32,
        })
    }

    /// The sparsity check on a render.
    pub fn check_render(&self, empty_ratio: f64) -> FilterVerdict {
        if empty_ratio > self.max_empty_ratio {
            FilterVerdict::TooSparse { empty_ratio }
        } else {
            FilterVerdict::Kept { empty_ratio }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_paper_filters_decide_at_their_thresholds_on_the_shorter_side() {
        let f = Filters::default();
        // 450 px across is kept, 449 is dropped with its value, whichever side is shorter.
        assert_eq!(f.check_size(450, 2000), None);
        assert_eq!(f.check_size(2000, 450), None);
        for (w, h) in [(449, 2000), (2000, 449)] {
            let v = f.check_size(w, h).unwrap();
            assert_eq!(
                (v.name(), v.value(), v.is_kept()),
                ("too_small", 449.0, false)
            );
        }
        // Exactly 85% empty is kept; more is dropped, the ratio recorded either way.
        let kept = f.check_render(0.85);
        assert_eq!(
            (kept.name(), kept.value(), kept.is_kept()),
            ("kept", 0.85, true)
        );
        let sparse = f.check_render(0.850001);
        assert_eq!((sparse.name(), sparse.value()), ("too_sparse", 0.850001));
    }
}
