//! `[NRW_ISA=avx2+fma] cargo bench -p nrw-style --bench vs_torch [-- --quick]`
//!
//! Our VGG16 style forward pass (relu1_2 … relu5_2 plus the five Gram matrices), by both
//! convolution algorithms, against PyTorch and onnxruntime on the CPU in the same run, same
//! weights, same input, same thread count: latency of one photo at 256² and 512² using all
//! cores, and throughput with photos processed in parallel (ours: one photo per core; the
//! peers: one batch). Each algorithm's accuracy is its worst Gram difference from the PyTorch
//! float64 fixture in ../shared/fixtures. The peers run from `NRW_TORCH_PYTHON` (default
//! `python3`) with torch, onnx and onnxruntime installed; they are never dependencies.
//!
//! Writes docs/bench/vgg_speed.md; with `NRW_ISA=avx2+fma` (our kernels capped at AVX2 at run
//! time, and PyTorch held to AVX2 by `ATEN_CPU_CAPABILITY=avx2 ONEDNN_MAX_CPU_ISA=AVX2`), what an
//! AVX2-only machine runs, into docs/bench/vgg_speed_avx2.md. onnxruntime has no switch to
//! hold it to AVX2, so there it keeps its AVX-512 kernels (a peer with an advantage).

use std::fmt::Write as _;
use std::path::Path;
use std::process::Command;
use std::time::Instant;

use nrw_style::isa::isa;
use nrw_style::{grams, ConvAlgo, Parallelism, Vgg, STYLE_LAYERS};
use rand::{Rng, SeedableRng};
use rayon::prelude::*;

#[path = "../../../tests/support/cpu.rs"]
mod cpu;
#[path = "../../../tests/support/npy.rs"]
mod npy;

/// VGG16's trunk to relu5_2 in PyTorch, weights read from the same safetensors file (parsed by
/// hand so the benchmark needs torch and numpy only), and the same graph exported to ONNX for
/// onnxruntime. Prints JSON: median seconds of latency and batched throughput per photo for
/// both peers; saves relu1_2's Gram of the first input for the agreement check.
const PEERS: &str = r#"
import sys, json, time, io, warnings, numpy as np, torch
threads, reps = int(sys.argv[3]), int(sys.argv[4])
torch.set_num_threads(threads); torch.set_grad_enabled(False)
raw = open(sys.argv[1], "rb").read(); n = int.from_bytes(raw[:8], "little"); head = json.loads(raw[8:8 + n])
def t(name):
    m = head[name]; a, b = m["data_offsets"]
    return torch.from_numpy(np.frombuffer(raw[8 + n + a:8 + n + b], np.float32).reshape(m["shape"]).copy())
cfg = [64, 64, "M", 128, 128, "M", 256, 256, 256, "M", 512, 512, 512, "M", 512, 512]
layers, idx, c_in = [], 0, 3
for v in cfg:
    if v == "M":
        layers.append(torch.nn.MaxPool2d(2)); idx += 1
    else:
        conv = torch.nn.Conv2d(c_in, v, 3, padding=1); conv.weight.copy_(t(f"features.{idx}.weight")); conv.bias.copy_(t(f"features.{idx}.bias"))
        layers += [conv, torch.nn.ReLU()]; idx += 2; c_in = v
taps = {3, 8, 13, 20, 27}
def style(x):
    out = []
    for i, l in enumerate(layers):
        x = l(x)
        if i in taps:
            b, c, h, w = x.shape; f = x.reshape(b, c, h * w)
            out.append(torch.bmm(f, f.transpose(1, 2)) / (c * h * w))
    return out
def timed(f, runs, per):
    f(); out = []
    for _ in range(runs):
        s = time.perf_counter(); f(); out.append((time.perf_counter() - s) / per)
    return float(np.median(out))
x = torch.from_numpy(np.load(sys.argv[2]))
res = {"torch_lat": timed(lambda: style(x[:1]), reps, 1),
       "torch_thr": timed(lambda: style(x), reps, len(x)),
       "torch_version": torch.__version__}
