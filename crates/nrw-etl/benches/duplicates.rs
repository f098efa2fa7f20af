//! `cargo bench -p nrw-etl --bench duplicates`
//!
//! How well near-duplicate search finds copies, and what it costs (docs/bench/duplicates.md).
//! A synthetic collection (60 photos) with 20 copies planted on purpose, 3 or 4 of each kind
//! (the same file, resized to 60%, re-encoded at JPEG quality 30, cropped to 70%,
//! recoloured, turned a quarter clockwise), and 15 twins taken from the very place of a
//! photo at another moment (other light, other people): distinct pictures that share a pose.
//! Every pair is scored once; the curves are the accept rules swept over those scores. The
//! real scenes of ../shared/data have no known copy: every pair there counts as distinct.
//! Then the cost: each photo's signals against colmap2nerf's sharpness + imagehash's phash
//! in Python on the same files, and the search at four working sizes.

#[path = "../../../tests/support/cpu.rs"]
mod cpu;

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use nrw_colmap::Reconstruction;
use nrw_dataset::PhotoSignals;
use nrw_pipeline::ingest::duplicates::{score_pairs, DuplicateOptions, PairScore, Photo};
use nrw_pipeline::ingest::signals::signals;

/// A collection: its model, photo folder, each photo's signals and typical depth.
struct Collection {
    name: String,
    rec: Reconstruction,
    images: PathBuf,
    signals: BTreeMap<u32, PhotoSignals>,
    depth: BTreeMap<u32, f64>,
    /// Seconds our signals took over all photos.
    seconds: f64,
}

/// Median camera-frame depth of the model's points in front of each camera.
fn depths(rec: &Reconstruction) -> BTreeMap<u32, f64> {
    rec.images
        .values()
        .map(|i| {
            let mut z: Vec<f64> = rec
                .points
                .values()
                .map(|p| i.cam_from_world.transform(p.xyz).z)
                .filter(|z| *z > 0.0)
                .collect();
            z.sort_by(f64::total_cmp);
            (i.id, z.get(z.len() / 2).copied().unwrap_or(0.0))
        })
        .collect()
}

fn collection(name: &str, scene: &Path) -> Collection {
    let rec = nrw_colmap::read_scene(scene).unwrap();
    let images = scene.join("images");
    let t = Instant::now();
    let signals = rec
        .images
        .values()
        .map(|i| {
            let photo = nrw_dataset::codec::load_photo(&images.join(&i.name)).unwrap();
            (i.id, signals(&photo))
        })
        .collect();
    let seconds = t.elapsed().as_secs_f64();
    Collection {
        name: name.into(),
        depth: depths(&rec),
        rec,
        images,
        signals,
        seconds,
    }
}

/// Every pair scored: the hash route for all, the pixels for pairs at one place.
fn scores(c: &Collection, o: &DuplicateOptions) -> (Vec<PairScore>, f64) {
    let photos: Vec<Photo> = c
        .rec
        .images
        .values()
        .map(|i| Photo {
            image_id: i.id,
            name: &i.name,
            signals: c.signals[&i.id],
            camera: &c.rec.cameras[&i.camera_id],
            pose: &i.cam_from_world,
            depth: c.depth[&i.id],
        })
        .collect();
    let wide = DuplicateOptions {
        phash_bits: 32,
        ..*o
    };
    let t = Instant::now();
    let s = score_pairs(&photos, &c.images, &wide).unwrap();
    (s, t.elapsed().as_secs_f64())
}

/// The planted truth: copy pairs by kind, and twin pairs, as unordered id pairs.
struct Truth {
    copies: BTreeMap<(u32, u32), String>,
    twins: BTreeSet<(u32, u32)>,
}

fn key(a: u32, b: u32) -> (u32, u32) {
    (a.min(b), a.max(b))
}

fn truth(
    rec: &Reconstruction,
    planted: &[nrw_synth::copies::Planted],
    moments: &[(String, String)],
) -> Truth {
    let id: BTreeMap<&str, u32> = rec
        .images
        .values()
        .map(|i| (i.name.as_str(), i.id))
        .collect();
    let kind = |k: nrw_synth::copies::CopyKind| {
        serde_json::to_value(k).unwrap().as_object().map_or_else(
            || {
                serde_json::to_value(k)
                    .unwrap()
                    .as_str()
                    .unwrap()
                    .to_string()
            },
            |o| o.keys().next().unwrap().clone(),
        )
    };
    Truth {
        copies: planted
            .iter()
            .map(|p| {
                (
                    key(id[p.original.as_str()], id[p.copy.as_str()]),
                    kind(p.kind),
                )
            })
            .collect(),
        twins: moments
            .iter()
            .map(|(a, b)| key(id[a.as_str()], id[b.as_str()]))
            .collect(),
    }
}

