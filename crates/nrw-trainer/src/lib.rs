//! The trainer side of the workspace: consumes a dataset through `nrw_dataset::reader` only
//! (never ETL internals) and proves it is fit for training by pretraining the paper's
//! appearance encoder on its style triplets.

pub mod error;
pub mod loader;
pub mod model;
pub mod train;

pub use error::{Result, TrainError};
pub use loader::{Batch, Loader, LoaderConfig};
pub use nrw_dataset::sampling::TripletSampler;
pub use train::{train, Report, TrainConfig};