np.save(sys.argv[5], style(x[:1])[0][0].double().numpy())
try:
    import onnxruntime as ort
    warnings.filterwarnings("ignore")
    class Style(torch.nn.Module):
        def __init__(self):
            super().__init__(); self.layers = torch.nn.ModuleList(layers)
        def forward(self, x):
            return tuple(style(x))
    buf = io.BytesIO()
    torch.onnx.export(Style(), x[:1], buf, dynamo=False, opset_version=17,
                      input_names=["x"], dynamic_axes={"x": {0: "batch"}})
    so = ort.SessionOptions(); so.intra_op_num_threads = threads; so.inter_op_num_threads = 1
    sess = ort.InferenceSession(buf.getvalue(), so, providers=["CPUExecutionProvider"])
    one, all_ = {"x": x[:1].numpy()}, {"x": x.numpy()}
    res["ort_lat"] = timed(lambda: sess.run(None, one), reps, 1)
    res["ort_thr"] = timed(lambda: sess.run(None, all_), reps, len(x))
    res["ort_version"] = ort.__version__
except Exception as e:
    print("onnxruntime not measured:", e, file=sys.stderr)
print(json.dumps(res))
"#;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

/// Median latency (one input, all threads) and throughput (one input per core) of ours.
fn time_ours(net: &Vgg, inputs: &[Vec<f32>], size: usize, reps: usize) -> (f64, f64) {
    let _ = grams(net, &inputs[0], size, size, Parallelism::Rayon(0));
    let lat = median(
        (0..reps)
            .map(|_| {
                let t = Instant::now();
                let _ = grams(net, &inputs[0], size, size, Parallelism::Rayon(0));
                t.elapsed().as_secs_f64()
            })
            .collect(),
    );
    let thr = median(
        (0..reps)
            .map(|_| {
                let t = Instant::now();
                inputs.par_iter().for_each(|x| {
                    let _ = grams(net, x, size, size, Parallelism::None);
                });
                t.elapsed().as_secs_f64() / inputs.len() as f64
            })
            .collect(),
    );
    (lat, thr)
}

/// Worst Gram difference from the PyTorch float64 fixture, relative to each Gram's largest
/// entry, over the five layers (None without ../shared).
fn fixture_error(net: &Vgg, root: &Path) -> Option<f64> {
    let path = root.join("../shared/fixtures/vgg16/100_7100_256x256.safetensors");
    let bytes = std::fs::read(path).ok()?;
    let st = safetensors::SafeTensors::deserialize(&bytes).ok()?;
    let t = st.tensor("input").ok()?;
    let input: Vec<f32> = t
        .data()
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
        .collect();
    let (h, w) = (t.shape()[2], t.shape()[3]);
    let mut worst = 0f64;
    for ((_, ours), layer) in grams(net, &input, h, w, Parallelism::Rayon(0))
        .iter()
        .zip(STYLE_LAYERS)
    {
        let want: Vec<f64> = st
            .tensor(&format!("gram_{layer}"))
            .ok()?
            .data()
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
            .collect();
        let scale = want.iter().fold(0f64, |m, v| m.max(v.abs()));
        let d = ours
            .iter()
            .zip(&want)
            .fold(0f64, |m, (a, b)| m.max((a - b).abs()));
        worst = worst.max(d / scale);
    }
    Some(worst)
}

/// The peers' JSON for one input size, or why there is none.
fn run_peers(
    python: &str,
    weights: &Path,
    x: &Path,
    g: &Path,
    threads: usize,
    reps: usize,
) -> Result<serde_json::Value, String> {
    let mut cmd = Command::new(python);
    cmd.args(["-c", PEERS])
        .arg(weights)
        .arg(x)
        .arg(threads.to_string())
        .arg(reps.to_string())
        .arg(g);
    if isa() != nrw_style::isa::Isa::Avx512 {
        cmd.env("ATEN_CPU_CAPABILITY", "avx2")
            .env("ONEDNN_MAX_CPU_ISA", "AVX2");
    }
    let o = cmd.output().map_err(|e| format!("{python}: {e}"))?;
    if !o.status.success() {
        return Err(String::from_utf8_lossy(&o.stderr).into_owned());
    }
    let err = String::from_utf8_lossy(&o.stderr);
    if !err.trim().is_empty() {
        eprintln!("{}", err.trim());
    }
    let line = String::from_utf8_lossy(&o.stdout);
    serde_json::from_str(line.lines().last().unwrap_or("")).map_err(|e| format!("{e}: {line}"))
}