/// (recall by kind, recall, false pairs among distinct, false twin pairs) under `accept`.
fn rates(
    s: &[PairScore],
    t: &Truth,
    accept: &dyn Fn(&PairScore) -> bool,
) -> (BTreeMap<String, (usize, usize)>, usize, usize, usize) {
    let mut by_kind: BTreeMap<String, (usize, usize)> = BTreeMap::new();
    for k in t.copies.values() {
        by_kind.entry(k.clone()).or_default().1 += 1;
    }
    let (mut found, mut false_pairs, mut false_twins) = (0, 0, 0);
    for p in s.iter().filter(|p| accept(p)) {
        match t.copies.get(&key(p.a, p.b)) {
            Some(k) => {
                by_kind.get_mut(k).unwrap().0 += 1;
                found += 1;
            }
            None => {
                false_pairs += 1;
                false_twins += usize::from(t.twins.contains(&key(p.a, p.b)));
            }
        }
    }
    (by_kind, found, false_pairs, false_twins)
}

/// Distinct pairs accepted in a real scene (none is a known copy).
fn real_false(s: &[PairScore], accept: &dyn Fn(&PairScore) -> bool) -> usize {
    s.iter().filter(|p| accept(p)).count()
}

fn pairs(n: usize) -> usize {
    n * (n - 1) / 2
}

