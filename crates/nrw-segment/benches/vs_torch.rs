//! `cargo bench -p nrw-segment --bench vs_torch [-- --quick]`
//!
//! Our SegFormer against PyTorch + Hugging Face transformers on the CPU, in the same run, same
//! randomly initialised weights (b0 and b2 architecture sizes, as released), same photos,
//! same thread count: the network alone at 512², and the whole chain (processor, network,
//! post-processing to the photo's size) for a 512 × 512 and a 900 × 600 photo. Latency: one
//! photo with all threads; throughput: as many photos as threads at once (ours: one photo per
//! core; PyTorch: one batch). The peer runs from `NRW_TORCH_PYTHON` (default `python3`) with
//! torch and transformers installed; they are never dependencies. Writes
//! docs/bench/segment_speed.md.

use std::fmt::Write as _;
use std::path::Path;
use std::process::Command;
use std::time::Instant;

use image::{Rgb, RgbImage};
use nrw_segment::{segment, Mode, Parallelism, Segformer};
use rand::{Rng, SeedableRng};
use rayon::prelude::*;

#[path = "../../../tests/support/cpu.rs"]
mod cpu;

/// Makes the model (seeded random init, saved with `save_pretrained`), then times PyTorch.
/// Prints one JSON line: medians in seconds and the labels of the 900 × 600 photo.
const TORCH: &str = r#"
import sys, json, time, numpy as np, torch
from PIL import Image
from transformers import SegformerConfig, SegformerForSemanticSegmentation
from transformers.models.segformer.image_processing_pil_segformer import SegformerImageProcessorPil
size, out_dir, threads, reps = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
photos = sys.argv[5:]
torch.set_num_threads(threads); torch.set_grad_enabled(False)
dims = {"b0": dict(hidden_sizes=[32, 64, 160, 256], depths=[2, 2, 2, 2], decoder_hidden_size=256),
        "b2": dict(hidden_sizes=[64, 128, 320, 512], depths=[3, 4, 6, 3], decoder_hidden_size=768)}[size]
torch.manual_seed(0)
model = SegformerForSemanticSegmentation(SegformerConfig(num_labels=150, **dims)).eval()
model.save_pretrained(out_dir)
proc = SegformerImageProcessorPil()
def med(f, n):
    f(); ts = []
    for _ in range(n):
        s = time.perf_counter(); f(); ts.append(time.perf_counter() - s)
    return float(np.median(ts))
def chain(imgs):
    pv = proc(images=imgs, return_tensors="pt")["pixel_values"]
    logits = model(pixel_values=pv).logits
    return proc.post_process_semantic_segmentation(type("O", (), {"logits": logits})(), target_sizes=[(i.height, i.width) for i in imgs])
