//! `cargo bench -p nrw-render --bench clean [-- POINTS]`
//!
//! What point-cloud clean-up buys and costs, on the synthetic landmark with 2% floating points
//! (`outliers = 0.02`; 10⁶ surface points by default): for statistical outlier removal at
//! k ∈ {8, 16, 32} × σ ∈ {1, 2, 3}, the floating points removed (recall), good points lost
//! (1 − precision), the rendered depth against ground truth (landmark pixels more than 1% off,
//! coverage) and the time per 10⁶ points; for normal estimation at k ∈ {8, 16, 32}, the angle
//! to the analytic normals and the time; and against Open3D (`remove_statistical_outlier`,
//! `estimate_normals` with the same k, same threads, same run) on the POINTS cloud and one ten
//! times larger, when `NRW_OPEN3D_PYTHON` (default `python3`) imports open3d — a benchmark
//! peer, never a dependency. Both sides run as child processes that read the same PLY, so each
//! reports its own time and memory peak. `--no-large` skips the larger cloud. Writes
//! docs/bench/cloud_clean.md.

#[path = "../../../tests/support/cpu.rs"]
mod cpu;
#[path = "../tests/support/truth.rs"]
mod truth;

use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

use glam::DVec3;
use nrw_render::clean::{estimate_normals, statistical_outliers};
use truth::depth_errors;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if let Some(at) = args.iter().position(|a| a == "--ours") {
        return ours(Path::new(&args[at + 1]));
    }
    let points: usize = args
        .iter()
        .find_map(|a| a.parse().ok())
        .unwrap_or(1_000_000);
    let tmp = tempfile::tempdir().unwrap();
    landmark(points, tmp.path());
    let dir = tmp.path();
    let cloud = nrw_colmap::read_ply(&dir.join("dense/fused.ply")).unwrap();
    let truth: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join(nrw_synth::truth::OUTLIERS)).unwrap())
            .unwrap();
    let surface = truth["surface_points"].as_u64().unwrap() as usize;
    let rec = nrw_colmap::read_scene(dir).unwrap();
    let origin = rec.scene_origin();
    let n = cloud.len();
    let mega = n as f64 / 1e6;
    let threads = rayon::current_num_threads();
    let (base_off, base_cov) = depth_errors(dir, &cloud.positions[..surface], None);
    let (raw_off, raw_cov) = depth_errors(dir, &cloud.positions, None);
    let pct = |a: usize, b: usize| 100.0 * a as f64 / b.max(1) as f64;
    let mut md = format!(
        "# Point-cloud clean-up: what it removes, what it costs\n\n\
         Regenerate: `cargo bench -p nrw-render --bench clean [-- POINTS]`. CPU: {}; {threads} threads.\n\n\
         Scene: the synthetic landmark, {surface} surface points plus {} floating points \
         (`outliers = 0.02`: uniform in the bounding box grown by 10%), 4 photos rendered at photo \
         size with r = 1. Depth is judged on landmark pixels (building, windows, columns) against \
         ground truth: the share more than 1% off, and coverage. Without the floating points: \
         {:.2}% off, {base_cov} covered; with them, not cleaned: {:.2}% off, {raw_cov} covered.\n\n\
         | k | σ | floating points removed (recall) | good points lost (1 − precision) | removed | depth: pixels > 1% off | covered | time per 10⁶ points |\n\
         |---|---|---|---|---|---|---|---|\n",
        cpu::describe(),
        n - surface,
        pct(base_off, base_cov),
        pct(raw_off, raw_cov),
    );
    for k in [8usize, 16, 32] {
        for sigma in [1.0, 2.0, 3.0] {
            let t = Instant::now();
            let (keep, r) = statistical_outliers(&cloud.positions, origin, k, sigma);
            let secs = t.elapsed().as_secs_f64();
            let caught = keep[surface..].iter().filter(|k| !**k).count();
            let lost = keep[..surface].iter().filter(|k| !**k).count();
            let kept: Vec<DVec3> = cloud
                .positions
                .iter()
                .zip(&keep)
                .filter(|(_, k)| **k)
                .map(|(p, _)| *p)
                .collect();
            let (off, cov) = depth_errors(dir, &kept, None);
            let _ = writeln!(
                md,
                "| {k} | {sigma} | {:.3} | {:.4} | {} | {:.2}% | {cov} | {:.2} s |",
                caught as f64 / (n - surface) as f64,
                lost as f64 / (caught + lost).max(1) as f64,
                r.removed,
                pct(off, cov),
                secs / mega
            );
            eprintln!("denoise k {k} σ {sigma}: {secs:.2} s");
        }
    }
    md += "\n## Normals (PCA of k neighbours, oriented toward the scene's mean camera)\n\n\
           On the surface points only (their analytic normals are known).\n\n\
           | k | median angle | mean angle | past 90° | time per 10⁶ points |\n|---|---|---|---|---|\n";
    let pts = &cloud.positions[..surface];
    let analytic: Vec<DVec3> = cloud.normals.as_ref().unwrap()[..surface]
        .iter()
        .map(|a| DVec3::from(a.map(f64::from)))
        .collect();
    let centres: Vec<DVec3> = rec
        .images
        .values()
        .map(|i| i.cam_from_world.centre())
        .collect();
    let cams = centres.iter().sum::<DVec3>() / centres.len() as f64;
    for k in [8usize, 16, 32] {
        let t = Instant::now();
        let est = estimate_normals(pts, origin, k, &|_| cams);
        let secs = t.elapsed().as_secs_f64();
        let mut angles: Vec<f64> = est
            .iter()
            .zip(&analytic)
            .map(|(e, a)| {
                DVec3::from(e.map(f64::from))
                    .dot(*a)
                    .clamp(-1.0, 1.0)
                    .acos()
                    .to_degrees()
            })
            .collect();
        let mean = angles.iter().sum::<f64>() / angles.len() as f64;
        let past = angles.iter().filter(|a| **a > 90.0).count();
        angles.sort_by(f64::total_cmp);
        let _ = writeln!(
            md,
            "| {k} | {:.3}° | {mean:.2}° | {:.2}% | {:.2} s |",
            angles[angles.len() / 2],
            pct(past, angles.len()),
            secs / (surface as f64 / 1e6)
        );
        eprintln!("normals k {k}: {secs:.2} s");
    }
    drop(cloud);
    let large = (!args.iter().any(|a| a == "--no-large")).then(|| {
        let d = tempfile::tempdir().unwrap();
        landmark(points * 10, d.path());
        d
    });
    let plys: Vec<std::path::PathBuf> = std::iter::once(dir)
        .chain(large.as_ref().map(|d| d.path()))
        .map(|d| d.join("dense/fused.ply"))
        .collect();
    md += &open3d_section(&plys, threads);
    md += "\nPast 90°: surfaces no camera sees (the back wall, the roof and ledge tops above \
           every camera) are turned toward the cameras, and points at edges whose \
           neighbourhood spans two faces.\n";
    let out = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/bench/cloud_clean.md");
    std::fs::write(&out, md).unwrap();
    eprintln!("wrote {}", out.display());
}

