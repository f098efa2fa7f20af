//! `cargo bench -p nrw-style --bench vs_torch [-- --quick]`
//!
//! Our VGG16 style forward pass (relu1_2 … relu5_2 plus the five Gram matrices) against
//! PyTorch on the CPU in the same run, same weights, same input, same thread count: latency of
//! one photo at 256² and 512² using both cores, and throughput with photos processed in
//! parallel (ours: one photo per core; PyTorch: a batch over both cores). PyTorch is a
//! benchmark-only peer (`pip install torch`), never a dependency. Writes docs/bench/vgg_speed.md.

use std::fmt::Write as _;
use std::path::Path;
use std::process::Command;
use std::time::Instant;

use nrw_style::{grams, Parallelism, Vgg};
use rand::{Rng, SeedableRng};
use rayon::prelude::*;

#[path = "../../../tests/support/npy.rs"]
mod npy;

/// VGG16's trunk to relu5_2 in PyTorch, weights read from the same safetensors file (parsed by
/// hand so the benchmark needs torch and numpy only). Prints median seconds: latency, then
/// batched throughput per photo; saves relu1_2's Gram of the first input for the parity check.
const TORCH: &str = r#"
import sys, json, time, numpy as np, torch
torch.set_num_threads(int(sys.argv[3])); torch.set_grad_enabled(False)
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
x = torch.from_numpy(np.load(sys.argv[2]))
reps = int(sys.argv[4])
style(x[:1])
lat = []
for _ in range(reps):
    s = time.perf_counter(); g = style(x[:1]); lat.append(time.perf_counter() - s)
