//! The paper's segmentation step: ADE20K-150 label maps of photos from a SegFormer the user
//! gives (Hugging Face layout: `config.json` + `model.safetensors`), on the CPU with the
//! `gemm` crate, pre- and post-processing as Hugging Face's `SegformerImageProcessor`. The
//! tool never downloads a model.

pub mod config;
pub mod error;
pub mod model;
pub mod ops;
pub mod postprocess;
pub mod preprocess;
pub mod segment;

pub use config::{SegformerConfig, ADE_CLASSES};
pub use error::{Result, SegmentError};
pub use model::{model_files, Segformer};
pub use nrw_gemm::Parallelism;
pub use ops::Map;
pub use segment::{segment, Mode, ModeKind};
