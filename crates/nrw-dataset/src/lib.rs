//! Every byte format of an nrw-etl dataset: the Parquet tables and their documented schemas,
//! the manifest, and atomic writes. The ETL and the trainer both go through this crate so
//! they can never disagree about a byte.

pub mod atomic;
pub mod checks;
pub mod codec;
pub mod corpus;
pub mod depth;
pub mod descriptors;
pub mod duplicates;
pub mod error;
pub mod fuzz_entry;
pub mod jpeg;
pub mod location;
pub mod manifest;
pub mod panic_guard;
pub mod parquet_io;
pub mod payload;
pub mod photo_info;
pub mod provenance;
pub mod publish;
pub mod reader;
pub mod resume;
pub mod sampling;
pub mod scene;
pub mod schema;
pub mod semantics;
pub mod split;
pub mod store;
pub mod thrift_bounds;
pub mod timings;
pub mod triplets;
pub mod units;
pub mod views;

pub use error::{DatasetError, Result};
pub use location::Location;
pub use store::Store;

/// Folder of the QA report inside a dataset by default (derived, not listed in the manifest).
pub const QA_DIR: &str = "qa";
/// Folder the pipeline runner exports into inside a dataset (derived, not listed).
pub const EXPORT_DIR: &str = "export";
pub use manifest::{FileEntry, Manifest, SceneSource, Tool, SCHEMA_VERSION};
pub use scene::{
    cameras_schema, images_schema, write_scene_tables, ImageOutcome, PhotoSignals, CAMERAS_TABLE,
    IMAGES_TABLE, VERDICT_KEPT, VERDICT_UNREADABLE,
};
pub use schema::TableDoc;
pub use views::{views_schema, write_shard, ViewRow};
