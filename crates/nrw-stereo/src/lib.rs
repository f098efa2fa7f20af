//! Dense geometry from calibrated photos without CUDA: the PatchMatch multi-view stereo of
//! COLMAP (Schönberger et al., ECCV 2016) and Gipuma/ACMH (Galliani et al., ICCV 2015; Xu &
//! Tao, CVPR 2019) on the CPU, and COLMAP's stereo fusion of the depth maps into a cloud.
//!
//! The crate knows no file: views come in as undistorted grey images with their pinhole
//! camera and pose in a scene-local frame (f64), maps go out in memory. Reading and writing
//! COLMAP's dense workspace is nrw-colmap's; running it over a scene is nrw-pipeline's.
//!
//! Pixel convention: map pixel (col, row) holds the depth along the ray through image point
//! (col + 0.5, row + 0.5), the centre of the pixel in COLMAP's (and the SfM model's)
//! convention. COLMAP's CUDA kernel and its fusion use (col, row) instead, half a pixel off
//! the model's convention; see docs/densify.md.

pub mod fusion;
mod ncc;
pub mod patchmatch;
mod rng;
pub mod view;

pub use fusion::{
    bands_of, fuse, fuse_into, FusedCloud, FusedPoint, FusionMaps, FusionOptions, FusionStats,
    FusionView, MapReader, BAND_ROWS,
};
pub use patchmatch::{
    filter, geometric, photometric, Hypotheses, PatchMatchOptions, Source, StereoMaps,
};
pub use view::{GrayImage, Pinhole, StereoView};
