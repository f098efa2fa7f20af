//! `cargo bench -p nrw-etl --bench style_tiers [-- --quick]`
//!
//! What each descriptor tier costs and how well its nearest neighbours agree with the
//! reference tier (VGG16, 512² centre crop, five layers): time per photo, recall@5 and
//! recall@20 of the reference's neighbours, and (synthetic scene, where each photo's true
//! appearance is known) how often a photo's 5 nearest neighbours share its appearance.
//! Scenes: a synthetic scene with simulated times of day, and the real photos of
//! ../shared/data. Writes docs/style-tiers.md and docs/style-tiers.svg.

#[path = "../../../tests/support/cpu.rs"]
mod cpu;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use image::RgbImage;
use nrw_style::{describe, distance2, Preprocess, Tier, Vgg};
use rayon::prelude::*;

fn knn(desc: &[Vec<f32>], i: usize, k: usize) -> Vec<usize> {
    let mut d: Vec<(f64, usize)> = desc
        .iter()
        .enumerate()
        .filter(|(j, _)| *j != i)
        .map(|(j, v)| (distance2(&desc[i], v), j))
        .collect();
    d.sort_by(|a, b| a.partial_cmp(b).unwrap());
    d.into_iter().take(k).map(|(_, j)| j).collect()
}

fn recall(reference: &[Vec<f32>], other: &[Vec<f32>], k: usize) -> f64 {
    let n = reference.len();
    let k = k.min(n - 1);
    let hits: usize = (0..n)
        .map(|i| {
            let a = knn(reference, i, k);
            knn(other, i, k).iter().filter(|j| a.contains(j)).count()
        })
        .sum();
    hits as f64 / (n * k) as f64
}

fn class_agreement(desc: &[Vec<f32>], labels: &[String], k: usize) -> f64 {
    let n = desc.len();
    let hits: usize = (0..n)
        .map(|i| {
            knn(desc, i, k)
                .iter()
                .filter(|j| labels[**j] == labels[i])
                .count()
        })
        .sum();
    hits as f64 / (n * k) as f64
}

struct Scene {
    name: String,
    photos: Vec<RgbImage>,
    labels: Option<Vec<String>>,
}

fn synthetic(quick: bool, dir: &Path) -> Scene {
    let spec = nrw_synth::SceneSpec::demo().shrunk(if quick { 24 } else { 60 }, (520, 600), 10_000);
    nrw_synth::generate(&spec, dir, &|| {}).unwrap();
    let truth: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.join("ground_truth/appearance.json")).unwrap(),
    )
    .unwrap();
    let (mut photos, mut labels) = (Vec::new(), Vec::new());
    for t in truth.as_array().unwrap() {
        photos.push(
            image::open(dir.join("images").join(t["name"].as_str().unwrap()))
                .unwrap()
                .to_rgb8(),
        );
        labels.push(t["label"].as_str().unwrap().to_string());
    }
    Scene {
        name: format!("synthetic ({} photos, 4 times of day)", photos.len()),
        photos,
        labels: Some(labels),
    }
}