thr = []
for _ in range(max(1, reps // 2)):
    s = time.perf_counter(); style(x); thr.append((time.perf_counter() - s) / len(x))
np.save(sys.argv[5], g[0][0].double().numpy())
ort_lat = float("nan")
try:  # the same graph through onnxruntime, when it is installed (another peer, never a dependency)
    import io, warnings, onnxruntime as ort
    warnings.filterwarnings("ignore")
    class Style(torch.nn.Module):
        def __init__(self):
            super().__init__(); self.layers = torch.nn.ModuleList(layers)  # weights as parameters
        def forward(self, x):
            return tuple(style(x))
    buf = io.BytesIO()
    torch.onnx.export(Style(), x[:1], buf, dynamo=False, opset_version=17)
    so = ort.SessionOptions(); so.intra_op_num_threads = int(sys.argv[3]); so.inter_op_num_threads = 1
    sess = ort.InferenceSession(buf.getvalue(), so, providers=["CPUExecutionProvider"])
    feed = {sess.get_inputs()[0].name: x[:1].numpy()}
    sess.run(None, feed)
    ol = []
    for _ in range(reps):
        s = time.perf_counter(); sess.run(None, feed); ol.append(time.perf_counter() - s)
    ort_lat = float(np.median(ol))
except Exception as e:
    print("onnxruntime not measured:", e, file=sys.stderr)
print(np.median(lat), np.median(thr), ort_lat)
"#;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let weights = root.join("../shared/weights/vgg16_imagenet.safetensors");
    let net = Vgg::load(&weights).expect("VGG16 weights in ../shared/weights");
    let threads = rayon::current_num_threads();
    let tmp = tempfile::tempdir().unwrap();
    let reps = if quick { 3 } else { 7 };
    let mut md =
        String::from("# VGG16 style forward pass: ours against PyTorch and onnxruntime\n\n");
    let _ = writeln!(
        md,
        "Regenerate: `cargo bench -p nrw-style --bench vs_torch` (needs `pip install torch` for the peer; \
         it is never a dependency). Work: VGG16 to relu5_2 and the five Gram matrices of one RGB input, \
         same weights and input for both, {threads} threads each. Latency: one photo using all threads \
         (median of {reps}). Throughput: {threads} photos at once — ours one photo per core, PyTorch one batch \
         — time per photo. Ratio > 1 means ours is faster. onnxruntime (if installed): the same PyTorch graph \
         exported to ONNX, latency with the same thread count.\n\n\
         | input | ours latency | PyTorch latency | ratio | onnxruntime latency | ratio | ours throughput | PyTorch throughput | ratio | relu1_2 Gram agreement |\n\
         |---|---|---|---|---|---|---|---|---|---|"
    );
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    for size in [256usize, 512] {
        let inputs: Vec<Vec<f32>> = (0..threads)
            .map(|_| {
                (0..3 * size * size)
                    .map(|_| rng.random_range(-2.0f32..2.0))
                    .collect()
            })
            .collect();
        let _ = grams(&net, &inputs[0], size, size, Parallelism::Rayon(0));
        let mut g0 = Vec::new();
        let lat = median(
            (0..reps)
                .map(|_| {
                    let t = Instant::now();
                    g0 = grams(&net, &inputs[0], size, size, Parallelism::Rayon(0));
                    t.elapsed().as_secs_f64()
                })
                .collect(),
        );
        let thr = median(
            (0..(reps / 2).max(1))
                .map(|_| {
                    let t = Instant::now();
                    inputs.par_iter().for_each(|x| {
                        let _ = grams(&net, x, size, size, Parallelism::None);
                    });
                    t.elapsed().as_secs_f64() / inputs.len() as f64
                })
                .collect(),
        );
        eprintln!("{size}²: ours latency {lat:.3} s, throughput {thr:.3} s/photo");
        let flat: Vec<f32> = inputs.iter().flatten().copied().collect();
        let x = tmp.path().join("x.npy");
        npy::write_npy_shape_f32(&x, &flat, &[threads, 3, size, size]);
        let g = tmp.path().join("g.npy");
        let out = Command::new("python3")
            .args(["-c", TORCH])
            .arg(&weights)
            .arg(&x)
            .arg(threads.to_string())
            .arg(reps.to_string())
            .arg(&g)
            .output();
        let (tl, tt, ol, agree) = match out {
            Ok(o) if o.status.success() => {
                let v: Vec<f64> = String::from_utf8_lossy(&o.stdout)
                    .split_whitespace()
                    .map(|t| t.parse().unwrap())
                    .collect();
                if v.get(2).is_none_or(|t| t.is_nan()) {
                    eprintln!("{}", String::from_utf8_lossy(&o.stderr).trim());
                }
                let theirs = npy::read_npy_f64(&g);
                let ours = &g0[0].1;
                let big = ours.iter().fold(0f64, |m, v| m.max(v.abs()));
                let worst = ours
                    .iter()
                    .zip(&theirs)
                    .fold(0f64, |m, (a, b)| m.max((a - b).abs()));
                (
                    v[0],
                    v[1],
                    v.get(2).copied().unwrap_or(f64::NAN),
                    worst / big,
                )
            }
            Ok(o) => {
                eprintln!("torch failed: {}", String::from_utf8_lossy(&o.stderr));
                continue;
            }
            Err(e) => {
                eprintln!("python3: {e}");
                continue;
            }
        };
        eprintln!("{size}²: torch latency {tl:.3} s, throughput {tt:.3} s/photo; onnxruntime latency {ol:.3} s");
        let ort = if ol.is_nan() {
            "not measured | —".to_string()
        } else {
            format!("{ol:.3} s | **{:.2}×**", ol / lat)
        };
        let _ = writeln!(
            md,
            "| {size}² | {lat:.3} s | {tl:.3} s | **{:.2}×** | {ort} | {thr:.3} s | {tt:.3} s | **{:.2}×** | {agree:.1e} of the largest entry |",
            tl / lat,
            tt / thr
        );
    }
    std::fs::create_dir_all(root.join("docs/bench")).unwrap();
    std::fs::write(root.join("docs/bench/vgg_speed.md"), md).unwrap();
    eprintln!("wrote docs/bench/vgg_speed.md");
}
