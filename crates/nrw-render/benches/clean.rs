//! `cargo bench -p nrw-render --bench clean [-- POINTS]`
//!
//! What point-cloud clean-up buys and costs, on the synthetic landmark with 2% floating points
//! (`outliers = 0.02`; 10⁶ surface points by default): for statistical outlier removal at
//! k ∈ {8, 16, 32} × σ ∈ {1, 2, 3}, the floating points removed (recall), good points lost
//! (1 − precision), the rendered depth against ground truth (landmark pixels more than 1% off,
//! coverage) and the time per 10⁶ points; for normal estimation at k ∈ {8, 16, 32}, the angle
//! to the analytic normals and the time; and against Open3D (`remove_statistical_outlier`,
//! `estimate_normals` with the same k, same threads, same cloud, same run) when
//! `NRW_OPEN3D_PYTHON` (default `python3`) imports open3d — a benchmark peer, never a
//! dependency. Writes docs/bench/cloud_clean.md.

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
    let points: usize = std::env::args()
        .skip(1)
        .find_map(|a| a.parse().ok())
        .unwrap_or(1_000_000);
    let tmp = tempfile::tempdir().unwrap();
    let mut spec = nrw_synth::SceneSpec::demo().shrunk(4, (240, 320), points);
    spec.observations.features = 300;
    spec.effects.transients = None;
    spec.effects.outliers = Some(0.02);
    nrw_synth::generate(&spec, tmp.path(), &|| {}).unwrap();
    let dir = tmp.path();
    let cloud = nrw_colmap::read_ply(&dir.join("dense/fused.ply")).unwrap();
    let truth: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("ground_truth/outliers.json")).unwrap())
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
    md += &open3d_section(
        &dir.join("dense/fused.ply"),
        &cloud.positions,
        origin,
        threads,
    );
    md += "\nPast 90°: surfaces no camera sees (the back wall, the roof and ledge tops above \
           every camera) are turned toward the cameras, and points at edges whose \
           neighbourhood spans two faces.\n";
    let out = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/bench/cloud_clean.md");
    std::fs::write(&out, md).unwrap();
    eprintln!("wrote {}", out.display());
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

/// The "against Open3D" section: ours and Open3D's time for k = 16 (σ = 2) on the same cloud.
fn open3d_section(ply: &Path, positions: &[DVec3], origin: DVec3, threads: usize) -> String {
    let t = Instant::now();
    let (_, r) = statistical_outliers(positions, origin, 16, 2.0);
    let ours_d = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let _ = estimate_normals(positions, origin, 16, &|_| DVec3::Z);
    let ours_n = t.elapsed().as_secs_f64();
    let python = std::env::var("NRW_OPEN3D_PYTHON").unwrap_or_else(|_| "python3".into());
    let o = std::process::Command::new(&python)
        .args(["-c", OPEN3D])
        .arg(ply)
        .env("OMP_NUM_THREADS", threads.to_string())
        .output();
    let peer: Option<serde_json::Value> = match o {
        Ok(o) if o.status.success() => serde_json::from_slice(&o.stdout).ok(),
        Ok(o) => {
            eprintln!(
                "open3d not measured: {}",
                String::from_utf8_lossy(&o.stderr)
            );
            None
        }
        Err(e) => {
            eprintln!("open3d not measured: {python}: {e}");
            None
        }
    };
    let mut md = format!(
        "\n## Against Open3D (same {} points, k = 16, σ = 2, {threads} threads)\n\n",
        positions.len()
    );
    match peer {
        Some(p) => {
            let f = |k: &str| p[k].as_f64().unwrap_or(f64::NAN);
            let _ = write!(
                md,
                "Open3D {}. Ratio = Open3D's time / ours (> 1: ours is faster).\n\n\
                 | operation | ours | Open3D | ratio |\n|---|---|---|---|\n\
                 | statistical outlier removal | {ours_d:.2} s ({} removed) | {:.2} s ({} removed) | **{:.2}×** |\n\
                 | normal estimation | {ours_n:.2} s | {:.2} s | **{:.2}×** |\n\n\
                 Open3D's process peaked at {:.0} MB (the cloud read from PLY and its tree); ours \
                 was not measured apart from this benchmark's process.\n",
                p["version"].as_str().unwrap_or("?"),
                r.removed,
                f("denoise"),
                p["removed"],
                f("denoise") / ours_d,
                f("normals"),
                f("normals") / ours_n,
                f("peak_mb"),
            );
        }
        None => md +=
            "Open3D not measured (its Python package is not installed for `NRW_OPEN3D_PYTHON`).\n",
    }
    md
}