fn real(root: &Path) -> Scene {
    let mut photos = Vec::new();
    for scene in ["sacre_coeur", "sceaux_castle"] {
        let dir = root.join("../shared/data").join(scene).join("images");
        let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
        files.sort();
        for f in files {
            let img = image::open(&f).unwrap().to_rgb8();
            // As ingest stores them: shorter side 600.
            let s = 600.0 / img.width().min(img.height()) as f64;
            photos.push(image::imageops::resize(
                &img,
                (img.width() as f64 * s).round() as u32,
                (img.height() as f64 * s).round() as u32,
                image::imageops::FilterType::Lanczos3,
            ));
        }
    }
    Scene {
        name: format!(
            "real ({} photos of sacre_coeur and sceaux_castle)",
            photos.len()
        ),
        photos,
        labels: None,
    }
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let weights = root.join("../shared/weights/vgg16_imagenet.safetensors");
    let net = Vgg::load(&weights).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    // The official tiers run the published code's convention (tensorflow-vgg's vgg16.npy,
    // Caffe input). No Caffe-trained file is here offline: the same ImageNet weights are put
    // in that layout, so these rows show the official *definition* on these weights.
    let npy = tmp.path().join("vgg16.npy");
    let o = std::process::Command::new("python3")
        .arg(root.join("tests/oracles/make_vgg16_npy.py"))
        .arg(&weights)
        .arg(&npy)
        .output()
        .expect("python3 with numpy");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let caffe = Vgg::load(&npy).unwrap();
    let scenes = [synthetic(quick, tmp.path()), real(&root)];
    let tiers = [
        "vgg16-512",
        "official",
        "official-256",
        "vgg16-full",
        "vgg16-256",
        "vgg16-128",
        "vgg16-256-l12",
        "vgg16-256-l345",
        "vgg16-128-l1",
        "color-stats",
    ];
    let mut md = String::from("# Style descriptor tiers: accuracy versus time\n\n");
    let _ = writeln!(md, "Machine: {}.\n", cpu::describe());
    let _ = writeln!(md, "Regenerate: `cargo bench -p nrw-etl --bench style_tiers`. Reference tier: VGG16 on a 512×512 centre crop, five layers (relu1_2 … relu5_2), the paper's choice. `official` is the paper's published distance (`style_loss.compute_pairwise_style_loss_v2`): a 512 × 512 centre crop without resizing, input v·2/255 − 1 into the published VGG (tensorflow-vgg: (x + 1)·255/2, BGR, minus the Caffe means), each layer's squared Gram difference averaged over its C² entries (so relu1_2 weighs 64× more relative to relu5_2 than in the reference tier); `official-256` crops 256 × 256.\n\nWeights each tier expects: the `vgg16-*`/`vgg19-*` tiers take torchvision's ImageNet VGG as safetensors (`features.N.weight`, ImageNet mean/std input); the `official` tiers take tensorflow-vgg's `vgg16.npy` (Caffe-trained, the file the published README downloads), and each refuses the other's file. No Caffe-trained `vgg16.npy` is available offline here, so the official rows below run the *same ImageNet weights* put in tensorflow-vgg's layout (tests/oracles/make_vgg16_npy.py) with the Caffe input: they measure the official definition (crop, input, per-layer means), not the published weights; recall with the real Caffe weights is not measured. Photos are stored with shorter side 600 px, as ingest stores them. Time: median per photo, one photo per core on 2 cores (wall time / photos × 2). Recall@k: the fraction of the reference's k nearest neighbours a tier also returns (k capped at N − 1). Class@5 (synthetic only): the fraction of a photo's 5 nearest neighbours with the same simulated time of day.\n");
    let mut points: Vec<(String, f64, f64)> = Vec::new();
    for scene in &scenes {
        let _ = writeln!(md, "\n## {}\n\n| tier | dim | ms / photo | recall@5 | recall@20 | class@5 |\n|---|---|---|---|---|---|", scene.name);
        let mut reference: Option<Vec<Vec<f32>>> = None;
        for name in tiers {
            let tier = Tier::parse(name).unwrap();
            let t = Instant::now();
            let desc: Vec<Vec<f32>> = scene
                .photos
                .par_iter()
                .map(|p| {
                    let n = if matches!(tier, Tier::Official { .. }) {
                        &caffe
                    } else {
                        &net
                    };
                    describe(&tier, Some(n), p, Preprocess::Imagenet)
                        .expect("tier photos are at least 16×16")
                })
                .collect();
            let ms = t.elapsed().as_secs_f64() * 1e3 / scene.photos.len() as f64
                * rayon::current_num_threads() as f64;
            let refd = reference.get_or_insert_with(|| desc.clone());
            let (r5, r20) = (recall(refd, &desc, 5), recall(refd, &desc, 20));
            let class = scene.labels.as_ref().map_or("—".to_string(), |l| {
                format!("{:.2}", class_agreement(&desc, l, 5))
            });
            let _ = writeln!(
                md,
                "| {name} | {} | {ms:.1} | {r5:.2} | {r20:.2} | {class} |",
                desc[0].len()
            );
            eprintln!(
                "{} {name}: {ms:.1} ms, r5 {r5:.2}, r20 {r20:.2}, class {class}",
                scene.name
            );
            if scene.labels.is_some() {
                points.push((name.to_string(), ms, r5));
            }
        }
    }
    md.push_str("\nReading it: the cheap tiers are orders of magnitude faster; how much of the reference's neighbourhood they keep is the recall. The time-of-day agreement says whether a tier still separates appearances, which is what triplet mining needs.\n\n![recall@5 versus time](style-tiers.svg)\n");
    std::fs::write(root.join("docs/style-tiers.md"), md).unwrap();
    std::fs::write(root.join("docs/style-tiers.svg"), svg(&points)).unwrap();
    eprintln!("wrote docs/style-tiers.md and .svg");
}

/// recall@5 against ms/photo (log scale), one labelled point per tier.
fn svg(points: &[(String, f64, f64)]) -> String {
    let (w, h, m) = (640.0, 400.0, 60.0);
    let (lo, hi) = points.iter().fold((f64::MAX, f64::MIN), |(l, u), p| {
        (l.min(p.1.max(1e-3).log10()), u.max(p.1.max(1e-3).log10()))
    });
    let (lo, hi) = (lo.floor(), hi.ceil().max(lo.floor() + 1.0));
    let x = |ms: f64| m + (ms.max(1e-3).log10() - lo) / (hi - lo) * (w - 2.0 * m);
    let y = |r: f64| h - m - r * (h - 2.0 * m);
    let mut s = format!("<svg xmlns='http://www.w3.org/2000/svg' width='{w}' height='{h}' font-family='sans-serif' font-size='12'>\n<rect width='100%' height='100%' fill='white'/>\n");
    let _ = writeln!(s, "<text x='{}' y='24' text-anchor='middle' font-weight='bold'>recall@5 of the reference's neighbours vs ms per photo (synthetic scene)</text>", w / 2.0);
    let _ = writeln!(
        s,
        "<rect x='{m}' y='{m}' width='{}' height='{}' fill='none' stroke='#999'/>",
        w - 2.0 * m,
        h - 2.0 * m
    );
    let mut e = lo;
    while e <= hi {
        let _ = writeln!(
            s,
            "<text x='{:.1}' y='{}' text-anchor='middle'>{}</text>",
            x(10f64.powf(e)),
            h - m + 16.0,
            10f64.powf(e)
        );
        e += 1.0;
    }
    for k in 0..=4 {
        let r = k as f64 / 4.0;
        let _ = writeln!(
            s,
            "<text x='{}' y='{:.1}' text-anchor='end'>{r:.2}</text>",
            m - 6.0,
            y(r) + 4.0
        );
    }
    let _ = writeln!(
        s,
        "<text x='{}' y='{}' text-anchor='middle'>ms per photo (log)</text>",
        w / 2.0,
        h - 16.0
    );
    for (name, ms, r) in points {
        let _ = writeln!(s, "<circle cx='{:.1}' cy='{:.1}' r='4' fill='#1f77b4'/><text x='{:.1}' y='{:.1}' font-size='11'>{name}</text>", x(*ms), y(*r), x(*ms) + 6.0, y(*r) - 6.0);
    }
    s.push_str("</svg>\n");
    s
}
