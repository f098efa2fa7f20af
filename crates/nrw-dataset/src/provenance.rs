//! What each sharded stage records about how it ran, typed: ingest's and style's parameters as
//! they go into unit records and the manifest's `parameters` (a JSON object, keys sorted), and
//! read back by field, never by a string key.

use serde::{Deserialize, Serialize};

use crate::error::{DatasetError, Result};

/// Ingest's settings and what it found, as recorded (defaults filled in), so a run can be
/// repeated and a unit checked against the others.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IngestParameters {
    /// The model's encoding: `bin` or `txt`.
    pub format: String,
    /// Which cloud was rendered (the dense PLY or the sparse points).
    pub point_source: String,
    /// Points rendered, after any clean-up.
    pub points: usize,
    pub min_dim: u32,
    pub radius: f64,
    pub max_empty: f64,
    pub min_photo_side: u32,
    pub rows_per_shard: usize,
    /// The label-map folder read (`--semantics`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub semantics: Option<String>,
    /// COLMAP's undistorter settings (`--undistort`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub undistort: Option<UndistortRecord>,
    /// What statistical outlier removal found (`--denoise`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub denoise: Option<DenoiseRecord>,
    /// Neighbours per normal estimate (`--estimate-normals`, when the cloud had none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub estimated_normals_k: Option<usize>,
    /// The SegFormer that labelled the photos (`--segment-weights`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub segment_model_sha256: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub segment_mode: Option<String>,
    /// The photo-info file read (`--photo-info`): licence, author, source per photo.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub photo_info: Option<String>,
    /// Photos less sharp than this were dropped (`--min-sharpness`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min_sharpness: Option<f64>,
}

/// The undistorter's settings, as COLMAP's image_undistorter takes them.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct UndistortRecord {
    pub blank_pixels: f64,
    pub min_scale: f64,
    pub max_scale: f64,
    pub max_image_size: Option<u64>,
}

/// Statistical outlier removal as Open3D defines it: its settings and what it found.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DenoiseRecord {
    pub k: usize,
    pub sigma: f64,
    pub mean: f64,
    pub std: f64,
    pub threshold: f64,
    pub points: usize,
    pub removed: usize,
}

/// Style's settings: which descriptors, from which weights, over how many photos.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StyleParameters {
    pub tier: String,
    /// SHA-256 of the weights file; empty for tiers without weights.
    pub weights_sha256: String,
    pub preprocess: String,
    pub photos: usize,
    pub photos_per_part: usize,
}

/// The JSON object a record holds.
pub type Parameters = serde_json::Map<String, serde_json::Value>;

/// `value` as the JSON object records hold.
pub fn to_parameters<T: Serialize>(value: &T) -> Parameters {
    match serde_json::to_value(value).expect("parameters serialise") {
        serde_json::Value::Object(m) => m,
        _ => unreachable!("parameters are structs"),
    }
}

/// The typed parameters in `map` (other stages' keys are ignored); an error names `file`
/// (where the map was read from) and the field.
pub fn from_parameters<T: for<'de> Deserialize<'de>>(
    file: &crate::Location,
    map: &Parameters,
) -> Result<T> {
    serde_json::from_value(serde_json::Value::Object(map.clone())).map_err(|e| {
        DatasetError::Value {
            path: file.into(),
            record: "parameters".into(),
            field: e.to_string(),
            problem: "missing or of another type; re-run ingest".into(),
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ingest_parameters_round_trip_and_leave_out_what_was_not_asked() {
        let p = IngestParameters {
            format: "bin".into(),
            point_source: "dense".into(),
            points: 10,
            min_dim: 600,
            radius: 1.0,
            max_empty: 0.85,
            min_photo_side: 450,
            rows_per_shard: 64,
            semantics: None,
            undistort: Some(UndistortRecord {
                blank_pixels: 0.0,
                min_scale: 0.2,
                max_scale: 2.0,
                max_image_size: None,
            }),
            denoise: None,
            estimated_normals_k: None,
            segment_model_sha256: None,
            segment_mode: None,
            photo_info: None,
            min_sharpness: None,
        };
        let mut m = to_parameters(&p);
        assert!(!m.contains_key("semantics") && !m.contains_key("denoise"));
        assert_eq!(m["undistort"]["max_image_size"], serde_json::Value::Null);
        // Another stage's keys in the same map are ignored.
        m.insert("tier".into(), "official".into());
        let back: IngestParameters = from_parameters(&"m".into(), &m).unwrap();
        assert_eq!(back, p);
        m.remove("max_empty");
        let e = from_parameters::<IngestParameters>(&"manifest.json".into(), &m)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("manifest.json") && e.contains("max_empty"),
            "{e}"
        );
    }
}
