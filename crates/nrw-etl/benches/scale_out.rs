//! `cargo bench -p nrw-etl --bench scale_out [-- PHOTOS POINTS]`
//!
//! The cost of splitting ingest into work units: one process against 4 units run one after
//! another on the same machine (each unit loads the whole cloud) plus `finalize`, with wall
//! time and peak memory (`/usr/bin/time`) of each process, on a synthetic scene of 200
//! photos and 10⁷ points by default. Checks that both datasets are byte-identical, and
//! writes the projection for larger scenes on M machines to docs/bench/scale_out.md.

#[path = "../../../tests/support/cpu.rs"]
mod cpu;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

#[path = "../../../tests/support/timed.rs"]
mod timed;

/// Wall seconds and peak resident MB of one `nrw-etl` process.
fn timed(args: &[&str]) -> (f64, f64) {
    timed::timed(env!("CARGO_BIN_EXE_nrw-etl"), args)
}

/// Every file of a dataset but timings.json, with its bytes.
fn files(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else if p.file_name().is_some_and(|n| n != "timings.json") {
                out.push((
                    p.strip_prefix(dir).unwrap().into(),
                    std::fs::read(&p).unwrap(),
                ));
            }
        }
    }
    out.sort();
    out
}

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let (photos, points) = timed::photos_points();
    let work = root.join("target/bench-scale-out");
    let _ = std::fs::remove_dir_all(&work);
    let scene = work.join("scene");
    let spec = nrw_synth::SceneSpec::demo().shrunk(photos, (600, 900), points);
    nrw_synth::generate(&spec, &scene, &|| {}).expect("synthetic scene");
    let scene_s = scene.to_str().unwrap();
    let rows = 64usize;
    let groups = photos.div_ceil(rows);
    let n = 4;
    // Best of two rounds per process, each into an empty folder (a rerun would resume).
    let best = |a: (f64, f64), b: (f64, f64)| if b.0 < a.0 { b } else { a };
    let (mut one_run, mut units_run, mut fin_run, mut idle_run) = (None, vec![None; n], None, None);
    let (one, units) = (work.join("one"), work.join("units"));
    let mut identical = true;
    for _ in 0..2 {
        for d in [&one, &units, &work.join("idle")] {
            let _ = std::fs::remove_dir_all(d);
        }
        let r = timed(&["ingest", scene_s, "--out", one.to_str().unwrap(), "--quiet"]);
        one_run = Some(one_run.map_or(r, |p| best(p, r)));
        for (i, slot) in units_run.iter_mut().enumerate() {
            let shard = format!("{i}/{n}");
            let r = timed(&[
                "ingest",
                scene_s,
                "--out",
                units.to_str().unwrap(),
                "--quiet",
                "--unit",
                &shard,
            ]);
            *slot = Some(slot.map_or(r, |p| best(p, r)));
        }
        let r = timed(&["finalize", units.to_str().unwrap()]);
        fin_run = Some(fin_run.map_or(r, |p| best(p, r)));
        identical &= files(&one) == files(&units);
        // A unit that owns no group pays only the fixed cost: model, cloud, input hashes.
        let idle = format!("{groups}/{}", groups + 1);
        let r = timed(&[
            "ingest",
            scene_s,
            "--out",
            work.join("idle").to_str().unwrap(),
            "--quiet",
            "--unit",
            &idle,
        ]);
        idle_run = Some(idle_run.map_or(r, |p| best(p, r)));
    }
    assert!(identical, "4 units + finalize must equal one process");
    let ((t_one, m_one), (t_fin, m_fin), (fixed, m_idle)) =
        (one_run.unwrap(), fin_run.unwrap(), idle_run.unwrap());
    let per_unit: Vec<(f64, f64)> = units_run.into_iter().map(Option::unwrap).collect();
    let t_units: f64 = per_unit.iter().map(|u| u.0).sum();
    let per_photo = ((t_one - fixed) / photos as f64).max(0.0);
    let mut md = String::new();
    let _ = writeln!(
        md,
        "# Scale-out: the cost of splitting ingest into work units\n"
    );
    let _ = writeln!(md, "Regenerate: `cargo bench -p nrw-etl --bench scale_out [-- PHOTOS POINTS]`.\n\nMachine: {}.\n", cpu::describe());
    let _ = writeln!(md, "Scene: synthetic (demo façade), {photos} photos of 600–900 px, {points} points; paper settings (600 px renders, r = 1, {rows} rows per shard, so {groups} shards). Each process timed whole by `/usr/bin/time` (wall seconds, peak resident memory), best of 2 rounds, each into an empty folder.\n");
    let _ = writeln!(md, "| run | groups | wall s | peak MB |\n|---|---|---|---|");
    let _ = writeln!(
        md,
        "| one process (`ingest`) | {groups} | {t_one:.1} | {m_one:.0} |"
    );
    for (i, (t, m)) in per_unit.iter().enumerate() {
        let g = (0..groups).filter(|g| g % n == i).count();
        let _ = writeln!(
            md,
            "| unit {i}/{n} (`ingest --unit {i}/{n}`) | {g} | {t:.1} | {m:.0} |"
        );
    }
    let _ = writeln!(
        md,
        "| a unit that owns no group (the fixed cost) | 0 | {fixed:.1} | {m_idle:.0} |"
    );
    let _ = writeln!(md, "| `finalize` | — | {t_fin:.2} | {m_fin:.0} |");
    let _ = writeln!(
        md,
        "| 4 units + finalize, one after another | {groups} | {:.1} | — |\n",
        t_units + t_fin
    );
    let _ = writeln!(md, "Byte-identical to the single process: {identical}.\n");
    let _ = writeln!(md, "Splitting cost: {:.2}× the single process's time when the 4 units run one after another on one machine. \
Each unit pays the fixed cost (reading the model and the cloud, hashing the inputs) of {fixed:.1} s; the rest of the single process, {per_photo:.3} s per photo, is rendering and encoding. \
Units are as uneven as their groups: a group is {rows} photos, and the last is the remainder.\n", (t_units + t_fin) / t_one);
    let _ = writeln!(
        md,
        "## Projection: 10⁴ photos, 10⁸ points, M machines like this one\n"
    );
    let scale = 1e8 / points as f64;
    let big_groups = 10_000usize.div_ceil(rows);
    let _ = writeln!(md, "Assumptions (stated, not measured): the fixed cost and the memory grow with the cloud (×{scale:.0} points), and so does the per-photo cost (every view splats every point in front of it); one unit per machine, all cores each; finalize as measured (it reads the model and the group records, not the cloud). 10⁴ photos make {big_groups} groups of {rows}: more machines than groups leave some idle, and the slowest unit sets the wall time.\n");
    let _ = writeln!(md, "| M | groups of the slowest unit | wall (h) | peak memory per unit (GB) |\n|---|---|---|---|");
    let mem = per_unit.iter().map(|u| u.1).fold(m_one, f64::max) * scale / 1024.0;
    for m in [1usize, 4, 16, 64, 157, 256] {
        let g = big_groups.div_ceil(m);
        let per = scale * fixed + scale * per_photo * (g * rows) as f64;
        let _ = writeln!(md, "| {m} | {g} | {:.2} | {mem:.1} |", per / 3600.0);
    }
    let _ = writeln!(md, "\nPast {big_groups} machines nothing is gained at 64 photos per shard (`--rows-per-shard` smaller makes more, smaller groups); the fixed cost then dominates, and a unit's memory is the cloud's whatever M is.");
    std::fs::create_dir_all(root.join("docs/bench")).unwrap();
    std::fs::write(root.join("docs/bench/scale_out.md"), &md).unwrap();
    print!("{md}");
}
