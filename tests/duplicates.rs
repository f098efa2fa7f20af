//! Near-duplicates: on a synthetic collection with copies planted on purpose (the same
//! upload twice, resized, re-encoded, cropped, recoloured), ingest finds every planted
//! group and no other; split keeps each group on one side for every seed; a published split
//! that puts one on both sides is warned about; blur is measured and filtered.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use nrw_synth::copies::{CopyKind, KINDS};

use super::{nrw, ok};

/// A PINHOLE scene of 20 photos with a copy of every fourth (5 copies, one of each kind),
/// and, from every fifth photo's very place, another picture taken at another moment
/// (other light, other people: 4 twins that are not copies).
fn planted(
    dir: &Path,
) -> (
    PathBuf,
    Vec<nrw_synth::copies::Planted>,
    Vec<(String, String)>,
) {
    let scene = dir.join("scene");
    let mut spec = nrw_synth::SceneSpec::demo().shrunk(20, (300, 360), 60_000);
    spec.cameras.model = "PINHOLE".into();
    spec.cameras.distortion = 0.0;
    nrw_synth::generate(&spec, &scene, &|| {}).unwrap();
    let twin = dir.join("twin");
    nrw_synth::generate(&nrw_synth::copies::other_moments(&spec), &twin, &|| {}).unwrap();
    let depth = spec.cameras.min_distance;
    let planted = nrw_synth::copies::plant_copies(&scene, 4, depth, 7).unwrap();
    let moments = nrw_synth::copies::plant_other_moments(&scene, &twin, 5, depth, 8).unwrap();
    assert_eq!((planted.len(), moments.len()), (5, 4));
    (scene, planted, moments)
}

fn ingest(scene: &Path, out: &Path, extra: &[&str]) -> String {
    let mut extra = extra.to_vec();
    extra.extend(["--max-empty", "1"]);
    let o = nrw(&super::strs(&super::ingest_small_args(scene, out, &extra)));
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// The groups found, as sets of names.
fn found(ds: &Path) -> BTreeSet<BTreeSet<String>> {
    let store = nrw_dataset::Store::local(ds);
    let members = nrw_dataset::duplicates::read_duplicates(&store).unwrap();
    let mut groups: BTreeMap<u32, BTreeSet<String>> = BTreeMap::new();
    for m in members {
        groups.entry(m.group).or_default().insert(m.name);
    }
    groups.into_values().collect()
}

/// Each photo's side in the split.
fn sides(ds: &Path) -> BTreeMap<String, String> {
    let store = nrw_dataset::Store::local(ds);
    nrw_dataset::split::read_splits(&store)
        .unwrap()
        .into_iter()
        .map(|a| (a.name, a.split))
        .collect()
}

#[test]
fn planted_copies_are_found_and_never_straddle_the_split() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, planted, moments) = planted(dir.path());
    let ds = dir.path().join("ds");
    let err = ingest(&scene, &ds, &[]);
    let want: BTreeSet<BTreeSet<String>> = planted
        .iter()
        .map(|p| [p.original.clone(), p.copy.clone()].into())
        .collect();
    // Every planted group, and no group among the 20 distinct photos and their 4 twins from
    // the same places.
    assert_eq!(found(&ds), want, "{err}");
    let grouped: BTreeSet<String> = found(&ds).into_iter().flatten().collect();
    assert!(moments.iter().all(|(_, twin)| !grouped.contains(twin)));
    assert!(
        err.contains("10 photos are copies of one another in 5 groups"),
        "{err}"
    );
    let d = ds.to_str().unwrap();
    let inspected: serde_json::Value =
        serde_json::from_str(&ok(&["inspect", d, "--json"])).unwrap();
    let listed: BTreeSet<BTreeSet<String>> =
        serde_json::from_value(inspected["near_duplicates"].clone()).unwrap();
    assert_eq!(listed, want);
    for seed in 0..40 {
        let o = ok(&["split", d, "--val", "6", "--seed", &seed.to_string()]);
        let side = sides(&ds);
        for g in &want {
            let s: BTreeSet<&String> = g.iter().map(|n| &side[n]).collect();
            assert_eq!(s.len(), 1, "seed {seed}: {g:?} straddles the split");
        }
        assert_eq!(side.values().filter(|s| *s == "val").count(), 6, "{o}");
        std::fs::remove_file(ds.join("splits.parquet")).unwrap();
    }
    // A published split that puts one group on both sides is warned about, naming it.
    let p = &planted[3];
    let mut tsv = String::from("filename\tid\tsplit\tdataset\n");
    for (k, name) in image_names(&scene).iter().enumerate() {
        let split = if *name == p.copy { "test" } else { "train" };
        tsv.push_str(&format!("{name}\t{k}\t{split}\tx\n"));
    }
    let file = dir.path().join("split.tsv");
    std::fs::write(&file, tsv).unwrap();
    let o = nrw(&["split", d, "--from-tsv", file.to_str().unwrap()]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{e}");
    assert!(
        e.contains("near-duplicates on both sides of the split")
            && e.contains(&p.copy)
            && e.contains(&p.original),
        "{e}"
    );
    // QA shows every group with its photos, and warns about the one on both sides.
    ok(&["qa", d]);
    let qa: serde_json::Value =
        serde_json::from_slice(&std::fs::read(ds.join("qa/qa.json")).unwrap()).unwrap();
    let groups: BTreeSet<BTreeSet<String>> =
        serde_json::from_value(qa["near_duplicates"].clone()).unwrap();
    assert_eq!(groups, want);
    let warned = warning(&qa, "near_duplicates_split");
    assert_eq!(warned, BTreeSet::from([p.copy.clone(), p.original.clone()]));
    let html = std::fs::read_to_string(ds.join("qa/report.html")).unwrap();
    let section = &html[html.find("<h2>Near-duplicates</h2>").unwrap()..];
    let section = &section[..section[4..].find("<h2>").map_or(section.len(), |e| e + 4)];
    for g in &want {
        for name in g {
            assert!(
                section.contains(&format!("alt=\"{name}\"")),
                "{name} has no thumbnail"
            );
        }
    }
}