/// The synthetic landmark with `points` surface points and 2% floating points, in `dir`.
fn landmark(points: usize, dir: &Path) {
    let mut spec = nrw_synth::SceneSpec::demo().shrunk(4, (240, 320), points);
    spec.observations.features = 300;
    spec.effects.transients = None;
    spec.effects.outliers = Some(0.02);
    nrw_synth::generate(&spec, dir, &|| {}).unwrap();
}

/// Resident-set peak of this process so far, in MB (Linux's VmHWM).
fn peak_mb() -> f64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<f64>().ok())
        .map_or(f64::NAN, |kb| kb / 1024.0)
}

/// Child-process side of the comparison: read the PLY, time k = 16 / σ = 2 removal and
/// k = 16 normals on it, print the figures as JSON.
fn ours(ply: &Path) {
    let cloud = nrw_colmap::read_ply(ply).unwrap();
    let origin = cloud.positions.iter().sum::<DVec3>() / cloud.len().max(1) as f64;
    let t = Instant::now();
    let (_, r) = statistical_outliers(&cloud.positions, origin, 16, 2.0);
    let denoise = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let normals = estimate_normals(&cloud.positions, origin, 16, &|_| DVec3::Z);
    let secs = t.elapsed().as_secs_f64();
    assert_eq!(normals.len(), cloud.len());
    println!(
        "{}",
        serde_json::json!({"denoise": denoise, "normals": secs, "removed": r.removed,
                           "peak_mb": peak_mb(), "points": cloud.len()})
    );
}

