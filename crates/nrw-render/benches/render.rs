//! `cargo bench -p nrw-render --bench render [-- accuracy|speed] [--quick]`
//!
//! accuracy: on a synthetic scene with true depth, for splat radius 0–3 and three render
//!   scales: surface coverage, depth error on the landmark, empty ratio and time per view.
//!   Writes docs/accuracy-vs-time.md and docs/accuracy-vs-time.svg.
//! speed: the same cloud and PINHOLE cameras rendered by us (colour + depth) and by Open3D's
//!   `project_to_depth_image` (depth only) in the same run, at 10⁵, 10⁶ and 10⁷ points;
//!   ratio, points/s, views/s. Writes docs/bench/render_speed.md. Needs `pip install open3d`.
//!   `--ours-only` times only ours and writes nothing (for trying changes).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use glam::DVec3;
use nrw_colmap::{read_model, read_ply, Format};
use nrw_dataset::depth::read_exr;
use nrw_render::{render, render_size, render_with, Kernel, RenderCloud, View};
use nrw_synth::geometry::Landmark;
use nrw_synth::SceneSpec;
use rand::SeedableRng;
use rayon::prelude::*;

#[path = "../../../tests/support/npy.rs"]
mod npy;
use npy::write_npy_f32 as write_npy;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.partial_cmp(b).unwrap());
    v[v.len() / 2]
}

struct Row {
    min_dim: u32,
    radius: f32,
    ms: f64,
    coverage: f64,
    empty: f64,
    median_err: f64,
    within: f64,
}

/// Rounds of the accuracy table's timing (each renders every row's views once).
const ACCURACY_ROUNDS: usize = 7;

