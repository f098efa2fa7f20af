//! What each fuzz target (`fuzz/fuzz_targets/`) runs on its bytes, here so that the targets,
//! the regression tests of what they found (`tests/fuzz_regressions.rs`) and CI share one
//! definition. Each returns an error for bytes a reader refuses; none may panic or allocate
//! beyond what the bytes justify.

use crate::location::Location;

use crate::error::Result;

/// A view shard: Parquet, schema, every payload's CRC-32, then every decoder; the rows read.
pub fn shard(data: &[u8]) -> Result<usize> {
    let path = &Location::parse("fuzz.parquet");
    let bytes = bytes::Bytes::copy_from_slice(data);
    crate::views::check_shard(path, bytes.clone())?;
    let views = crate::reader::views_in(bytes, path)?;
    for v in &views {
        v.photo()?;
        v.color()?;
        v.depth()?;
        v.semantics()?;
        v.transient()?;
        v.labels()?;
        v.crop_at(1, 1, 8)?;
    }
    Ok(views.len())
}

/// One payload past the CRC-32 a mutated shard would fail, into its decoder: the first byte
/// picks the column (photo, colour render, depth, semantics, transient, labels) of a 16 × 16
/// view.
pub fn payload(data: &[u8]) -> Result<()> {
    let Some((&which, payload)) = data.split_first() else {
        return Ok(());
    };
    let p = payload.to_vec();
    let mut v = crate::ViewRow {
        image_id: 1,
        name: "fuzz".into(),
        camera_id: 1,
        model: "PINHOLE".into(),
        width: 16,
        height: 16,
        scale_x: 1.0,
        scale_y: 1.0,
        params: vec![16.0, 16.0, 8.0, 8.0],
        qvec: [1.0, 0.0, 0.0, 0.0],
        tvec: [0.0; 3],
        empty_ratio: 0.0,
        photo_png: Vec::new(),
        color_png: Vec::new(),
        depth_exr: Vec::new(),
        normal_png: None,
        semantics_png: None,
        transient_png: None,
        labels_png: None,
    };
    match which % 6 {
        0 => {
            v.photo_png = p;
            v.photo().map(|_| ())
        }
        1 => {
            v.color_png = p;
            v.color().map(|_| ())
        }
        2 => {
            v.depth_exr = p;
            v.depth().map(|_| ())
        }
        3 => {
            v.semantics_png = Some(p);
            v.semantics().map(|_| ())
        }
        4 => {
            v.transient_png = Some(p);
            v.transient().map(|_| ())
        }
        _ => {
            v.labels_png = Some(p);
            v.labels().map(|_| ())
        }
    }
}

/// A descriptor part: every row's CRC-32, then its kind and rows; the rows read.
pub fn descriptors(data: &[u8]) -> Result<usize> {
    let path = &Location::parse("part.parquet");
    let bytes = bytes::Bytes::copy_from_slice(data);
    crate::descriptors::check_part(path, bytes.clone())?;
    Ok(crate::descriptors::part_in(bytes, path)?.1.len())
}

/// A triplets table as the trainer's sampler reads it; the rows read.
pub fn triplets(data: &[u8]) -> Result<usize> {
    let path = &Location::parse("triplets.parquet");
    Ok(crate::triplets::triplets_in(bytes::Bytes::copy_from_slice(data), path)?.len())
}

/// A manifest.json.
pub fn manifest(data: &[u8]) -> Result<()> {
    crate::Manifest::parse(data, "manifest.json".into()).map(|_| ())
}

/// A photo as ingest decodes it, with the size limit lowered to 2^24 pixels so the fuzzer's
/// 512 MB allocation limit holds; its width.
pub fn photo(data: &[u8]) -> std::result::Result<u32, String> {
    crate::codec::decode_photo(data, 1 << 24).map(|i| i.width())
}
