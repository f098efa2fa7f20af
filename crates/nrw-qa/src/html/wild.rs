//! The sections about photos from the wild: licences, sharpness and exposure, and
//! near-duplicate groups.

use std::fmt::Write as _;

use super::markup::{esc, photo_figure, Inputs};
use crate::error::Result;
use crate::plots;
use crate::tables::ImageRow;

/// Photos by licence, or a line saying nobody recorded them.
pub(super) fn licences(h: &mut String, inp: &Inputs) {
    h.push_str("<h2>Licences</h2>");
    if inp.figures.licences.is_empty() {
        h.push_str("<p>No photo-info was given: every photo's licence is unknown (<code>nrw-etl ingest --photo-info FILE</code> records licence, author and source per photo).</p>");
        return;
    }
    h.push_str("<table><tr><th>licence</th><th>photos</th></tr>");
    for (l, n) in &inp.figures.licences {
        let _ = write!(h, "<tr><td>{}</td><td>{n}</td></tr>", esc(l));
    }
    h.push_str("</table>");
}

/// Sharpness and exposure of the kept photos, and the least sharp of them.
pub(super) fn sharpness(h: &mut String, inp: &Inputs) -> Result<()> {
    h.push_str("<h2>Sharpness and exposure</h2>");
    let mut kept: Vec<(&ImageRow, nrw_dataset::PhotoSignals)> = inp
        .images
        .iter()
        .filter(|r| r.verdict == nrw_dataset::scene::VERDICT_KEPT)
        .filter_map(|r| Some((r, r.signals?)))
        .collect();
    if kept.is_empty() {
        h.push_str(
            "<p>No photo signals recorded (no kept view, or ingested before they were).</p>",
        );
        return Ok(());
    }
    h.push_str("<p>Sharpness is the variance of the Laplacian of the full-size photo's grey levels, as instant-ngp's colmap2nerf records it: higher is sharper, and it grows with resolution, so compare photos of similar size. Exposure is the mean grey level (0–255) and the share of crushed (≤ 5) and clipped (≥ 250) pixels.</p><div class=\"charts\">");
    let log_sharp: Vec<f64> = kept
        .iter()
        .map(|(_, s)| (s.sharpness.max(1e-3)).log10())
        .collect();
    let lines: Vec<(&str, f64)> = inp
        .min_sharpness
        .map(|m| ("--min-sharpness", m.max(1e-3).log10()))
        .into_iter()
        .collect();
    h.push_str(&plots::histogram(
        "sharpness of kept photos",
        "log10 variance of the Laplacian",
        &[("photos", &log_sharp)],
        None,
        &lines,
    )?);
    let luma: Vec<f64> = kept.iter().map(|(_, s)| s.luma_mean).collect();
    let clipped: Vec<f64> = kept.iter().map(|(_, s)| s.bright_fraction).collect();
    let crushed: Vec<f64> = kept.iter().map(|(_, s)| s.dark_fraction).collect();
    h.push_str(&plots::histogram(
        "exposure of kept photos",
        "mean grey level",
        &[("photos", &luma)],
        Some((0.0, 255.0)),
        &[],
    )?);
    h.push_str(&plots::histogram(
        "crushed and clipped pixels",
        "fraction of the photo",
        &[("≤ 5 (crushed)", &crushed), ("≥ 250 (clipped)", &clipped)],
        Some((0.0, 1.0)),
        &[],
    )?);
    h.push_str("</div><p>The least sharp kept photos:</p><div class=\"strip\">");
    kept.sort_by(|a, b| a.1.sharpness.total_cmp(&b.1.sharpness));
    for (r, s) in kept.iter().take(4) {
        let caption = format!(
            "{} — sharpness {:.1}, mean grey {:.0}",
            r.name, s.sharpness, s.luma_mean
        );
        h.push_str(&photo_figure(inp, &r.name, &caption));
    }
    h.push_str("</div>");
    Ok(())
}

/// Each group of photos that are one picture, side by side, with its split and evidence.
pub(super) fn near_duplicates(h: &mut String, inp: &Inputs) {
    h.push_str("<h2>Near-duplicates</h2>");
    let groups = &inp.figures.near_duplicates;
    if groups.is_empty() {
        h.push_str("<p class=\"ok\">No two kept photos are one picture (resized, re-encoded, cropped or recoloured copies would be shown here; split keeps each group on one side).</p>");
        return;
    }
    let _ = write!(h, "<p>{} groups of photos that are one picture (scene/duplicates.parquet). Split keeps each group on one side, so validation never sees a copy of a training photo. Each photo: its split, and the evidence that matched it (hash bits apart of 64; correlation of the photos aligned through their cameras).</p>", groups.len());
    let split: std::collections::BTreeMap<&str, &str> = inp
        .images
        .iter()
        .filter_map(|r| Some((r.name.as_str(), r.split.as_deref()?)))
        .collect();
    for group in groups.iter().take(MAX_GROUPS_SHOWN) {
        h.push_str("<div class=\"strip\">");
        for name in group {
            let m = inp.duplicates.iter().find(|m| &m.name == name);
            let evidence = m.map_or(String::new(), |m| {
                format!(
                    "{} bits{}",
                    m.phash_distance.unwrap_or(64),
                    m.ncc.map_or(String::new(), |c| format!(", ncc {c:.3}"))
                )
            });
            let caption = format!(
                "{name} — {} ({evidence})",
                split.get(name.as_str()).copied().unwrap_or("not split")
            );
            h.push_str(&photo_figure(inp, name, &caption));
        }
        h.push_str("</div>");
    }
    if groups.len() > MAX_GROUPS_SHOWN {
        let _ = write!(
            h,
            "<p>… and {} more groups (qa.json lists them all).</p>",
            groups.len() - MAX_GROUPS_SHOWN
        );
    }
}

/// Near-duplicate groups shown with thumbnails (qa.json lists every group).
const MAX_GROUPS_SHOWN: usize = 24;