/// colmap2nerf's sharpness and imagehash's phash on the same files in one Python process:
/// (seconds, peak RSS MB), or None without the oracles.
fn python_peer(files: &[PathBuf]) -> Option<(f64, f64)> {
    let code = r#"
import sys, time, resource, cv2, imagehash, PIL.Image
files = sys.stdin.read().split("\n")
t = time.perf_counter()
for p in files:
    if p:
        g = cv2.cvtColor(cv2.imread(p), cv2.COLOR_BGR2GRAY)
        cv2.Laplacian(g, cv2.CV_64F).var()
        imagehash.phash(PIL.Image.open(p))
print(time.perf_counter() - t, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
"#;
    let mut child = std::process::Command::new("python3")
        .args(["-c", code])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .ok()?;
    use std::io::Write;
    let list: Vec<String> = files.iter().map(|f| f.display().to_string()).collect();
    child
        .stdin
        .take()?
        .write_all(list.join("\n").as_bytes())
        .ok()?;
    let o = child.wait_with_output().ok()?;
    let text = String::from_utf8(o.stdout).ok()?;
    let v: Vec<f64> = text
        .split_whitespace()
        .filter_map(|x| x.parse().ok())
        .collect();
    (o.status.success() && v.len() == 2).then(|| (v[0], v[1]))
}

fn peak_rss_mb() -> f64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    status
        .lines()
        .find(|l| l.starts_with("VmHWM"))
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|kb| kb.parse::<f64>().ok())
        .map_or(0.0, |kb| kb / 1024.0)
}

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("planted");
    let mut spec = nrw_synth::SceneSpec::demo().shrunk(60, (360, 480), 120_000);
    spec.cameras.model = "PINHOLE".into();
    spec.cameras.distortion = 0.0;
    nrw_synth::generate(&spec, &scene, &|| {}).unwrap();
    let twin = tmp.path().join("twin");
    nrw_synth::generate(&nrw_synth::copies::other_moments(&spec), &twin, &|| {}).unwrap();
    let depth = spec.cameras.min_distance;
    let moments = nrw_synth::copies::plant_other_moments(&scene, &twin, 4, depth, 8).unwrap();
    let mut kinds = nrw_synth::copies::KINDS.to_vec();
    kinds.push(nrw_synth::copies::CopyKind::Rotated);
    let planted = nrw_synth::copies::plant_copies_of(&scene, 3, depth, 7, &kinds).unwrap();
    let synthetic = collection("synthetic, planted", &scene);
    let t = truth(&synthetic.rec, &planted, &moments);
    let shared = root.join("../shared/data");
    let real: Vec<Collection> = ["sceaux_castle", "sacre_coeur"]
        .iter()
        .filter(|s| shared.join(s).exists())
        .map(|s| collection(s, &shared.join(s)))
        .collect();
    let o = DuplicateOptions::default();
    let (syn_scores, _) = scores(&synthetic, &o);
    let real_scores: Vec<Vec<PairScore>> = real.iter().map(|c| scores(c, &o).0).collect();

    let n = synthetic.rec.images.len();
    let mut md = String::new();
    let _ = writeln!(md, "# Near-duplicates: precision, recall and cost\n");
    let _ = writeln!(
        md,
        "Made by `cargo bench -p nrw-etl --bench duplicates` on {}.\n",
        cpu::describe()
    );
    let _ = writeln!(
        md,
        "**Synthetic collection**: {} photos of the demo landmark (PINHOLE, shorter side 360–480 px), {} of them generated, {} planted copies (each kind in turn: identical file, resized 60%, re-encoded JPEG q30, cropped 70%, recoloured, turned a quarter clockwise) and {} twins from a photo's very place at another moment (light rotated, twice the people). Denominators: recall counts the {} planted (original, copy) pairs; false pairs count among the {} pairs that are not a planted copy ({} of them twins). **Real scenes** ({}): no known copy, every pair distinct ({}). Nothing here was tuned on the real scenes.\n",
        n,
        n - planted.len() - moments.len(),
        planted.len(),
        moments.len(),
        t.copies.len(),
        pairs(n) - t.copies.len(),
        t.twins.len(),
        real.iter().map(|c| format!("{}: {} photos", c.name, c.rec.images.len())).collect::<Vec<_>>().join(", "),
        real.iter().map(|c| format!("{} pairs", pairs(c.rec.images.len()))).collect::<Vec<_>>().join(", "),
    );
    let kinds: Vec<String> = {
        let mut k: Vec<String> = t
            .copies
            .values()
            .cloned()
            .collect::<BTreeSet<_>>()
            .into_iter()
            .collect();
        k.sort();
        k
    };
    let header = |md: &mut String, first: &str| {
        let _ = writeln!(
            md,
            "| {first} | {} | recall | false pairs (synthetic) | of them twins | {} |",
            kinds.join(" | "),
            real.iter()
                .map(|c| format!("false pairs ({})", c.name))
                .collect::<Vec<_>>()
                .join(" | ")
        );
        let cols = 4 + kinds.len() + real.len();
        let _ = writeln!(md, "|{}", "---|".repeat(cols));
    };
    let row = |md: &mut String, label: String, accept: &dyn Fn(&PairScore) -> bool| {
        let (by_kind, found, fp, ft) = rates(&syn_scores, &t, accept);
        let _ = writeln!(
            md,
            "| {label} | {} | {found}/{} | {fp} | {ft} | {} |",
            kinds
                .iter()
                .map(|k| format!("{}/{}", by_kind[k].0, by_kind[k].1))
                .collect::<Vec<_>>()
                .join(" | "),
            t.copies.len(),
            real_scores
                .iter()
                .map(|s| real_false(s, accept).to_string())
                .collect::<Vec<_>>()
                .join(" | ")
        );
    };
    let _ = writeln!(md, "## The perceptual hash alone\n\nA pair is one picture when its hashes are at most *b* bits apart (of 64).\n");
    header(&mut md, "b");
    for b in [0, 2, 4, 6, 8, 10, 12, 14, 16, 20] {
        row(
            &mut md,
            format!("{b}{}", if b == o.phash_bits { " (default)" } else { "" }),
            &|p: &PairScore| p.phash_distance <= b,
        );
    }
    let _ = writeln!(md, "\n## The cameras and pixels alone\n\nPairs whose cameras are at one place (centres within {:.0}% of the depth, axes within {}°) are aligned through their cameras; one picture when the grey levels correlate at least τ over at least {:.0}% of the smaller photo.\n", o.centre_fraction * 100.0, o.max_degrees, o.min_overlap * 100.0);
    header(&mut md, "τ");
    for tau in [0.5, 0.6, 0.7, 0.8, 0.85, 0.87, 0.9, 0.95, 0.98] {
        let opts = DuplicateOptions {
            phash_bits: 0,
            min_ncc: tau,
            ..o
        };
        let label = format!("{tau}{}", if tau == o.min_ncc { " (default)" } else { "" });
        row(&mut md, label, &|p: &PairScore| {
            p.ncc
                .is_some_and(|(c, ov)| c >= opts.min_ncc && ov >= opts.min_overlap)
        });
    }
    let _ = writeln!(md, "\n## Both, at the defaults (what ingest runs)\n\nWhere the cameras are at one place the pixels decide; elsewhere the hash.\n");
    header(&mut md, "rule");
    row(
        &mut md,
        format!(
            "pixels τ ≥ {} at one place, else hash ≤ {} bits",
            o.min_ncc, o.phash_bits
        ),
        &|p: &PairScore| p.is_duplicate(&o),
    );
    let either = |p: &PairScore| {
        p.phash_distance <= o.phash_bits
            || p.ncc
                .is_some_and(|(c, ov)| c >= o.min_ncc && ov >= o.min_overlap)
    };
    row(&mut md, "either (hash or pixels)".into(), &either);
    let twin_ncc: Vec<f64> = syn_scores
        .iter()
        .filter(|p| t.twins.contains(&key(p.a, p.b)))
        .filter_map(|p| p.ncc.map(|c| c.0))
        .collect();
    let copy_ncc: Vec<f64> = syn_scores
        .iter()
        .filter(|p| t.copies.contains_key(&key(p.a, p.b)))
        .filter_map(|p| p.ncc.map(|c| c.0))
        .collect();
    let _ = writeln!(
        md,
        "\nCorrelation of the aligned photos: planted copies {} (min {:.3}), twins from the same place {} (max {:.3}).\n",
        copy_ncc.len(),
        copy_ncc.iter().copied().fold(f64::INFINITY, f64::min),
        twin_ncc.len(),
        twin_ncc.iter().copied().fold(f64::NEG_INFINITY, f64::max),
    );

    let _ = writeln!(md, "## What accuracy costs in time\n\nThe pixel comparison at four working sizes (longest side each photo is averaged down to), over the synthetic collection's {} pairs; the margin is the lowest copy correlation minus the highest twin correlation (larger separates better).\n", pairs(n));
    let _ = writeln!(md, "| working side (px) | search s | lowest copy ncc | highest twin ncc | margin |\n|---|---|---|---|---|");
    for side in [40, 80, 160, 320] {
        let opts = DuplicateOptions {
            working_side: side,
            ..o
        };
        let (s, secs) = scores(&synthetic, &opts);
        let ncc = |set: &dyn Fn(&PairScore) -> bool, pick: fn(f64, f64) -> f64, init: f64| {
            s.iter()
                .filter(|p| set(p))
                .filter_map(|p| p.ncc.map(|c| c.0))
                .fold(init, pick)
        };
        let lo = ncc(
            &|p: &PairScore| t.copies.contains_key(&key(p.a, p.b)),
            f64::min,
            f64::INFINITY,
        );
        let hi = ncc(
            &|p: &PairScore| t.twins.contains(&key(p.a, p.b)),
            f64::max,
            f64::NEG_INFINITY,
        );
        let _ = writeln!(
            md,
            "| {side}{} | {secs:.3} | {lo:.3} | {hi:.3} | {:.3} |",
            if side == o.working_side {
                " (default)"
            } else {
                ""
            },
            lo - hi
        );
    }
    let files: Vec<PathBuf> = std::iter::once(&synthetic)
        .chain(real.iter())
        .flat_map(|c| {
            c.rec
                .images
                .values()
                .map(|i| c.images.join(&i.name))
                .collect::<Vec<_>>()
        })
        .collect();
    let ours: f64 = synthetic.seconds + real.iter().map(|c| c.seconds).sum::<f64>();
    let _ = writeln!(md, "\n## Each photo's signals against Python\n\nSharpness, exposure and hash of all {} photos (decode included) in this process, against colmap2nerf's sharpness (`cv2.imread`, `cvtColor`, `Laplacian(...).var()`) plus `imagehash.phash` on the same files in one Python process.\n", files.len());
    let _ = writeln!(
        md,
        "| | seconds | ms per photo | peak RSS (MB) |\n|---|---|---|---|"
    );
    let _ = writeln!(
        md,
        "| ours (one thread) | {ours:.2} | {:.1} | {:.0} (whole benchmark) |",
        1e3 * ours / files.len() as f64,
        peak_rss_mb()
    );
    match python_peer(&files) {
        Some((secs, rss)) => {
            let _ = writeln!(
                md,
                "| Python (cv2 + imagehash) | {secs:.2} | {:.1} | {rss:.0} |",
                1e3 * secs / files.len() as f64
            );
            let _ = writeln!(md, "\nOurs takes {:.2}× Python's time.", ours / secs);
        }
        None => {
            let _ = writeln!(md, "| Python | not run: cv2 or imagehash missing | | |");
        }
    }
    let path = root.join("docs/bench/duplicates.md");
    std::fs::write(&path, &md).unwrap();
    println!("{md}\nwritten to {}", path.display());
}