/// The photos a QA warning of this kind lists.
fn warning(qa: &serde_json::Value, kind: &str) -> BTreeSet<String> {
    qa["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|w| w["kind"] == kind)
        .flat_map(|w| w["photos"].as_array().unwrap().iter())
        .map(|p| p.as_str().unwrap().to_string())
        .collect()
}

/// Every image name of the scene's model.
fn image_names(scene: &Path) -> Vec<String> {
    nrw_colmap::read_scene(scene)
        .unwrap()
        .images
        .values()
        .map(|i| i.name.clone())
        .collect()
}

#[test]
fn sharpness_and_exposure_are_recorded_and_the_blur_filter_drops_with_its_reason() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("scene");
    let mut spec = nrw_synth::SceneSpec::demo().shrunk(6, (160, 200), 30_000);
    spec.cameras.model = "PINHOLE".into();
    spec.cameras.distortion = 0.0;
    nrw_synth::generate(&spec, &scene, &|| {}).unwrap();
    // Blur one photo hard and black out another.
    let names = image_names(&scene);
    let photo = |n: &str| scene.join("images").join(n);
    let blurred = image::open(photo(&names[0])).unwrap().blur(6.0);
    blurred.save(photo(&names[0])).unwrap();
    let img = image::open(photo(&names[1])).unwrap();
    image::RgbImage::new(img.width(), img.height())
        .save(photo(&names[1]))
        .unwrap();
    let ds = dir.path().join("ds");
    ingest(&scene, &ds, &[]);
    let rows = images_table(&ds);
    let sharp = |n: &str| rows[n].0.unwrap();
    let others: Vec<f64> = names[2..].iter().map(|n| sharp(n)).collect();
    assert!(
        others.iter().all(|s| *s > 4.0 * sharp(&names[0])),
        "{others:?} vs {}",
        sharp(&names[0])
    );
    // The black photo: no sharpness, every pixel crushed, and in no group (its hash is empty).
    assert_eq!(rows[&names[1]].0, Some(0.0));
    assert_eq!(rows[&names[1]].1, Some(1.0));
    assert!(found(&ds).is_empty());
    ok(&["qa", ds.to_str().unwrap()]);
    let qa: serde_json::Value =
        serde_json::from_slice(&std::fs::read(ds.join("qa/qa.json")).unwrap()).unwrap();
    assert_eq!(
        warning(&qa, "low_sharpness"),
        BTreeSet::from([names[0].clone(), names[1].clone()])
    );
    // The filter drops the blurred photo (and the black one), with the value as the verdict's.
    let min = (sharp(&names[0]) * 2.0).to_string();
    let ds2 = dir.path().join("ds2");
    let err = ingest(&scene, &ds2, &["--min-sharpness", &min]);
    assert!(err.contains("2 too blurry"), "{err}");
    let rows = images_table(&ds2);
    assert_eq!(rows[&names[0]].2, "too_blurry");
    assert_eq!(rows[&names[1]].2, "too_blurry");
    assert!(names[2..].iter().all(|n| rows[n].2 == "kept"));
}