/// Open3D on the same PLY, same k and threads: times, removed count, peak memory.
const OPEN3D: &str = r#"
import sys, time, resource, json, open3d as o3d
pc = o3d.io.read_point_cloud(sys.argv[1])
pc.normals = o3d.utility.Vector3dVector()
t = time.perf_counter(); _, ind = pc.remove_statistical_outlier(16, 2.0); d = time.perf_counter() - t
t = time.perf_counter(); pc.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(16)); nt = time.perf_counter() - t
print(json.dumps({"denoise": d, "normals": nt, "removed": len(pc.points) - len(ind),
                  "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, "version": o3d.__version__}))
"#;

/// Run one side of the comparison as a child process; its JSON, or why there is none.
fn child(mut cmd: std::process::Command, threads: usize) -> Result<serde_json::Value, String> {
    let o = cmd
        .env("OMP_NUM_THREADS", threads.to_string())
        .env("RAYON_NUM_THREADS", threads.to_string())
        .output()
        .map_err(|e| e.to_string())?;
    if !o.status.success() {
        return Err(String::from_utf8_lossy(&o.stderr).into_owned());
    }
    serde_json::from_slice(&o.stdout).map_err(|e| e.to_string())
}

/// The comparison on each PLY: both sides as child processes, their times, removed counts
/// and memory peaks, and the Open3D version they reported.
fn open3d_section(plys: &[std::path::PathBuf], threads: usize) -> String {
    let python = std::env::var("NRW_OPEN3D_PYTHON").unwrap_or_else(|_| "python3".into());
    let mut md = format!(
        "\n## Against Open3D (k = 16, σ = 2, {threads} threads, same PLY, same run)\n\n\
         Each side runs in its own process that reads the PLY and then times the two \
         operations; the peak is that process's resident-set high-water mark (PLY, cloud, tree \
         and results). Ratio = Open3D's time / ours (> 1: ours is faster).\n\n\
         | points | operation | ours | Open3D | ratio | removed (ours / Open3D) | peak memory (ours / Open3D) |\n\
         |---|---|---|---|---|---|---|\n"
    );
    let mut version = None;
    for ply in plys {
        let mut me = std::process::Command::new(std::env::current_exe().unwrap());
        me.arg("--ours").arg(ply);
        let mut peer = std::process::Command::new(&python);
        peer.args(["-c", OPEN3D]).arg(ply);
        match (child(me, threads), child(peer, threads)) {
            (Ok(us), Ok(them)) => {
                eprintln!("open3d: {them}; ours: {us}");
                md += &peer_rows(&us, &them);
                version = them["version"].as_str().map(str::to_string);
            }
            (a, b) => {
                eprintln!("comparison not measured: ours {a:?}, open3d {b:?}");
                let why = if a.is_err() {
                    "ours failed"
                } else {
                    "Open3D is not installed for `NRW_OPEN3D_PYTHON`"
                };
                md += &format!("| {} | not measured: {why} | | | | | |\n", ply.display());
            }
        }
    }
    md += &format!(
        "\nOpen3D {}: `remove_statistical_outlier(16, 2.0)` and `estimate_normals(KDTreeSearchParamKNN(16))`, \
         each building its own KD-tree, as ours does. Ours orients toward a fixed point; Open3D \
         orients nothing when no normals exist.\n",
        version.as_deref().unwrap_or("(not measured)")
    );
    md
}

/// The two table rows of one measured PLY, from both sides' JSON.
fn peer_rows(us: &serde_json::Value, them: &serde_json::Value) -> String {
    let f = |v: &serde_json::Value, k: &str| v[k].as_f64().unwrap_or(f64::NAN);
    let points = us["points"].as_u64().unwrap_or(0);
    format!(
        "| {points} | statistical outlier removal | {:.2} s | {:.2} s | **{:.2}×** | {} / {} | {:.0} MB / {:.0} MB |\n\
         | {points} | normal estimation | {:.2} s | {:.2} s | **{:.2}×** | | |\n",
        f(us, "denoise"),
        f(them, "denoise"),
        f(them, "denoise") / f(us, "denoise"),
        us["removed"],
        them["removed"],
        f(us, "peak_mb"),
        f(them, "peak_mb"),
        f(us, "normals"),
        f(them, "normals"),
        f(them, "normals") / f(us, "normals"),
    )
}
