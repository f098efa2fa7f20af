//! What every section of the page is made of: the inputs, escaping, and figures (a photo's
//! thumbnail read through the one checked join of an image name).

use std::path::Path;

use crate::tables::{ImageRow, Triplets};
use crate::thumbs::{self, THUMB};
use crate::Figures;

/// Everything the page shows.
pub struct Inputs<'a> {
    pub dir: &'a nrw_dataset::Store,
    pub manifest: &'a nrw_dataset::Manifest,
    pub figures: &'a Figures,
    pub images: &'a [ImageRow],
    pub triplets: Option<&'a Triplets>,
    pub descriptors: Option<&'a nrw_dataset::descriptors::Index>,
    pub max_empty: f64,
    pub min_side: f64,
    /// The blur filter ingest ran with, if any.
    pub min_sharpness: Option<f64>,
    /// Members of near-duplicate groups (scene/duplicates.parquet).
    pub duplicates: &'a [nrw_dataset::duplicates::Member],
}

/// `s` with HTML's special characters escaped.
pub(super) fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// An image (a data URI) with its alt text and caption.
pub(super) fn figure(uri: &str, alt: &str, caption: &str) -> String {
    format!(
        "<figure><img src=\"{uri}\" alt=\"{}\"><figcaption>{}</figcaption></figure>",
        esc(alt),
        esc(caption)
    )
}

/// A thumbnail of a photo from the scene's images folder with a caption, or the caption
/// alone where the photo cannot be read (the name is data: joined through the one check,
/// and a photo linking out of the folder is not opened).
pub(super) fn photo_figure(inp: &Inputs, name: &str, caption: &str) -> String {
    let images_dir = inp.manifest.scene.images_dir.as_deref().map(Path::new);
    let img = images_dir
        .and_then(|d| nrw_colmap::names::photo_path(d, name, false).ok())
        .and_then(|p| nrw_dataset::codec::load_photo(&p).ok());
    match img {
        Some(img) => {
            let t = thumbs::thumb(&img, THUMB);
            figure(&thumbs::data_uri(&t), name, caption)
        }
        None => format!(
            "<figure><figcaption>{} (photo not found)</figcaption></figure>",
            esc(caption)
        ),
    }
}