/// name → (sharpness, dark fraction, verdict) from scene/images.parquet.
fn images_table(ds: &Path) -> BTreeMap<String, (Option<f64>, Option<f64>, String)> {
    let store = nrw_dataset::Store::local(ds);
    let signals = nrw_dataset::scene::read_signals(&store).unwrap();
    nrw_dataset::scene::read_verdicts(&store)
        .unwrap()
        .into_iter()
        .map(|(id, name, verdict)| {
            let s = signals.get(&id);
            (
                name,
                (s.map(|s| s.sharpness), s.map(|s| s.dark_fraction), verdict),
            )
        })
        .collect()
}

/// A real scene (../shared/data/NAME) copied into `dir` with one copy of every second photo
/// planted (each of `kinds` in turn, each with the original's lens scaled, shifted or turned
/// as its pixels were), and what was planted.
fn real_with_copies(
    name: &str,
    dir: &Path,
    kinds: &[CopyKind],
) -> Option<(PathBuf, Vec<nrw_synth::copies::Planted>)> {
    let src = super::shared::shared(&format!("data/{name}"))?;
    let scene = dir.join(name);
    let sparse = scene.join("sparse/0");
    std::fs::create_dir_all(&sparse).unwrap();
    let rec = nrw_colmap::read_model(&src.join("sparse/0"), None).unwrap();
    nrw_colmap::write_model(&rec, &sparse, nrw_colmap::Format::Binary).unwrap();
    super::copy_photos(&src.join("images"), &scene.join("images"));
    // The dense cloud where the scene has one (sceaux_castle); sacre_coeur renders its SfM
    // points.
    if src.join("dense/fused.ply").is_file() {
        std::fs::create_dir_all(scene.join("dense")).unwrap();
        std::fs::copy(src.join("dense/fused.ply"), scene.join("dense/fused.ply")).unwrap();
    }
    let planted =
        nrw_synth::copies::plant_copies_of(&scene, 2, viewing_distance(&rec), 7, kinds).unwrap();
    Some((scene, planted))
}

/// The median distance from a photo's centre to the points it observes: the scale of the
/// registration noise a planted copy gets.
fn viewing_distance(rec: &nrw_colmap::Reconstruction) -> f64 {
    let mut d: Vec<f64> = rec
        .points
        .values()
        .flat_map(|p| {
            p.track
                .iter()
                .map(move |e| (rec.images[&e.image_id].cam_from_world.centre() - p.xyz).length())
        })
        .collect();
    d.sort_by(f64::total_cmp);
    d[d.len() / 2]
}

#[test]
fn copies_of_real_photos_are_found_on_both_real_scenes_and_nothing_else_is() {
    let dir = tempfile::tempdir().unwrap();
    let mut table = String::new();
    // Every kind on sceaux_castle's 6 copies; sacre_coeur's 5 take every kind but the same
    // upload, a quarter-turned copy first.
    let mut every = KINDS.to_vec();
    every.push(CopyKind::Rotated);
    let turned_first = [CopyKind::Rotated, KINDS[1], KINDS[2], KINDS[3], KINDS[4]];
    for (name, kinds) in [
        ("sceaux_castle", &every[..]),
        ("sacre_coeur", &turned_first[..]),
    ] {
        let Some((scene, planted)) = real_with_copies(name, dir.path(), kinds) else {
            return;
        };
        let ds = dir.path().join(format!("{name}-ds"));
        let err = ingest(&scene, &ds, &[]);
        let want: BTreeSet<BTreeSet<String>> = planted
            .iter()
            .map(|p| [p.original.clone(), p.copy.clone()].into())
            .collect();
        let got = found(&ds);
        let hits = want.intersection(&got).count();
        table += &format!(
            "{name}: {hits} of {} planted groups found, {} groups found in all ({:?})\n",
            want.len(),
            got.len(),
            planted.iter().map(|p| p.kind).collect::<Vec<_>>()
        );
        assert_eq!(got, want, "{name}\n{table}{err}");
    }
    eprintln!("{table}");
}