/// "0.123 s | **1.50×**" for a peer's time against ours, or "not measured | —".
fn peer_cells(peer: Option<f64>, ours: f64) -> String {
    match peer {
        Some(p) => format!("{p:.3} s | **{:.2}×**", p / ours),
        None => "not measured | —".into(),
    }
}

/// Whether this CPU has AVX-512F (false off x86-64).
fn cpu_has_avx512() -> bool {
    #[cfg(target_arch = "x86_64")]
    return std::arch::is_x86_feature_detected!("avx512f");
    #[cfg(not(target_arch = "x86_64"))]
    false
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let python = std::env::var("NRW_TORCH_PYTHON").unwrap_or_else(|_| "python3".into());
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let weights = root.join("../shared/weights/vgg16_imagenet.safetensors");
    let nets: Vec<Vgg> = [ConvAlgo::Direct, ConvAlgo::Winograd]
        .into_iter()
        .map(|a| Vgg::load_with(&weights, a).expect("VGG16 weights in ../shared/weights"))
        .collect();
    let threads = rayon::current_num_threads();
    let tmp = tempfile::tempdir().unwrap();
    let reps = if quick { 3 } else { 7 };
    // A machine without AVX-512 runs AVX2 kernels whatever the build: its figures are the
    // AVX2 table's, measured without emulation.
    let real_avx2 = !cpu_has_avx512();
    let avx2_only = isa() != nrw_style::isa::Isa::Avx512;
    let (out_name, title) = if avx2_only {
        ("vgg_speed_avx2.md", " (AVX2 kernels only)")
    } else {
        ("vgg_speed.md", "")
    };
    let mut md = format!(
        "# VGG16 style forward pass{title}: ours against PyTorch and onnxruntime\n\n\
         Regenerate: `{}NRW_TORCH_PYTHON=/path/to/python cargo bench -p nrw-style --bench vs_torch` \
         (the peers need torch, onnx and onnxruntime; never dependencies).\n\n\
         CPU: {}. Our kernels' instruction set (transforms and GEMMs): {}. Threads: \
         {threads} on every side.\n\n",
        if avx2_only && !real_avx2 { "NRW_ISA=avx2+fma " } else { "" },
        cpu::describe(),
        isa().name(),
    );
    if real_avx2 {
        md += "This machine has no AVX-512, so every side runs its AVX2 kernels: no emulation, \
               onnxruntime included.\n\n";
    } else if avx2_only {
        md += "AVX2 emulation on this machine: our kernels are capped at AVX2 (`NRW_ISA`) and PyTorch runs \
               with `ATEN_CPU_CAPABILITY=avx2 ONEDNN_MAX_CPU_ISA=AVX2`. onnxruntime cannot be held to \
               AVX2 at run time, so it keeps its AVX-512 kernels here: the onnxruntime ratios of this \
               table are against a peer with wider vectors than ours.\n\n";
    }
    md += &format!(
        "Work: VGG16 to relu5_2 and the five Gram matrices of one RGB input, same weights and input \
         for every side. Latency: one photo using all threads. Throughput: as many photos as threads \
         at once — ours one photo per core, the peers one batch — time per photo. Each figure is the \
         median of {reps} runs after a warm-up. Ratio = peer time / our time (> 1: ours is faster).\n\n"
    );
    let mut accuracy = String::from(
        "## What accuracy costs in time\n\n\
         | algorithm | multiplications per output, input and output channel | latency 256² | latency 512² | \
         worst Gram difference from PyTorch float64 (fixture 100_7100, 5 layers, of the largest entry) |\n\
         |---|---|---|---|---|\n",
    );
    let mut speed = String::from(
        "## Ours (Winograd, the default) against the peers\n\n\
         | input | ours latency | PyTorch | ratio | onnxruntime | ratio | ours throughput | PyTorch | ratio | onnxruntime | ratio | relu1_2 Gram vs PyTorch f32 |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let mut lat_by_algo = vec![Vec::new(); nets.len()];
    let mut versions = String::new();
    for size in [256usize, 512] {
        let inputs: Vec<Vec<f32>> = (0..threads)
            .map(|_| {
                (0..3 * size * size)
                    .map(|_| rng.random_range(-2.0f32..2.0))
                    .collect()
            })
            .collect();
        let timings: Vec<(f64, f64)> = nets
            .iter()
            .map(|n| time_ours(n, &inputs, size, reps))
            .collect();
        for (i, (l, t)) in timings.iter().enumerate() {
            eprintln!(
                "{size}²: ours {} latency {l:.3} s, throughput {t:.3} s/photo",
                nets[i].algo.name()
            );
            lat_by_algo[i].push(*l);
        }
        let (lat, thr) = timings[1];
        let flat: Vec<f32> = inputs.iter().flatten().copied().collect();
        let x = tmp.path().join("x.npy");
        npy::write_npy_shape_f32(&x, &flat, &[threads, 3, size, size]);
        let g = tmp.path().join("g.npy");
        let peers = match run_peers(&python, &weights, &x, &g, threads, reps) {
            Ok(v) => v,
            Err(e) => {
                eprintln!("peers not measured at {size}²: {e}");
                let _ = writeln!(
                    speed,
                    "| {size}² | {lat:.3} s | not measured | — | not measured | — | {thr:.3} s | not measured | — | not measured | — | — |"
                );
                continue;
            }
        };
        let num = |k: &str| peers.get(k).and_then(|v| v.as_f64());
        eprintln!("{size}²: peers {peers}");
        if versions.is_empty() {
            versions = format!(
                "Peers: torch {}, onnxruntime {}.\n\n",
                peers["torch_version"].as_str().unwrap_or("?"),
                peers["ort_version"].as_str().unwrap_or("not installed")
            );
        }
        let theirs = npy::read_npy_f64(&g);
        let ours = grams(&nets[1], &inputs[0], size, size, Parallelism::Rayon(0));
        let big = ours[0].1.iter().fold(0f64, |m, v| m.max(v.abs()));
        let worst = ours[0]
            .1
            .iter()
            .zip(&theirs)
            .fold(0f64, |m, (a, b)| m.max((a - b).abs()));
        let _ = writeln!(
            speed,
            "| {size}² | {lat:.3} s | {} | {} | {thr:.3} s | {} | {} | {:.1e} of the largest entry |",
            peer_cells(num("torch_lat"), lat),
            peer_cells(num("ort_lat"), lat),
            peer_cells(num("torch_thr"), thr),
            peer_cells(num("ort_thr"), thr),
            worst / big
        );
    }
    for (i, net) in nets.iter().enumerate() {
        let err = fixture_error(net, &root)
            .map_or("not measured (no ../shared)".into(), |e| format!("{e:.1e}"));
        let mults = match net.algo {
            ConvAlgo::Direct => "9",
            ConvAlgo::Winograd => "2.25 (conv1_1: 9)",
        };
        let _ = writeln!(
            accuracy,
            "| {} | {mults} | {:.3} s | {:.3} s | {err} |",
            net.algo.name(),
            lat_by_algo[i].first().copied().unwrap_or(f64::NAN),
            lat_by_algo[i].get(1).copied().unwrap_or(f64::NAN),
        );
    }
    md += &versions;
    md += &speed;
    md += "\n";
    md += &accuracy;
    md += "\nThe parity tests hold every Gram within 1e-4 of PyTorch float64 for both algorithms; \
           Winograd's own error bound is tested in `nrw-style`'s unit tests (docs/style.md).\n";
    std::fs::create_dir_all(root.join("docs/bench")).unwrap();
    std::fs::write(root.join("docs/bench").join(out_name), md).unwrap();
    eprintln!("wrote docs/bench/{out_name}");
}
