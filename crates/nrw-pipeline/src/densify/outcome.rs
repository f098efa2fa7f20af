//! What densify did: each view's verdict, and the reports of the stage and of a work unit.

use nrw_colmap::dense::MapPass;

use crate::Unit;

/// Why a view has (or has no) depth map.
#[derive(Debug, Clone, PartialEq)]
pub enum DensifyVerdict {
    /// Depth kept at `pixels` pixels of the final map.
    Densified { pixels: usize },
    /// No other view shares enough points at a wide enough angle.
    NoSourceView,
    /// The view sees no sparse point in front of it, so stereo has no depth range.
    NoDepthRange,
    /// The photo could not be read or undistorted.
    Unreadable(String),
}

/// One view's outcome.
#[derive(Debug, Clone)]
pub struct ViewOutcome {
    pub image_id: u32,
    pub name: String,
    pub width: u64,
    pub height: u64,
    pub verdict: DensifyVerdict,
}

/// What densify did (the whole stage, or `finalize` after its work units).
#[derive(Debug, Clone)]
pub struct DensifyReport {
    pub out: nrw_dataset::Location,
    pub views: Vec<ViewOutcome>,
    pub points: usize,
    /// Fusion's band reads (more than the bands when its cache was too small for its walks'
    /// bands) and the most map bytes it held: what `--fusion-cache-mb` cost.
    pub fusion: nrw_stereo::FusionStats,
    /// The bytes of every fused view's maps: the cache that reads each view once.
    pub fusion_all_bytes: usize,
    /// Seconds of each phase this process ran: undistortion, photometric, geometric, fusion.
    pub seconds: [Option<f64>; 4],
}

impl DensifyReport {
    /// How many views got a depth map.
    pub fn densified(&self) -> usize {
        self.views
            .iter()
            .filter(|v| matches!(v.verdict, DensifyVerdict::Densified { .. }))
            .count()
    }
}

/// What one work unit of a stereo pass did.
#[derive(Debug, Clone)]
pub struct UnitReport {
    /// Where the units build the workspace (published by `finalize`): a folder or a prefix.
    pub staging: nrw_dataset::Location,
    pub pass: MapPass,
    pub unit: Unit,
    /// Views this unit owns, of all views with sources.
    pub owned: usize,
    pub planned: usize,
    /// Views matched by this run, and views found done by an earlier (interrupted) one.
    pub computed: usize,
    pub resumed: usize,
    /// Seconds this invocation spent undistorting photos (`None`: the workspace held them).
    pub undistort_seconds: Option<f64>,
    pub seconds: f64,
}