fn accuracy(quick: bool) {
    let points = SceneSpec::demo().geometry.points;
    let mut spec = SceneSpec::demo().shrunk(if quick { 3 } else { 8 }, (600, 600), points);
    spec.effects = Default::default();
    let dir = tempfile::tempdir().unwrap();
    nrw_synth::generate(&spec, dir.path(), &|| {}).unwrap();
    let rec = read_model(&dir.path().join("sparse/0"), Some(Format::Binary)).unwrap();
    let cloud = read_ply(&dir.path().join("dense/fused.ply")).unwrap();
    let origin = rec.scene_origin();
    let rc = RenderCloud::from_ply(origin, &cloud);
    let truth: Vec<_> = rec
        .images
        .values()
        .map(|img| {
            let stem = Path::new(&img.name).with_extension("");
            let d = read_exr(
                &dir.path()
                    .join("ground_truth/depth")
                    .join(format!("{}.exr", stem.display())),
            )
            .unwrap();
            let l = image::open(
                dir.path()
                    .join("ground_truth/semantics")
                    .join(format!("{}.png", stem.display())),
            )
            .unwrap()
            .to_luma8();
            (img, d, l)
        })
        .collect();
    // Every (resolution, radius, view) is timed once per round with the rounds outermost, so
    // each sees several phases of a shared machine; its best round counts (interference only
    // slows a run down), then the median over views.
    let configs: Vec<(u32, f32)> = [300u32, 600, 900]
        .into_iter()
        .flat_map(|m| [0.0f32, 0.5, 1.0, 1.5, 2.0, 3.0].map(|r| (m, r)))
        .collect();
    let views: Vec<Vec<View>> = configs
        .iter()
        .map(|&(min_dim, radius)| {
            truth
                .iter()
                .map(|(img, _, _)| {
                    let cam = &rec.cameras[&img.camera_id];
                    let (w, h) = render_size(cam.width, cam.height, min_dim);
                    View::new(img, cam, origin, w, h, radius)
                })
                .collect()
        })
        .collect();
    let mut best = vec![vec![f64::INFINITY; truth.len()]; configs.len()];
    for _ in 0..ACCURACY_ROUNDS {
        for (vs, bs) in views.iter().zip(&mut best) {
            for (view, b) in vs.iter().zip(bs.iter_mut()) {
                let t = Instant::now();
                std::hint::black_box(render(view, &rc));
                *b = b.min(t.elapsed().as_secs_f64());
            }
        }
    }
    let mut rows = Vec::new();
    for ((&(min_dim, radius), vs), times) in configs.iter().zip(&views).zip(best) {
        let mut errs = Vec::new();
        let (mut surface, mut covered_surface, mut empty_sum) = (0usize, 0usize, 0.0);
        for ((_, gt, labels), view) in truth.iter().zip(vs) {
            let (w, h) = (view.width, view.height);
            let buf = render(view, &rc);
            empty_sum += buf.empty_ratio();
            for y in 0..h as usize {
                let py = (((y as f64 + 0.5) / view.scale.y) as usize).min(gt.height - 1);
                for x in 0..w as usize {
                    let px = (((x as f64 + 0.5) / view.scale.x) as usize).min(gt.width - 1);
                    let t = gt.data[py * gt.width + px];
                    if t <= 0.0 {
                        continue;
                    }
                    surface += 1;
                    let d = buf.depth[y * w as usize + x];
                    if d > 0.0 {
                        covered_surface += 1;
                        let l = labels.get_pixel(px as u32, py as u32)[0];
                        if [2u8, 9, 43].contains(&l) {
                            errs.push(((d - t) / t).abs() as f64);
                        }
                    }
                }
            }
        }
        let within = errs.iter().filter(|e| **e <= 0.01).count() as f64 / errs.len().max(1) as f64;
        let row = Row {
            min_dim,
            radius,
            ms: median(times) * 1e3,
            coverage: covered_surface as f64 / surface as f64,
            empty: empty_sum / truth.len() as f64,
            median_err: if errs.is_empty() {
                f64::NAN
            } else {
                median(errs)
            },
            within,
        };
        eprintln!(
            "min_dim {min_dim} r {radius}: {:.2} ms, coverage {:.3}, median err {:.4}",
            row.ms, row.coverage, row.median_err
        );
        rows.push(row);
    }
    let mut md = String::from("# Accuracy versus time: splat radius and render resolution\n\n");
    let _ = writeln!(
        md,
        "Regenerate: `cargo bench -p nrw-render --bench render -- accuracy`. Scene: the demo landmark \
         ({} dense points, {} photos with shorter side 600 px, no photo effects), true depth from the \
         generator. *Surface coverage*: rendered pixels among pixels whose true depth has a surface \
         (sky excluded). *Depth error*: |rendered − true| / true on landmark pixels (building, windows, \
         columns), with true depth looked up at the photo pixel under each render pixel. *Empty*: the \
         fraction the 85% filter sees. Time: per view (best of {} rounds that each time every row, median over the {} views; SIMPLE_RADIAL lens, AVX2 kernel where the CPU has it) on this machine (2 cores, one view per core \
         in ingest); compare rows, not machines.\n",
        cloud.len(),
        truth.len(),
        ACCURACY_ROUNDS,
        truth.len()
    );
    md.push_str("| min dim (px) | radius (px) | ms / view | surface coverage | empty ratio | median depth error | within 1% |\n|---|---|---|---|---|---|---|\n");
    for r in &rows {
        let _ = writeln!(
            md,
            "| {} | {} | {:.2} | {:.1}% | {:.1}% | {:.2}% | {:.1}% |",
            r.min_dim,
            r.radius,
            r.ms,
            r.coverage * 100.0,
            r.empty * 100.0,
            r.median_err * 100.0,
            r.within * 100.0
        );
    }
    md.push_str(
        "\nReading it: coverage grows with the radius and falls with resolution (the same points \
         spread over more pixels); depth error grows with the radius (a splat gives its depth to \
         pixels up to r away) and is worst at r = 0 for low coverage (farther points show through \
         holes). The paper's setting, 600 px and r = 1, sits at the knee. ![plot](accuracy-vs-time.svg)\n",
    );
    std::fs::write(root().join("docs/accuracy-vs-time.md"), md).unwrap();
    std::fs::write(root().join("docs/accuracy-vs-time.svg"), svg(&rows)).unwrap();
    eprintln!("wrote docs/accuracy-vs-time.md and .svg");
}

