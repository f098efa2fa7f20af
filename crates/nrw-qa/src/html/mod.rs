//! The report page: one HTML file, charts inline as SVG, thumbnails as data URIs, a small
//! script that checks every image decoded (a broken one logs a console error and marks the
//! page, so a headless browser test can catch it).

use nrw_dataset::split::{TRAIN, VAL};
use std::fmt::Write as _;
use std::path::Path;

use nrw_dataset::reader::Dataset;
use nrw_dataset::scene::ImageVerdict;

use crate::error::Result;
use crate::plots;
use crate::tables::ImageRow;
use crate::thumbs::{self, THUMB};
use crate::Figures;

mod markup;
mod wild;

pub use markup::Inputs;
use markup::{esc, figure, photo_figure};
use wild::{licences, near_duplicates, sharpness};

const STYLE: &str = "body{font-family:system-ui,sans-serif;margin:0 auto;max-width:1100px;padding:0 24px 48px;color:#222}
h1{margin-bottom:0}h2{border-bottom:2px solid #0072b2;padding-bottom:4px;margin-top:40px}
.sub{color:#666;margin-top:4px}.cards{display:flex;flex-wrap:wrap;gap:12px}
.card{background:#f3f6fa;border-radius:8px;padding:10px 16px;min-width:110px}.card b{display:block;font-size:26px}
.funnel{display:flex;align-items:center;gap:6px;flex-wrap:wrap}.funnel span{color:#999}
table{border-collapse:collapse;margin:8px 0}td,th{border-bottom:1px solid #ddd;padding:4px 10px;text-align:left}
.charts{display:flex;flex-wrap:wrap;gap:16px}.sheet{display:grid;grid-template-columns:repeat(4,auto);gap:6px;justify-content:start}
.sheet img,.strip img{width:220px;border-radius:3px}.strip{display:flex;gap:6px;align-items:flex-start;flex-wrap:wrap;margin-bottom:14px}
figure{margin:0}figcaption{font-size:12px;color:#555;max-width:220px;overflow-wrap:anywhere}
.warn{background:#fff4e0;border-left:4px solid #e69f00;padding:8px 12px;margin:8px 0}.ok{background:#e8f6ef;border-left:4px solid #009e73;padding:8px 12px}
.near figcaption{color:#0072b2}.far figcaption{color:#d55e00}details{margin-top:4px}code{background:#f3f3f3;padding:1px 4px}";

const CHECK: &str = "window.addEventListener('load',function(){var bad=[];document.querySelectorAll('img').forEach(function(i){if(!i.complete||i.naturalWidth===0)bad.push(i.alt||i.src.slice(0,40));});document.body.setAttribute('data-qa-images',bad.length?'broken':'ok');document.body.setAttribute('data-qa-image-count',String(document.images.length));if(bad.length)console.error('QA report: '+bad.length+' image(s) failed to load: '+bad.join(', '));});";

/// Build the page.
pub fn render(inp: &Inputs) -> Result<String> {
    let f = inp.figures;
    let mut h = String::new();
    let _ = write!(
        h,
        "<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>QA — {}</title><style>{STYLE}</style></head><body>",
        esc(&f.dataset)
    );
    let _ = write!(
        h,
        "<h1>Dataset QA</h1><p class=\"sub\">{} · scene {} · {}</p>",
        esc(&f.dataset),
        esc(&f.scene_dir),
        esc(&f.tool)
    );
    summary(&mut h, f);
    parameters(&mut h, f);
    warnings(&mut h, f);
    licences(&mut h, inp);
    drops(&mut h, inp)?;
    distributions(&mut h, inp)?;
    sharpness(&mut h, inp)?;
    near_duplicates(&mut h, inp);
    // Views are read only when something was kept (an all-dropped dataset has no shards).
    let ds = if inp.figures.counts.shard_rows > 0 {
        Some(Dataset::open(inp.dir)?)
    } else {
        None
    };
    contact_sheet(&mut h, inp, ds.as_ref())?;
    split(&mut h, inp)?;
    triplets(&mut h, inp, ds.as_ref())?;
    let _ = writeln!(h, "<script>{CHECK}</script></body></html>");
    Ok(h)
}

/// The funnel of counts from registered to split, and what the shards, descriptors and
/// triplets hold.
fn summary(h: &mut String, f: &Figures) {
    let c = &f.counts;
    h.push_str("<h2>Summary</h2><div class=\"funnel\">");
    let stages = [
        ("registered", c.registered),
        ("rendered", c.rendered),
        (nrw_dataset::scene::VERDICT_KEPT, c.kept),
        (TRAIN, c.train),
        (VAL, c.val),
    ];
    for (i, (name, n)) in stages.iter().enumerate() {
        if i > 0 {
            h.push_str("<span>→</span>");
        }
        let _ = write!(h, "<div class=\"card\"><b>{n}</b>{name}</div>");
    }
    h.push_str("</div>");
    let _ = write!(
        h,
        "<p>{} view rows in the shards; {} style descriptors; {}.</p>",
        c.shard_rows,
        c.descriptors,
        match &f.triplets {
            Some(t) => format!(
                "triplets for {} anchors (k = {}, tier {}, {} path, {}{})",
                t.anchors,
                t.k,
                esc(&t.tier),
                esc(&t.method),
                esc(&t.scope),
                t.recall_nearest
                    .map_or(String::new(), |r| format!(", recall@k {r:.3}"))
            ),
            None => "no triplets yet (run <code>nrw-etl triplets</code>)".into(),
        }
    );
}

/// Every recorded parameter and stage timing, folded.
fn parameters(h: &mut String, f: &Figures) {
    h.push_str("<details open><summary>Parameters and timings</summary><table><tr><th>parameter</th><th>value</th></tr>");
    for (k, v) in &f.parameters {
        let _ = write!(
            h,
            "<tr><td>{}</td><td>{}</td></tr>",
            esc(k),
            esc(&v.to_string())
        );
    }
    h.push_str("</table><table><tr><th>stage</th><th>seconds</th></tr>");
    for (k, v) in &f.timings {
        let _ = write!(h, "<tr><td>{}</td><td>{v:.2}</td></tr>", esc(k));
    }
    if f.timings.is_empty() {
        h.push_str("<tr><td colspan=2>no timings recorded</td></tr>");
    }
    h.push_str("</table></details>");
}

/// The warnings, each with up to 20 of its photos.
fn warnings(h: &mut String, f: &Figures) {
    h.push_str("<h2>Worth a look</h2>");
    if f.warnings.is_empty() {
        h.push_str("<p class=\"ok\">Nothing unusual found.</p>");
    }
    for w in &f.warnings {
        let _ = write!(
            h,
            "<div class=\"warn\"><b>{}</b>: {}",
            esc(&w.kind),
            esc(&w.message)
        );
        if !w.photos.is_empty() {
            let list: Vec<String> = w.photos.iter().take(20).map(|p| esc(p)).collect();
            let _ = write!(
                h,
                "<details><summary>photos</summary>{}{}</details>",
                list.join(", "),
                if w.photos.len() > 20 { " …" } else { "" }
            );
        }
        h.push_str("</div>");
    }
}

fn drops(h: &mut String, inp: &Inputs) -> Result<()> {
    let f = inp.figures;
    h.push_str("<h2>Drops</h2>");
    if f.drops.is_empty() {
        h.push_str("<p class=\"ok\">No photo was dropped.</p>");
        return Ok(());
    }
    let reason = |r: &str| match ImageVerdict::of(r) {
        Some(ImageVerdict::TooSmall) => {
            format!("photo shorter side under {:.0} px", inp.min_side)
        }
        Some(ImageVerdict::TooSparse) => {
            format!("render more than {:.0}% empty", inp.max_empty * 100.0)
        }
        Some(ImageVerdict::Unreadable) => {
            "photo or label map cannot be decoded whole: empty, truncated or corrupt".into()
        }
        Some(ImageVerdict::TooBlurry) => {
            "sharpness (variance of the Laplacian) under --min-sharpness".into()
        }
        Some(ImageVerdict::Kept) | None => r.to_string(),
    };
    h.push_str("<div class=\"charts\"><table><tr><th>reason</th><th>photos</th></tr>");
    for (r, n) in &f.drops {
        let _ = write!(
            h,
            "<tr><td>{} <small>({})</small></td><td>{n}</td></tr>",
            esc(r),
            esc(&reason(r))
        );
    }
    h.push_str("</table>");
    let bars: Vec<(String, f64)> = std::iter::once((
        nrw_dataset::scene::VERDICT_KEPT.to_string(),
        f.counts.kept as f64,
    ))
    .chain(f.drops.iter().map(|(r, n)| (r.clone(), *n as f64)))
    .collect();
    h.push_str(&plots::bars("photos by verdict", &bars)?);
    h.push_str("</div>");
    unreadable_list(h, inp);
    // A few dropped photos with the measured value, from the scene's images when reachable.
    let mut strip = String::new();
    for r in inp
        .images
        .iter()
        .filter(|r| r.verdict != nrw_dataset::scene::VERDICT_KEPT)
        .take(6)
    {
        let measured = match ImageVerdict::of(&r.verdict) {
            Some(ImageVerdict::TooSparse) => format!("{:.1}% empty", r.verdict_value * 100.0),
            Some(ImageVerdict::TooSmall) => format!("{:.0} px shorter side", r.verdict_value),
            Some(ImageVerdict::Unreadable) => r.verdict_detail.clone().unwrap_or_default(),
            Some(ImageVerdict::TooBlurry) => format!("sharpness {:.1}", r.verdict_value),
            Some(ImageVerdict::Kept) | None => format!("{}", r.verdict_value),
        };
        let caption = format!("{} — {} ({measured})", r.name, r.verdict);
        strip.push_str(&photo_figure(inp, &r.name, &caption));
    }
    let _ = write!(h, "<p>Some dropped photos, with the value that dropped them:</p><div class=\"strip\">{strip}</div>");
    Ok(())
}

/// Every unreadable photo with the decoder's message: the user must fix or remove each file.
fn unreadable_list(h: &mut String, inp: &Inputs) {
    let bad: Vec<_> = inp
        .images
        .iter()
        .filter(|r| r.verdict == nrw_dataset::VERDICT_UNREADABLE)
        .collect();
    if bad.is_empty() {
        return;
    }
    let _ = write!(
        h,
        "<p class=\"warn\">{} photo(s) could not be decoded whole and were left out; re-download or remove them:</p><table><tr><th>photo</th><th>bytes</th><th>decoder</th></tr>",
        bad.len()
    );
    for r in bad {
        let _ = write!(
            h,
            "<tr><td>{}</td><td>{:.0}</td><td>{}</td></tr>",
            esc(&r.name),
            r.verdict_value,
            esc(r.verdict_detail.as_deref().unwrap_or(""))
        );
    }
    h.push_str("</table>");
}

fn distributions(h: &mut String, inp: &Inputs) -> Result<()> {
    let im = inp.images;
    let empty: Vec<f64> = im.iter().filter_map(|r| r.empty_ratio).collect();
    let short: Vec<f64> = im
        .iter()
        .filter_map(|r| Some(r.photo_width?.min(r.photo_height?) as f64))
        .collect();
    let kept: Vec<&ImageRow> = im
        .iter()
        .filter(|r| r.verdict == nrw_dataset::scene::VERDICT_KEPT)
        .collect();
    let dmin: Vec<f64> = kept.iter().filter_map(|r| r.depth_min).collect();
    let dmax: Vec<f64> = kept.iter().filter_map(|r| r.depth_max).collect();
    let obs: Vec<f64> = im.iter().map(|r| r.num_observations as f64).collect();
    h.push_str("<h2>Distributions</h2><div class=\"charts\">");
    h.push_str(&plots::histogram(
        "empty pixels per render",
        "empty ratio",
        &[("views", &empty)],
        Some((0.0, 1.0)),
        &[("drop threshold", inp.max_empty)],
    )?);
    h.push_str(&plots::histogram(
        "photo size",
        "shorter side (px)",
        &[("photos", &short)],
        None,
        &[("minimum", inp.min_side)],
    )?);
    h.push_str(&plots::histogram(
        "depth range of kept views",
        "depth (scene units)",
        &[("nearest", &dmin), ("furthest", &dmax)],
        None,
        &[],
    )?);
    h.push_str(&plots::histogram(
        "sparse points seen per photo",
        "COLMAP observations",
        &[("photos", &obs)],
        None,
        &[],
    )?);
    h.push_str("</div>");
    Ok(())
}

fn contact_sheet(h: &mut String, inp: &Inputs, ds: Option<&Dataset>) -> Result<()> {
    h.push_str("<h2>Alignment</h2>");
    let kept: Vec<u32> = inp
        .images
        .iter()
        .filter(|r| r.verdict == nrw_dataset::scene::VERDICT_KEPT)
        .map(|r| r.image_id)
        .collect();
    let Some(ds) = ds.filter(|_| !kept.is_empty()) else {
        h.push_str("<p>No kept views to show.</p>");
        return Ok(());
    };
    h.push_str("<p>Photo | colour render | depth (near dark, far bright, empty white) | checkerboard of photo and render in 32-pixel tiles (empty render pixels show the photo dimmed): where they align, edges run straight across tile borders; a misaligned render breaks them.</p><div class=\"sheet\">");
    let step = (kept.len() / 6).max(1);
    for id in kept.iter().step_by(step).take(6) {
        let v = ds.get(*id)?;
        let photo = v.photo()?;
        let rgba = v.color()?;
        let color = thumbs::render_rgb(&rgba);
        let depth = v.depth()?;
        let empty = inp
            .images
            .iter()
            .find(|r| r.image_id == *id)
            .and_then(|r| r.empty_ratio)
            .unwrap_or(f64::NAN);
        let cells = [
            (
                thumbs::thumb(&photo, THUMB),
                format!("{} (id {id})", v.name),
            ),
            (
                thumbs::thumb(&color, THUMB),
                format!("render, {:.0}% empty", empty * 100.0),
            ),
            (
                thumbs::thumb(&thumbs::depth_rgb(&depth), THUMB),
                "depth".to_string(),
            ),
            (
                thumbs::thumb(&thumbs::checkerboard(&photo, &rgba, 32), THUMB),
                "photo / render checkerboard".to_string(),
            ),
        ];
        for (img, cap) in cells {
            h.push_str(&figure(&thumbs::data_uri(&img), &cap, &cap));
        }
    }
    h.push_str("</div>");
    Ok(())
}

fn split(h: &mut String, inp: &Inputs) -> Result<()> {
    h.push_str("<h2>Split</h2>");
    let of = |s: &str, f: &dyn Fn(&ImageRow) -> Option<f64>| -> Vec<f64> {
        inp.images
            .iter()
            .filter(|r| r.split.as_deref() == Some(s))
            .filter_map(f)
            .collect()
    };
    let c = &inp.figures.counts;
    if c.train + c.val == 0 {
        h.push_str("<p>Not split yet (run <code>nrw-etl split</code>).</p>");
        return Ok(());
    }
    let _ = write!(h, "<p>{} train, {} validation photos. Validation should look like training: similar coverage, sizes and depths.</p><div class=\"charts\">", c.train, c.val);
    let empty = |r: &ImageRow| r.empty_ratio;
    let short = |r: &ImageRow| Some(r.photo_width?.min(r.photo_height?) as f64);
    let (te, ve) = (of(TRAIN, &empty), of(VAL, &empty));
    let (ts, vs) = (of(TRAIN, &short), of(VAL, &short));
    let (td, vd) = (of(TRAIN, &|r| r.depth_max), of(VAL, &|r| r.depth_max));
    h.push_str(&plots::histogram(
        "empty ratio: train vs val",
        "empty ratio",
        &[(TRAIN, &te), (VAL, &ve)],
        Some((0.0, 1.0)),
        &[],
    )?);
    h.push_str(&plots::histogram(
        "photo size: train vs val",
        "shorter side (px)",
        &[(TRAIN, &ts), (VAL, &vs)],
        None,
        &[],
    )?);
    h.push_str(&plots::histogram(
        "furthest depth: train vs val",
        "depth (scene units)",
        &[(TRAIN, &td), (VAL, &vd)],
        None,
        &[],
    )?);
    h.push_str("</div>");
    Ok(())
}

/// The first two principal components of the descriptors (the randomised PCA the approximate
/// k-NN path uses), as plot coordinates; empty when they cannot be fitted.
fn pca2(
    dir: &nrw_dataset::Store,
    index: &nrw_dataset::descriptors::Index,
) -> Result<Vec<(f64, f64)>> {
    let n = index.entries.len();
    let spilled = match nrw_knn::Spilled::from_source(n, |sink| index.visit(dir, sink)) {
        Ok(s) => s,
        Err(nrw_knn::StreamError::Source(e)) => return Err(e.into()),
        // Descriptors the PCA cannot fit (not finite, mixed lengths) get no chart, as before.
        Err(_) => return Ok(Vec::new()),
    };
    let pca = nrw_knn::approx::Pca::fit_spilled(&spilled, 2, 0);
    Ok(pca
        .project_spilled(&spilled)
        .into_iter()
        .map(|p| (p[0] as f64, p.get(1).copied().unwrap_or(0.0) as f64))
        .collect())
}

fn triplets(h: &mut String, inp: &Inputs, ds: Option<&Dataset>) -> Result<()> {
    h.push_str("<h2>Style neighbours</h2>");
    if let Some(index) = inp.descriptors.filter(|d| d.entries.len() >= 2) {
        let desc = &index.entries;
        let xy = pca2(inp.dir, index)?;
        let split_of = |id: u32| {
            inp.images
                .iter()
                .find(|r| r.image_id == id)
                .and_then(|r| r.split.clone())
                .unwrap_or_else(|| "unsplit".into())
        };
        let mut by_split: std::collections::BTreeMap<String, Vec<(f64, f64)>> = Default::default();
        for (r, p) in desc.iter().zip(&xy) {
            by_split.entry(split_of(r.image_id)).or_default().push(*p);
        }
        h.push_str("<div class=\"charts\">");
        h.push_str(&plots::scatter(
            "style descriptors (PCA) by split",
            &by_split.into_iter().collect::<Vec<_>>(),
        )?);
        true_appearance(h, inp, desc, &xy)?;
        h.push_str("</div>");
    } else {
        h.push_str("<p>No style descriptors yet (run <code>nrw-etl style</code>).</p>");
    }
    let (Some(t), Some(ds)) = (inp.triplets, ds) else {
        h.push_str("<p>No triplets yet (run <code>nrw-etl triplets</code>).</p>");
        return Ok(());
    };
    h.push_str("<p>Anchors with their nearest (blue) and furthest (orange) photos in style: nearest should share the anchor's look (light, weather, season), furthest should not.</p>");
    let thumb_of = |id: u32| -> Result<(String, String)> {
        let v = ds.get(id)?;
        Ok((
            thumbs::data_uri(&thumbs::thumb(&v.photo()?, 160)),
            v.name.clone(),
        ))
    };
    for (anchor, near, far) in &t.sample {
        h.push_str("<div class=\"strip\">");
        let (uri, name) = thumb_of(*anchor)?;
        h.push_str(&figure(&uri, &name, &format!("anchor {name}")));
        for (class, ids) in [("near", near), ("far", far)] {
            for id in ids.iter().take(3) {
                let (uri, name) = thumb_of(*id)?;
                let _ = write!(
                    h,
                    "<div class=\"{class}\">{}</div>",
                    figure(&uri, &name, &format!("{class}: {name}"))
                );
            }
        }
        h.push_str("</div>");
    }
    Ok(())
}

/// Synthetic scenes know each photo's true appearance: the descriptors' PCA plotted by it.
fn true_appearance(
    h: &mut String,
    inp: &Inputs,
    desc: &[nrw_dataset::descriptors::Entry],
    xy: &[(f64, f64)],
) -> Result<()> {
    let truth = Path::new(&inp.manifest.scene.scene_dir).join(nrw_synth::truth::APPEARANCE);
    if let Some(labels) = std::fs::read_to_string(&truth)
        .ok()
        .and_then(|s| serde_json::from_str::<serde_json::Value>(&s).ok())
    {
        let label_of = |name: &str| {
            labels.as_array().and_then(|a| {
                a.iter()
                    .find(|t| t["name"].as_str() == Some(name))
                    .and_then(|t| t["label"].as_str().map(str::to_string))
            })
        };
        let mut by_class: std::collections::BTreeMap<String, Vec<(f64, f64)>> = Default::default();
        for (r, p) in desc.iter().zip(xy) {
            by_class
                .entry(label_of(&r.name).unwrap_or_else(|| "unknown".into()))
                .or_default()
                .push(*p);
        }
        h.push_str(&plots::scatter(
            "style descriptors (PCA) by true appearance",
            &by_class.into_iter().collect::<Vec<_>>(),
        )?);
    }
    Ok(())
}
