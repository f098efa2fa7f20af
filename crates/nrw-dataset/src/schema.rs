//! The table descriptions in `schemas/*.toml`: one file per Parquet table, with each field's
//! type, nullability and meaning. Writers define their Arrow schemas in code; tests check
//! them against these files, so the documentation cannot drift from the bytes.

use std::path::Path;
use std::sync::Arc;

use arrow_schema::{DataType, Field, Schema};
use serde::Deserialize;

use crate::error::{DatasetError, Result};

/// One table's description as written in `schemas/`.
#[derive(Debug, Clone, Deserialize)]
pub struct TableDoc {
    /// Path of the table inside a dataset, e.g. `scene/images.parquet`.
    pub table: String,
    pub doc: String,
    pub fields: Vec<FieldDoc>,
}

/// One field of a table description.
#[derive(Debug, Clone, Deserialize)]
pub struct FieldDoc {
    pub name: String,
    /// `uint32`, `float64`, `utf8`, `bool`, `binary`, `list<float64>`, …
    #[serde(rename = "type")]
    pub ty: String,
    pub nullable: bool,
    pub doc: String,
}

/// Arrow type for a type name used in `schemas/`.
pub fn parse_type(ty: &str) -> Option<DataType> {
    if let Some(inner) = ty.strip_prefix("list<").and_then(|s| s.strip_suffix('>')) {
        return Some(DataType::List(Arc::new(Field::new(
            "item",
            parse_type(inner)?,
            false,
        ))));
    }
    Some(match ty {
        "bool" => DataType::Boolean,
        "uint8" => DataType::UInt8,
        "uint16" => DataType::UInt16,
        "uint32" => DataType::UInt32,
        "uint64" => DataType::UInt64,
        "int32" => DataType::Int32,
        "int64" => DataType::Int64,
        "float32" => DataType::Float32,
        "float64" => DataType::Float64,
        "utf8" => DataType::Utf8,
        "binary" => DataType::Binary,
        _ => return None,
    })
}

impl TableDoc {
    /// Parse a schema file.
    pub fn load(path: &Path) -> Result<TableDoc> {
        let text = std::fs::read_to_string(path).map_err(|e| DatasetError::io(path, e))?;
        toml::from_str(&text).map_err(|e| DatasetError::Schema {
            path: path.into(),
            problem: e.to_string(),
        })
    }

    /// The Arrow schema this description specifies.
    pub fn arrow_schema(&self, path: &Path) -> Result<Schema> {
        let fields = self
            .fields
            .iter()
            .map(|f| {
                let ty = parse_type(&f.ty).ok_or_else(|| DatasetError::Schema {
                    path: path.into(),
                    problem: format!("field `{}`: unknown type {:?}", f.name, f.ty),
                })?;
                Ok(Field::new(&f.name, ty, f.nullable))
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Schema::new(fields))
    }
}