/// Two panels (coverage and within-1% versus ms/view), one line per render size.
fn svg(rows: &[Row]) -> String {
    let (w, h, m) = (900.0, 380.0, 50.0);
    let pw = (w - 3.0 * m) / 2.0;
    let ph = h - 2.0 * m;
    let max_ms = rows.iter().map(|r| r.ms).fold(0.0, f64::max) * 1.05;
    let colors = ["#1f77b4", "#d62728", "#2ca02c"];
    let mut s = format!("<svg xmlns='http://www.w3.org/2000/svg' width='{w}' height='{h}' font-family='sans-serif' font-size='12'>\n<rect width='100%' height='100%' fill='white'/>\n");
    for (panel, (title, get)) in [
        (
            "surface coverage",
            (|r: &Row| r.coverage) as fn(&Row) -> f64,
        ),
        ("depth within 1%", |r: &Row| r.within),
    ]
    .iter()
    .enumerate()
    {
        let x0 = m + panel as f64 * (pw + m);
        let _ = writeln!(
            s,
            "<rect x='{x0}' y='{m}' width='{pw}' height='{ph}' fill='none' stroke='#999'/>"
        );
        let _ = writeln!(s, "<text x='{}' y='{}' text-anchor='middle' font-weight='bold'>{title} vs ms per view</text>", x0 + pw / 2.0, m - 12.0);
        let _ = writeln!(
            s,
            "<text x='{}' y='{}' text-anchor='middle'>ms / view</text>",
            x0 + pw / 2.0,
            h - 12.0
        );
        for k in 0..=4 {
            let v = k as f64 / 4.0;
            let y = m + ph - v * ph;
            let _ = writeln!(s, "<text x='{}' y='{}' text-anchor='end'>{:.0}%</text><line x1='{x0}' x2='{}' y1='{y}' y2='{y}' stroke='#eee'/>", x0 - 4.0, y + 4.0, v * 100.0, x0 + pw);
            let t = max_ms * v;
            let _ = writeln!(
                s,
                "<text x='{}' y='{}' text-anchor='middle'>{t:.1}</text>",
                x0 + v * pw,
                m + ph + 16.0
            );
        }
        for (ci, dim) in [300u32, 600, 900].iter().enumerate() {
            let pts: Vec<(f64, f64, f32)> = rows
                .iter()
                .filter(|r| r.min_dim == *dim)
                .map(|r| (x0 + r.ms / max_ms * pw, m + ph - get(r) * ph, r.radius))
                .collect();
            let path: Vec<String> = pts
                .iter()
                .map(|(x, y, _)| format!("{x:.1},{y:.1}"))
                .collect();
            let _ = writeln!(
                s,
                "<polyline points='{}' fill='none' stroke='{}' stroke-width='2'/>",
                path.join(" "),
                colors[ci]
            );
            for (x, y, r) in &pts {
                let _ = writeln!(s, "<circle cx='{x:.1}' cy='{y:.1}' r='3' fill='{}'/><text x='{:.1}' y='{:.1}' font-size='10'>r={r}</text>", colors[ci], x + 4.0, y - 4.0);
            }
            let _ = writeln!(
                s,
                "<text x='{}' y='{}' fill='{}'>{dim} px</text>",
                x0 + 8.0,
                m + 16.0 + 14.0 * ci as f64,
                colors[ci]
            );
        }
    }
    s.push_str("</svg>\n");
    s
}

/// Open3D timing the views once per line read from stdin, answering with a JSON list of
/// seconds per view: the benchmark alternates rounds of ours and Open3D's, so both tools
/// see the same phases of a noisy machine.
const OPEN3D_ROUNDS: &str = r#"
import json, sys, time, numpy as np
import open3d as o3d, open3d.core as o3c
pts = np.load(sys.argv[1]); views = json.load(open(sys.argv[2]))
pcd = o3d.t.geometry.PointCloud(o3c.Tensor(pts))
cams = [(v["w"], v["h"], o3c.Tensor(np.array(v["K"], dtype=np.float64)), o3c.Tensor(np.array(v["E"], dtype=np.float64))) for v in views]
print("ready", flush=True)
for _ in sys.stdin:
    ts = []
    for w, h, K, E in cams:
        t = time.perf_counter()
        d = pcd.project_to_depth_image(w, h, K, E, depth_scale=1.0, depth_max=1e4)
        ts.append(time.perf_counter() - t)
    print(json.dumps(ts), flush=True)