x = torch.randn(1, 3, 512, 512)
r = {"forward": med(lambda: model(pixel_values=x), reps)}
for p in photos:
    img = Image.open(p).convert("RGB")
    r["chain_" + p] = med(lambda: chain([img]), reps)
    r["batch_" + p] = med(lambda: chain([img] * threads), max(1, reps // 2)) / threads
    r["labels_" + p] = (chain([img])[0].numpy() + 1).astype(np.uint8).tobytes().hex()
print(json.dumps(r))
"#;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

fn time(reps: usize, mut f: impl FnMut()) -> f64 {
    f();
    median(
        (0..reps)
            .map(|_| {
                let t = Instant::now();
                f();
                t.elapsed().as_secs_f64()
            })
            .collect(),
    )
}

/// A photo with structure and noise (the network's cost does not depend on content).
fn photo(w: u32, h: u32, seed: u64) -> RgbImage {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    RgbImage::from_fn(w, h, |x, y| {
        let base = [(x / 7 + y / 11) % 255, (y / 5) % 255, (x / 3) % 255];
        Rgb(base.map(|b| (b as i32 + rng.random_range(-20..20)).clamp(0, 255) as u8))
    })
}

/// What the modes and photo sizes cost (ours, one photo per core), and the streaming
/// arg-max against the full upsampling it replaces (same labels, time and memory).
fn modes_table(md: &mut String, model: &Segformer, threads: usize, reps: usize) {
    let _ = writeln!(
        md,
        "\n## What the modes cost (ours, SegFormer-b0)\n\n\
         Time per photo with {threads} photos at once, one per core (`nrw-etl segment`'s way), the whole chain \
         including the streaming arg-max. `resize` is Hugging Face's default (one 512² pass, aspect ratio \
         squashed); `whole` keeps the aspect ratio (one pass at a shorter side of 512, the protocol behind \
         the SegFormer paper's ADE20K numbers); `slide` covers the same scaled photo with 512² windows; `crop` is the \
         published code's (one 512² pass, labels only inside the crop). The accuracy each buys cannot be \
         measured here (no ADE20K weights offline; `tests/oracles/segment_check.py` measures it where they are).\n\n\
         | photo | resize 512 | whole 512 | slide 512 | crop 512 | post-processing: streaming arg-max | full upsampling + arg-max (memory) | same labels |\n\
         |---|---|---|---|---|---|---|---|"
    );
    for (w, h) in [(900u32, 600u32), (2000, 1500), (4000, 3000)] {
        let img = photo(w, h, 7);
        let batch: Vec<RgbImage> = vec![img.clone(); threads];
        let mut cells = Vec::new();
        for mode in [
            Mode::default(),
            Mode::Whole { size: 512 },
            Mode::Slide { size: 512 },
            Mode::CenterCrop { size: 512 },
        ] {
            let t = time((reps / 2).max(1), || {
                batch.par_iter().for_each(|i| {
                    segment(model, i, mode, "bench", Parallelism::None).unwrap();
                });
            }) / threads as f64;
            cells.push(format!("{t:.3} s"));
        }
        let x = nrw_segment::preprocess::preprocess(&img, 512, 512);
        let logits = model.logits(&x, 512, 512, Parallelism::Rayon(0));
        let mut fast = Vec::new();
        let tf = time(reps, || {
            fast = nrw_segment::postprocess::labels(&logits, w as usize, h as usize)
        });
        let bytes = logits.c * (w * h) as usize * 4;
        let (tn, same) = if bytes <= 8 << 30 {
            let mut naive = Vec::new();
            let tn = time(1, || {
                naive = nrw_segment::postprocess::labels_full(&logits, w as usize, h as usize);
            });
            (
                format!("{tn:.3} s ({:.1} GB)", bytes as f64 / 1e9),
                if naive == fast { "yes" } else { "**no**" },
            )
        } else {
            ("not run".to_string(), "—")
        };
        let _ = writeln!(
            md,
            "| {w} × {h} | {} | {tf:.3} s | {tn} | {same} |",
            cells.join(" | ")
        );
        eprintln!("modes {w}×{h}: {cells:?}, post {tf:.3} s vs {tn}");
    }
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let python = std::env::var("NRW_TORCH_PYTHON").unwrap_or_else(|_| "python3".into());
    let threads = rayon::current_num_threads();
    let reps = if quick { 2 } else { 5 };
    let tmp = tempfile::tempdir().unwrap();
    let photos = [(512u32, 512u32), (900, 600)];
    let paths: Vec<_> = photos
        .iter()
        .map(|&(w, h)| {
            let p = tmp.path().join(format!("photo_{w}x{h}.png"));
            photo(w, h, w as u64).save(&p).unwrap();
            p
        })
        .collect();
    let mut md = String::from("# Segmentation speed: ours against PyTorch + transformers\n\n");
    let _ = writeln!(
        md,
        "Regenerate: `NRW_TORCH_PYTHON=/path/to/python cargo bench -p nrw-segment --bench vs_torch` (the peer \
         needs torch and transformers; never dependencies). CPU: {}. Threads: {threads} on both sides.\n\n\
         Same randomly initialised SegFormer (seeded, made by transformers, loaded by both), same photos. \
         *Network*: the forward pass alone on a 512² input. *Chain*: what `segment --mode resize` does for \
         one photo — the processor (PIL bilinear resize to 512², rescale, normalise), the network, and the \
         logits upsampled to the photo's size with the arg-max (transformers: `post_process_semantic_segmentation`). \
         Latency: one photo using all threads (median of {reps}); throughput: {threads} photos at once \
         (ours one per core, PyTorch one batch), time per photo. Ratio = PyTorch time / ours (> 1: ours faster). \
         Labels: share of the 900 × 600 photo's pixels where both give the same class (both in float32; \
         random weights make many near-ties, so this is a floor, not the parity test — that one is \
         `cargo test -p nrw-segment --test fixture`, against float64).\n\n\
         | model | work | ours | PyTorch | ratio |\n|---|---|---|---|---|",
        cpu::describe()
    );
    let mut per_photo = Vec::new();
    let mut b0 = None;
    for size in ["b0", "b2"] {
        let dir = tmp.path().join(size);
        let mut cmd = Command::new(&python);
        cmd.args(["-c", TORCH, size])
            .arg(&dir)
            .arg(threads.to_string())
            .arg(reps.to_string())
            .args(&paths);
        let out = cmd.output().expect("run the PyTorch peer");
        assert!(
            out.status.success(),
            "PyTorch peer failed (set NRW_TORCH_PYTHON to a python with torch and transformers): {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let r: serde_json::Value = serde_json::from_slice(out.stdout.trim_ascii()).unwrap();
        let model = Segformer::load(&dir).unwrap();
        if size == "b0" {
            b0 = Some(model.clone());
        }
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2);
        let x: Vec<f32> = (0..3 * 512 * 512)
            .map(|_| rng.random_range(-2.0f32..2.0))
            .collect();
        let ours = time(reps, || {
            model.logits(&x, 512, 512, Parallelism::Rayon(0));
        });
        let theirs = r["forward"].as_f64().unwrap();
        eprintln!("{size} network: ours {ours:.3} s, torch {theirs:.3} s");
        let _ = writeln!(
            md,
            "| {size} | network, 512² | {ours:.3} s | {theirs:.3} s | **{:.2}×** |",
            theirs / ours
        );
        for (&(w, h), p) in photos.iter().zip(&paths) {
            let key = p.display().to_string();
            let img = image::open(p).unwrap().to_rgb8();
            let mode = Mode::default();
            let mut labels = None;
            let lat = time(reps, || {
                labels = Some(segment(&model, &img, mode, "bench", Parallelism::Rayon(0)).unwrap());
            });
            let batch: Vec<RgbImage> = vec![img.clone(); threads];
            let thr = time((reps / 2).max(1), || {
                batch.par_iter().for_each(|i| {
                    segment(&model, i, mode, "bench", Parallelism::None).unwrap();
                });
            }) / threads as f64;
            let (tl, tt) = (
                r[format!("chain_{key}")].as_f64().unwrap(),
                r[format!("batch_{key}")].as_f64().unwrap(),
            );
            let theirs_labels = r[format!("labels_{key}")].as_str().unwrap();
            let ours_labels = labels.unwrap();
            let same = ours_labels
                .as_raw()
                .iter()
                .zip(theirs_labels.as_bytes().chunks_exact(2))
                .filter(|(a, h)| format!("{:02x}", a).as_bytes() == *h)
                .count() as f64
                / ours_labels.as_raw().len() as f64;
            eprintln!("{size} {w}×{h}: ours {lat:.3}/{thr:.3} s, torch {tl:.3}/{tt:.3} s, same labels {same:.4}");
            let _ = writeln!(md, "| {size} | chain, {w} × {h} photo, latency | {lat:.3} s | {tl:.3} s | **{:.2}×** |", tl / lat);
            let _ = writeln!(
                md,
                "| {size} | chain, {w} × {h} photo, throughput per photo | {thr:.3} s | {tt:.3} s | **{:.2}×** (labels agree on {:.2}% of pixels) |",
                tt / thr,
                same * 100.0
            );
            if (w, h) == (900, 600) {
                per_photo.push((size, thr));
            }
        }
    }
    let _ = writeln!(md, "\nWhat segmenting 10⁴ photos of 900 × 600 costs on this machine ({threads} threads, `nrw-etl segment`, one photo per core):\n");
    for (size, thr) in per_photo {
        let _ = writeln!(
            md,
            "- SegFormer-{size}: {:.2} s per photo, **{:.1} hours** for 10⁴ photos",
            thr,
            thr * 1e4 / 3600.0
        );
    }
    modes_table(&mut md, &b0.expect("b0 measured"), threads, reps);
    std::fs::create_dir_all(root.join("docs/bench")).unwrap();
    std::fs::write(root.join("docs/bench/segment_speed.md"), md).unwrap();
    eprintln!("wrote docs/bench/segment_speed.md");
}
