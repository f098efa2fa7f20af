//! The trainer crate on a dataset: the loader's crops, and pretraining that learns and resumes.

use super::*;

/// A synthetic dataset ready for training: ingested, split, described (colour statistics) and
/// with triplets of `k` neighbours.
fn trainable_dataset(tmp: &Path, photos: usize, k: usize) -> PathBuf {
    let ds = small_dataset(tmp, photos, true);
    let d = ds.to_str().unwrap();
    ok(&["split", d, "--val", "2", "--seed", "3"]);
    ok(&["style", d, "--tier", "color-stats", "--quiet"]);
    ok(&["triplets", d, "--k", &k.to_string()]);
    ds
}

#[test]
fn trainer_loader_crops_align_cover_every_row_once_repeat_under_a_seed_and_stay_bounded() {
    use nrw_trainer::{Loader, LoaderConfig};
    let tmp = tempfile::tempdir().unwrap();
    let ds_dir = small_dataset(tmp.path(), 9, true);
    ok(&["split", ds_dir.to_str().unwrap(), "--val", "2"]);
    let ds = nrw_dataset::reader::Dataset::open(&ds_dir).unwrap();
    let cfg = LoaderConfig {
        crop: 48,
        batch: 3,
        seed: 7,
        semantics: true,
    };
    let loader = Loader::new(&ds, "train", cfg.clone()).unwrap();
    let batches: Vec<_> = loader.epoch(0).map(|b| b.unwrap()).collect();
    // The epoch covers each row of the split exactly once.
    let mut seen: Vec<u32> = batches.iter().flat_map(|b| b.ids.clone()).collect();
    seen.sort_unstable();
    assert_eq!(seen, ds.ids("train").unwrap());
    // Every channel of a crop is the same window of its view (photo, render, depth, semantics).
    let scale = nrw_dataset::scene::read_depth_max(&nrw_dataset::Store::from(&ds_dir))
        .unwrap()
        .unwrap() as f32;
    let s = 48usize;
    for b in &batches {
        for (k, (&id, &(x, y))) in b.ids.iter().zip(&b.offsets).enumerate() {
            let v = ds.get(id).unwrap();
            let (photo, color, depth) =
                (v.photo().unwrap(), v.color().unwrap(), v.depth().unwrap());
            let sem = v.semantics().unwrap().unwrap();
            for j in 0..s {
                for i in 0..s {
                    let (px, py) = (x + i as u32, y + j as u32);
                    let at = |c: usize| b.photo[((k * 3 + c) * s + j) * s + i];
                    let p = photo.get_pixel(px, py);
                    assert_eq!(at(0), p[0] as f32 / 127.5 - 1.0);
                    assert_eq!(at(2), p[2] as f32 / 127.5 - 1.0);
                    let c = color.get_pixel(px, py);
                    let r = b.color[((k * 3 + 1) * s + j) * s + i];
                    let z = b.depth[(k * s + j) * s + i];
                    let dz = depth.data[py as usize * depth.width + px as usize];
                    assert_eq!(z, if dz > 0.0 { (dz / scale).min(1.0) } else { 0.0 });
                    // Known alignment of synthetic renders: drawn colour ⇔ depth, same pixel.
                    assert_eq!(c[3] > 0, z > 0.0, "view {id} at ({px}, {py})");
                    assert_eq!(
                        r,
                        if c[3] > 0 {
                            c[1] as f32 / 127.5 - 1.0
                        } else {
                            -1.0
                        }
                    );
                    let m = b.semantics.as_ref().unwrap()[((k * 3) * s + j) * s + i];
                    assert_eq!(m, sem.get_pixel(px, py)[0] as f32 / 127.5 - 1.0);
                }
            }
        }
    }
    // Deterministic under a seed; another seed draws other crops.
    let again: Vec<_> = Loader::new(&ds, "train", cfg.clone())
        .unwrap()
        .epoch(0)
        .map(|b| b.unwrap())
        .collect();
    for (a, b) in batches.iter().zip(&again) {
        assert_eq!(
            (&a.ids, &a.offsets, &a.photo),
            (&b.ids, &b.offsets, &b.photo)
        );
    }
    let other: Vec<_> = Loader::new(&ds, "train", LoaderConfig { seed: 8, ..cfg })
        .unwrap()
        .epoch(0)
        .map(|b| b.unwrap())
        .collect();
    assert!(batches
        .iter()
        .zip(&other)
        .any(|(a, b)| a.ids != b.ids || a.offsets != b.offsets));
    // Bounded memory: never more decoded views alive than one batch.
    assert!(loader.peak_in_flight() <= 3, "{}", loader.peak_in_flight());
    // A crop larger than the views is a clear error naming the view.
    let big = Loader::new(
        &ds,
        "train",
        LoaderConfig {
            crop: 4000,
            batch: 2,
            seed: 0,
            semantics: false,
        },
    )
    .unwrap();
    let err = big.epoch(0).next().unwrap().unwrap_err().to_string();
    assert!(err.contains("does not fit"), "{err}");
}

