//! `cargo bench -p nrw-etl --bench jpeg_decode`
//!
//! What decoding photos as Pillow does costs (docs/bench/jpeg_decode.md): every JPEG of
//! ../shared/data through our decoder (libjpeg-turbo's C code, no SIMD), through zune-jpeg (the
//! `image` crate's decoder, ours before), and through Pillow (libjpeg-turbo with SIMD) in one
//! Python process, same files, same run: median time per photo over 7 decodes, and how many
//! pixels each gives that differ from Pillow's.

#[path = "../../../tests/support/cpu.rs"]
mod cpu;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

const ROUNDS: usize = 7;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

fn photos(root: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for dir in [
        "sacre_coeur/images",
        "sceaux_castle/images",
        "sacre_coeur/dense/images",
    ] {
        let Ok(rd) = std::fs::read_dir(root.join(dir)) else {
            continue;
        };
        for e in rd.flatten() {
            if e.path()
                .extension()
                .is_some_and(|x| x.eq_ignore_ascii_case("jpg"))
            {
                out.push(e.path());
            }
        }
    }
    out.sort();
    out
}

/// Median seconds of `f` over [`ROUNDS`] runs.
fn time<T>(f: impl Fn() -> T) -> (f64, T) {
    let mut ts = Vec::new();
    let mut last = None;
    for _ in 0..ROUNDS {
        let t = Instant::now();
        last = Some(f());
        ts.push(t.elapsed().as_secs_f64());
    }
    (median(ts), last.expect("rounds > 0"))
}

/// Pillow's decode of each file: (median seconds, RGB bytes), from one Python process.
fn pillow(files: &[PathBuf], tmp: &Path) -> (Vec<f64>, String) {
    let script = r#"
import sys, time, numpy as np, PIL
from PIL import Image, features
out = sys.argv[1]; rounds = int(sys.argv[2])
for k, p in enumerate(sys.argv[3:]):
    ts = []
    for _ in range(rounds):
        t = time.perf_counter(); a = np.asarray(Image.open(p).convert('RGB')); ts.append(time.perf_counter() - t)
    a.tofile('%s/%d.rgb' % (out, k)); ts.sort(); print(ts[len(ts) // 2])
print('Pillow %s, libjpeg-turbo %s' % (PIL.__version__, features.version('libjpeg_turbo')))
"#;
    let o = Command::new("python3")
        .args(["-c", script, tmp.to_str().unwrap(), &ROUNDS.to_string()])
        .args(files)
        .env("OMP_NUM_THREADS", "1")
        .output()
        .expect("python3");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8(o.stdout).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let (version, times) = lines.split_last().unwrap();
    (
        times.iter().map(|l| l.parse().unwrap()).collect(),
        version.to_string(),
    )
}

fn differing(a: &[u8], b: &[u8]) -> (usize, u8) {
    let n = a.chunks(3).zip(b.chunks(3)).filter(|(x, y)| x != y).count();
    let worst = a
        .iter()
        .zip(b)
        .map(|(x, y)| x.abs_diff(*y))
        .max()
        .unwrap_or(0);
    (n, worst)
}

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let files = photos(&root.join("../shared/data"));
    assert!(!files.is_empty(), "no JPEGs in ../shared/data");
    let tmp = tempfile::tempdir().unwrap();
    let (pil_times, version) = pillow(&files, tmp.path());
    let (mut ours_t, mut zune_t) = (Vec::new(), Vec::new());
    let (mut ours_d, mut zune_d, mut pixels) = (0usize, 0usize, 0usize);
    let (mut ours_w, mut zune_w) = (0u8, 0u8);
    for (k, f) in files.iter().enumerate() {
        let bytes = std::fs::read(f).unwrap();
        let pil = std::fs::read(tmp.path().join(format!("{k}.rgb"))).unwrap();
        let (t, ours) = time(|| {
            nrw_dataset::codec::decode_photo(&bytes, nrw_dataset::codec::MAX_PHOTO_PIXELS).unwrap()
        });
        ours_t.push(t);
        let (t, zune) = time(|| image::load_from_memory(&bytes).unwrap().into_rgb8());
        zune_t.push(t);
        let (n, w) = differing(ours.as_raw(), &pil);
        ours_d += n;
        ours_w = ours_w.max(w);
        let (n, w) = differing(zune.as_raw(), &pil);
        zune_d += n;
        zune_w = zune_w.max(w);
        pixels += pil.len() / 3;
    }
    let ms = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64 * 1e3;
    let (o, z, p) = (ms(&ours_t), ms(&zune_t), ms(&pil_times));
    let mut md = String::from("# JPEG decoding: Pillow's pixels, and what they cost\n\n");
    let _ = writeln!(
        md,
        "Regenerate: `cargo bench -p nrw-etl --bench jpeg_decode` (needs numpy and Pillow).\n\nMachine: {}.\n\n{} JPEGs of ../shared/data ({:.1} Mpixel in all, 0.5–1.5 Mpixel each), one thread, each decoded {ROUNDS} times; time is the mean over photos of each photo's median. Differing pixels are counted against Pillow's RGB in the same run ({version}).\n",
        cpu::describe(),
        files.len(),
        pixels as f64 / 1e6
    );
    let _ = writeln!(md, "| decoder | ms / photo | pixels differing from Pillow | largest difference (levels) |\n|---|---|---|---|");
    let pct = |d: usize| 100.0 * d as f64 / pixels as f64;
    let _ = writeln!(md, "| ours: libjpeg-turbo's decoder (mozjpeg-sys, C, no SIMD) | {o:.2} | {ours_d} ({:.3}%) | {ours_w} |", pct(ours_d));
    let _ = writeln!(md, "| zune-jpeg 0.5 (the `image` crate; ours before) | {z:.2} | {zune_d} ({:.3}%) | {zune_w} |", pct(zune_d));
    let _ = writeln!(
        md,
        "| Pillow (libjpeg-turbo with SIMD, Python) | {p:.2} | — | — |"
    );
    let _ = writeln!(
        md,
        "\nEqual pixels cost {:.2}× zune-jpeg's time ({:+.2} ms a photo) and take {:.2}× Pillow's time (Pillow's libjpeg-turbo has its SIMD kernels; ours is built without them, so that no assembler is needed to build). Peak memory is the decoded RGB buffer in all three (3 bytes a pixel) plus the decoder's row buffers.",
        o / z,
        o - z,
        o / p
    );
    let path = root.join("docs/bench/jpeg_decode.md");
    std::fs::write(&path, &md).unwrap();
    print!("{md}");
    eprintln!("wrote {}", path.display());
}