"#;

/// A running Open3D process (`OPEN3D_ROUNDS`) on the points and views in a directory.
struct Open3dRounds {
    child: std::process::Child,
    out: std::io::BufReader<std::process::ChildStdout>,
    /// Views in views.json: a round that answers for another count has failed.
    views: usize,
}

impl Open3dRounds {
    /// `threads` OpenMP threads; `None` (and why, on stderr) when Open3D cannot run.
    fn start(dir: &Path, threads: usize, views: usize) -> Option<Open3dRounds> {
        use std::io::BufRead;
        let mut child = Command::new("python3")
            .env("OMP_NUM_THREADS", threads.to_string())
            .args(["-c", OPEN3D_ROUNDS])
            .arg(dir.join("pts.npy"))
            .arg(dir.join("views.json"))
            .stdin(std::process::Stdio::piped())
            .stdout(std::process::Stdio::piped())
            .spawn()
            .map_err(|e| eprintln!("python3: {e}"))
            .ok()?;
        let mut out = std::io::BufReader::new(child.stdout.take()?);
        let mut line = String::new();
        if out.read_line(&mut line).ok()? == 0 || line.trim() != "ready" {
            eprintln!("open3d failed to start (see its error above)");
            return None;
        }
        Some(Open3dRounds { child, out, views })
    }

    /// One round folded into `best` (seconds per view), or `None` when the process failed.
    fn round_into(&mut self, best: &mut [f64]) -> Option<()> {
        use std::io::{BufRead, Write};
        writeln!(self.child.stdin.as_mut()?, "go").ok()?;
        let mut line = String::new();
        self.out.read_line(&mut line).ok()?;
        let ts: Vec<f64> = serde_json::from_str(&line).ok()?;
        (ts.len() == self.views && best.len() == self.views).then_some(())?;
        for (b, t) in best.iter_mut().zip(ts) {
            *b = b.min(t);
        }
        Some(())
    }

    /// Seconds per view: each view's best of `rounds`, median over views.
    fn best_of(&mut self, rounds: usize) -> Option<f64> {
        let mut best = vec![f64::INFINITY; self.views];
        for _ in 0..rounds {
            self.round_into(&mut best)?;
        }
        Some(median(best))
    }
}

impl Drop for Open3dRounds {
    fn drop(&mut self) {
        drop(self.child.stdin.take());
        let _ = self.child.wait();
    }
}

/// The registered image a synthetic shot stands for.
fn shot_image(s: &nrw_synth::cameras::Shot) -> nrw_colmap::Image {
    nrw_colmap::Image {
        id: s.image_id,
        name: s.name.clone(),
        camera_id: s.camera_id,
        cam_from_world: s.pose,
        stored_quat_norm: 1.0,
        points2d: vec![],
    }
}

fn has_avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    return is_x86_feature_detected!("avx2");
    #[cfg(not(target_arch = "x86_64"))]
    false
}