#[test]
fn trainer_lowers_the_loss_beats_chance_on_held_out_triplets_and_resumes_exactly() {
    use nrw_trainer::{train, TrainConfig};
    let tmp = tempfile::tempdir().unwrap();
    let ds_dir = trainable_dataset(tmp.path(), 26, 8);
    let ds = nrw_dataset::reader::Dataset::open(&ds_dir).unwrap();
    let cfg = TrainConfig {
        steps: 60,
        batch: 8,
        crop: 32,
        lr: 3e-3,
        pos_k: 3,
        neg_k: 5,
        checkpoint_every: 20,
        // At the default 0.1 most of these triplets start inside the margin (per-step loss
        // mostly 0, a few spikes), so "the loss falls" would be decided by where the spikes
        // land; at 1.0 the first steps' loss is substantial and its fall is the property.
        margin: 1.0,
        ..TrainConfig::default()
    };
    let whole = tmp.path().join("whole");
    let r = train(&ds, "train", &cfg, &whole, &mut |_, _| {}).unwrap();
    let mean = |v: &[(u64, f64)]| v.iter().map(|p| p.1).sum::<f64>() / v.len() as f64;
    let (first, last) = (mean(&r.losses[..15]), mean(&r.losses[45..]));
    eprintln!(
        "accuracy {} → {}, class {:?}",
        r.accuracy_before, r.accuracy_after, r.class_agreement
    );
    assert!(last < first * 0.8, "loss {first} → {last}");
    assert!(r.held_out_triplets > 0);
    assert!(
        r.accuracy_after > 0.5 && r.accuracy_after >= r.accuracy_before,
        "held-out accuracy {} → {}",
        r.accuracy_before,
        r.accuracy_after
    );
    // Interrupted after 20 steps, then resumed: the same losses as the uninterrupted run.
    let part = tmp.path().join("part");
    train(
        &ds,
        "train",
        &TrainConfig {
            steps: 20,
            ..cfg.clone()
        },
        &part,
        &mut |_, _| {},
    )
    .unwrap();
    let resumed = train(&ds, "train", &cfg, &part, &mut |_, _| {}).unwrap();
    assert_eq!(resumed.resumed_from, Some(20));
    for (a, b) in r.losses.iter().zip(&resumed.losses) {
        assert_eq!(a.0, b.0);
        assert!(
            (a.1 - b.1).abs() <= 1e-5 * a.1.abs().max(1e-6),
            "step {}: {} vs {}",
            a.0,
            a.1,
            b.1
        );
    }
    // A setting out of range is named as its config field (nrw-train maps it to --pos-k).
    for (pos_k, neg_k, setting) in [(0, 1, "pos_k"), (1, 1_000, "neg_k")] {
        let e = train(
            &ds,
            "train",
            &TrainConfig {
                pos_k,
                neg_k,
                ..cfg.clone()
            },
            &tmp.path().join("bad-k"),
            &mut |_, _| {},
        )
        .unwrap_err();
        assert!(
            matches!(&e, nrw_trainer::TrainError::Setting { setting: s, .. } if *s == setting),
            "{e}"
        );
        assert!(e.to_string().contains("per anchor"), "{e}");
    }
    // Other settings in the same folder are refused, not mixed.
    let err = train(
        &ds,
        "train",
        &TrainConfig { lr: 1e-2, ..cfg },
        &part,
        &mut |_, _| {},
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("other settings"), "{err}");
}
