//! Renders a reconstructed point cloud from each photo's exact camera into a deep buffer
//! (depth, and colour and normals where the cloud has them) that aligns with the photo pixel
//! for pixel, and applies the paper's filters. Cost follows the scene: chunks outside a
//! view or hidden behind nearer points are skipped, and lenses without distortion run no
//! distortion code.

pub mod clean;
pub mod cloud;
mod occlusion;
mod simd;
pub mod splat;
pub mod undistort;
pub mod verdict;
pub mod view;
mod zbuffer;

pub use cloud::{Chunk, RenderCloud, CHUNK_POINTS};
pub use splat::{render, render_with, DeepBuffer, Kernel};
pub use undistort::{undistort_labels, undistort_photo, Rgb8};
pub use verdict::{FilterVerdict, Filters};
pub use view::{render_size, View};