fn speed(quick: bool, ours_only: bool) {
    let spec = SceneSpec::demo();
    let landmark = Landmark::new(&spec.geometry);
    let sizes: &[usize] = if quick {
        &[100_000, 1_000_000]
    } else {
        &[100_000, 1_000_000, 10_000_000]
    };
    let tmp = tempfile::tempdir().unwrap();
    let mut md = String::from("# Render speed against Open3D\n\n");
    let _ = writeln!(
        md,
        "Regenerate: `cargo bench -p nrw-render --bench render -- speed` (needs `pip install open3d`). \
         The demo landmark's surface sampled at N points; 8 PINHOLE views of 800×600; 3–5 rounds that \
         alternate between the tools (ours renders every view, then Open3D, kept running in one process, \
         does), so that both see the same phases of a shared machine; for each view its best round \
         (interference only ever slows a run down), then the median over views; one thread for both \
         (`OMP_NUM_THREADS=1`). Open3D: `t.geometry.PointCloud.project_to_depth_image` \
         (depth only, one pixel per point). Ours: `nrw_render::render` producing colour and depth, radius 0 \
         (the same footprint) and 1 (the paper's). Cloud preparation (re-centring, Morton sort, chunks) is \
         timed separately: it is paid once per scene, not per view. Two camera sets: *whole* (12–40 m away, \
         the landmark fills the view) and *close-up* (5–8 m away, a view sees part of the scene, where \
         chunk culling pays).\n"
    );
    md.push_str("| views | points | cloud prep | chunks visited | points skipped as hidden (r=0 / r=1) | ours r=0 ms/view | ours r=1 ms/view | ours r=1, portable kernel | Open3D ms/view | Open3D / ours (r=0) | Open3D / ours (r=1) | ours points/s (r=1) | ours views/s (r=1) |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    let mut md3 = String::from("| views | points | r=0 ms/view | r=0 portable | speed-up | r=1 ms/view | r=1 portable | speed-up |\n|---|---|---|---|---|---|---|---|\n");
    let mut md2 = String::from("| views | points | cores | ours views/s (r=1, views in parallel) | Open3D views/s (OpenMP) | ours / Open3D |\n|---|---|---|---|---|---|\n");
    let clouds: Vec<(usize, Vec<DVec3>)> = sizes
        .iter()
        .map(|&n| {
            (
                n,
                landmark
                    .sample_surface(n, &mut rand_chacha::ChaCha8Rng::seed_from_u64(n as u64))
                    .iter()
                    .map(|p| p.p)
                    .collect(),
            )
        })
        .collect();
    let (mut met, mut measured) = ([0usize; 2], 0usize);
    for (label, d0, d1) in [("whole", 12.0, 40.0), ("close-up", 5.0, 8.0)] {
        let mut cam_spec = spec.cameras.clone();
        cam_spec.model = "PINHOLE".into();
        cam_spec.count = 8;
        cam_spec.min_size = 600;
        cam_spec.max_size = 600;
        cam_spec.small_fraction = 0.0;
        cam_spec.away_fraction = 0.0;
        cam_spec.min_distance = d0;
        cam_spec.max_distance = d1;
        let shots = nrw_synth::cameras::shots(
            &cam_spec,
            &landmark,
            "png",
            &mut rand_chacha::ChaCha8Rng::seed_from_u64(5),
        );
        let views_json: Vec<serde_json::Value> = shots
            .iter()
            .map(|s| {
                let p = &s.camera.params;
                let r = s.pose.matrix();
                let t = s.pose.translation;
                serde_json::json!({
                    "w": s.camera.width, "h": s.camera.height,
                    "K": [[p[0], 0.0, p[2]], [0.0, p[1], p[3]], [0.0, 0.0, 1.0]],
                    "E": [[r.x_axis.x, r.y_axis.x, r.z_axis.x, t.x], [r.x_axis.y, r.y_axis.y, r.z_axis.y, t.y], [r.x_axis.z, r.y_axis.z, r.z_axis.z, t.z], [0.0, 0.0, 0.0, 1.0]],
                })
            })
            .collect();
        std::fs::write(
            tmp.path().join("views.json"),
            serde_json::to_string(&views_json).unwrap(),
        )
        .unwrap();
        for (n, world) in &clouds {
            let n = *n;
            let colors: Vec<[u8; 3]> = vec![[128, 128, 128]; world.len()];
            let t = Instant::now();
            let rc = RenderCloud::new(DVec3::ZERO, world, Some(&colors), None);
            let prep = t.elapsed().as_secs_f64();
            let flat: Vec<f32> = world
                .iter()
                .flat_map(|p| [p.x as f32, p.y as f32, p.z as f32])
                .collect();
            write_npy(&tmp.path().join("pts.npy"), &flat, 3);
            let runs = if n >= 10_000_000 { 3 } else { 5 };
            // Views at r = 0 and r = 1.
            let views: Vec<[View; 2]> = shots
                .iter()
                .map(|s| {
                    let img = shot_image(s);
                    let (w, h) = (s.camera.width as u32, s.camera.height as u32);
                    [0.0, 1.0].map(|r| View::new(&img, &s.camera, DVec3::ZERO, w, h, r))
                })
                .collect();
            let views1: Vec<&View> = views.iter().map(|[_, v]| v).collect();
            // Rounds alternate between the tools; each view's best round counts.
            let mut o3d_rounds = (!ours_only)
                .then(|| Open3dRounds::start(tmp.path(), 1, views.len()))
                .flatten();
            let mut ours = [
                vec![f64::INFINITY; views.len()],
                vec![f64::INFINITY; views.len()],
            ];
            let mut o3d_best = vec![f64::INFINITY; views.len()];
            let (mut visited, mut tested, mut hidden) = (0usize, [0usize; 2], [0usize; 2]);
            for _ in 0..runs {
                for (vi, pair) in views.iter().enumerate() {
                    for (k, v) in pair.iter().enumerate() {
                        let t = Instant::now();
                        let b = std::hint::black_box(render(v, &rc));
                        ours[k][vi] = ours[k][vi].min(t.elapsed().as_secs_f64());
                        visited += b.chunks_visited;
                        tested[k] += b.points_tested;
                        hidden[k] += b.points_hidden;
                    }
                }
                if let Some(o) = o3d_rounds.as_mut() {
                    if o.round_into(&mut o3d_best).is_none() {
                        eprintln!("open3d stopped answering");
                        o3d_rounds = None;
                    }
                }
            }
            let o3d = o3d_rounds.is_some().then(|| median(o3d_best));
            drop(o3d_rounds);
            let visited_frac = visited as f64 / (rc.chunks.len() * shots.len() * 2 * runs) as f64;
            let [o0, o1] = ours.map(median);
            // What the AVX2 kernel buys: the portable one on the same views (r = 1).
            let mut portable = Vec::new();
            for v in &views1 {
                let mut best = f64::INFINITY;
                for _ in 0..runs {
                    let t = Instant::now();
                    std::hint::black_box(render_with(v, &rc, Kernel::Portable));
                    best = best.min(t.elapsed().as_secs_f64());
                }
                portable.push(best);
            }
            let head = format!(
                "| {label} | {n} | {:.0} ms | {:.0}% | {:.0}% / {:.0}% | {:.2} | {:.2} | {:.2} |",
                prep * 1e3,
                visited_frac * 100.0,
                hidden[0] as f64 * 100.0 / tested[0].max(1) as f64,
                hidden[1] as f64 * 100.0 / tested[1].max(1) as f64,
                o0 * 1e3,
                o1 * 1e3,
                median(portable) * 1e3
            );
            if label == "whole" && n >= 1_000_000 {
                // The same views through SIMPLE_RADIAL (k = -0.05), the model COLMAP gives
                // internet photos: no Open3D equivalent, so ours against the portable kernel.
                let mut t = [[0.0f64; 2]; 2];
                for (ri, r) in [0.0f32, 1.0].into_iter().enumerate() {
                    let mut per = [Vec::new(), Vec::new()];
                    for s in &shots {
                        let p = &s.camera.params;
                        let cam = nrw_colmap::Camera {
                            model: nrw_colmap::CameraModel::SimpleRadial,
                            params: vec![p[0], p[2], p[3], -0.05],
                            ..s.camera.clone()
                        };
                        let img = shot_image(s);
                        let (w, h) = (cam.width as u32, cam.height as u32);
                        let v = View::new(&img, &cam, DVec3::ZERO, w, h, r);
                        for (ki, kernel) in [Kernel::Auto, Kernel::Portable].into_iter().enumerate()
                        {
                            let mut best = f64::INFINITY;
                            for _ in 0..runs {
                                let t0 = Instant::now();
                                std::hint::black_box(render_with(&v, &rc, kernel));
                                best = best.min(t0.elapsed().as_secs_f64());
                            }
                            per[ki].push(best);
                        }
                    }
                    t[ri] = [median(per[0].clone()), median(per[1].clone())];
                }
                let _ = writeln!(
                    md3,
                    "| {label} | {n} | {:.2} | {:.2} | **{:.1}×** | {:.2} | {:.2} | **{:.1}×** |",
                    t[0][0] * 1e3,
                    t[0][1] * 1e3,
                    t[0][1] / t[0][0],
                    t[1][0] * 1e3,
                    t[1][1] * 1e3,
                    t[1][1] / t[1][0],
                );
            }
            if n == *sizes.last().unwrap() {
                // Both cores: ours renders views in parallel (as `nrw-etl ingest` does),
                // Open3D parallelises within a view (OpenMP, all cores).
                let cores = rayon::current_num_threads();
                let t = Instant::now();
                for _ in 0..runs {
                    views1.par_iter().for_each(|v| {
                        std::hint::black_box(render(v, &rc));
                    });
                }
                let ours_vps = (runs * views1.len()) as f64 / t.elapsed().as_secs_f64();
                let o3d_all = (!ours_only)
                    .then(|| Open3dRounds::start(tmp.path(), cores, views1.len())?.best_of(runs))
                    .flatten();
                let _ = writeln!(
                    md2,
                    "| {label} | {n} | {cores} | {ours_vps:.1} | {} | {} |",
                    o3d_all.map_or("not measured".into(), |t| format!("{:.1}", 1.0 / t)),
                    o3d_all.map_or("—".into(), |t| format!("**{:.1}×**", ours_vps * t)),
                );
            }
            if let Some(t3) = o3d {
                met[0] += (t3 / o0 >= 10.0) as usize;
                met[1] += (t3 / o1 >= 10.0) as usize;
                measured += 1;
            }
            let row = match o3d {
                Some(t3) => format!(
                    "{head} {:.2} | **{:.1}×** | **{:.1}×** | {:.2e} | {:.0} |\n",
                    t3 * 1e3,
                    t3 / o0,
                    t3 / o1,
                    n as f64 / o1,
                    1.0 / o1
                ),
                None => format!(
                    "{head} not measured | — | — | {:.2e} | {:.0} |\n",
                    n as f64 / o1,
                    1.0 / o1
                ),
            };
            eprint!("{row}");
            md.push_str(&row);
        }
    }
    let _ = writeln!(
        md,
        "\nReading it: at the same footprint (r = 0) we are several times faster than Open3D's depth-only \
         projection while also producing colour; the paper's r = 1 costs up to about 2× r = 0 (up to 9 pixel \
         updates per point). Close-up views visit a fraction of the chunks, so their cost grows \
         sub-linearly with the cloud while Open3D's grows linearly. On whole views of a dense cloud \
         the chunks behind the landmark's near side are skipped unprojected (occlusion culling, \
         *hidden* column; renders unchanged, see docs/rendering.md). Small clouds are bound by a fixed \
         ~0.5 ms per 800×600 view (allocating and resolving the buffers). `render` uses the AVX2 kernel \
         where the CPU has it (this one: {}); the portable column is the baseline x86-64 code on the \
         same views, bit-identical output. Issue 4's target (≥ 10× Open3D for colour + depth) held in \
         this run for {} of {measured} rows at r = 0 and {} of {measured} at r = 1.\n\n\
         ## Both cores\n\n\
         Throughput of the machine, each tool parallel its own way: ours renders the views in parallel \
         (rayon, as `nrw-etl ingest` does), Open3D parallelises within a view (OpenMP on all cores).\n\n{md2}\n\
         ## Lenses with distortion\n\n\
         The same whole views through SIMPLE_RADIAL (k = -0.05), the model COLMAP gives internet photos \
         (and the real scenes in ../shared/data have). Open3D has no distorted projection, so this is ours \
         (`render`, AVX2 where available) against the portable kernel, one thread, same output bit for bit. \
         Projection here is COLMAP's f64 formula in a scalar loop (PINHOLE's is f32, 8 points per instruction), which is why it costs more.\n\n{md3}",
        if has_avx2() { "yes" } else { "no" },
        met[0],
        met[1]
    );
    if ours_only {
        eprintln!("--ours-only: docs/bench/render_speed.md left as it was");
        return;
    }
    std::fs::create_dir_all(root().join("docs/bench")).unwrap();
    std::fs::write(root().join("docs/bench/render_speed.md"), md).unwrap();
    eprintln!("wrote docs/bench/render_speed.md");
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let quick = args.iter().any(|a| a == "--quick");
    let want = |k: &str| {
        !args.iter().any(|a| a == "accuracy" || a == "speed") || args.iter().any(|a| a == k)
    };
    if want("accuracy") {
        accuracy(quick);
    }
    if want("speed") {
        speed(quick, args.iter().any(|a| a == "--ours-only"));
    }
}
