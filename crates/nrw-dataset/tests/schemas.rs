//! The writers' Arrow schemas must equal the documentation in schemas/, field for field.

use std::path::{Path, PathBuf};

use arrow_schema::SchemaRef;
use nrw_dataset::{cameras_schema, images_schema, TableDoc, CAMERAS_TABLE, IMAGES_TABLE};

fn schemas_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../schemas")
}

/// Every table the crate writes: (schema file, table path, writer schema).
fn written_tables() -> Vec<(&'static str, &'static str, SchemaRef)> {
    vec![
        ("scene_cameras.toml", CAMERAS_TABLE, cameras_schema()),
        ("scene_images.toml", IMAGES_TABLE, images_schema()),
        (
            "scene_photos.toml",
            nrw_dataset::photo_info::PHOTOS_TABLE,
            nrw_dataset::photo_info::photos_schema(),
        ),
        (
            "scene_duplicates.toml",
            nrw_dataset::duplicates::DUPLICATES_TABLE,
            nrw_dataset::duplicates::duplicates_schema(),
        ),
        (
            "views.toml",
            "shards/views-NNNNN.parquet",
            nrw_dataset::views_schema(),
        ),
        (
            "descriptors.toml",
            "descriptors/part-NNNNN.parquet",
            nrw_dataset::descriptors::descriptors_schema(),
        ),
        (
            "triplets.toml",
            nrw_dataset::triplets::TRIPLETS_TABLE,
            nrw_dataset::triplets::triplets_schema(),
        ),
        (
            "corpus.toml",
            nrw_dataset::corpus::CORPUS_FILE,
            nrw_dataset::corpus::corpus_schema(),
        ),
        (
            "splits.toml",
            nrw_dataset::split::SPLITS_TABLE,
            nrw_dataset::split::splits_schema(),
        ),
    ]
}

#[test]
fn writer_schemas_equal_the_schema_files() {
    for (file, table, schema) in written_tables() {
        let path = schemas_dir().join(file);
        let doc = TableDoc::load(&path).unwrap();
        assert_eq!(doc.table, table, "{file}");
        let want = doc.arrow_schema(&path).unwrap();
        let got: Vec<_> = schema
            .fields()
            .iter()
            .map(|f| (f.name().clone(), f.data_type().clone(), f.is_nullable()))
            .collect();
        let exp: Vec<_> = want
            .fields()
            .iter()
            .map(|f| (f.name().clone(), f.data_type().clone(), f.is_nullable()))
            .collect();
        assert_eq!(got, exp, "{file} disagrees with the writer");
        assert!(
            doc.fields.iter().all(|f| !f.doc.trim().is_empty()),
            "{file}: every field documented"
        );
    }
}

#[test]
fn every_schema_file_describes_a_written_table() {
    let documented: Vec<String> = std::fs::read_dir(schemas_dir())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".toml"))
        .collect();
    let written: Vec<&str> = written_tables().iter().map(|t| t.0).collect();
    for d in &documented {
        assert!(
            written.contains(&d.as_str()),
            "schemas/{d} describes no table this crate writes"
        );
    }
}
