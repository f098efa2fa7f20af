use super::*;
use nrw_style::{Arch, Grams, NetInput, StyleError};
use std::path::Path;
use std::sync::Mutex;

/// A backend that is not the CPU VGG: its Grams record each input's size and mean, and
/// it remembers the batch sizes it was called with.
struct Fake {
    fail: bool,
    batches: Mutex<Vec<usize>>,
}

impl Backend for Fake {
    fn arch(&self) -> Arch {
        Arch::Vgg16
    }
    fn weights_sha256(&self) -> &str {
        "fake-weights"
    }
    fn device(&self) -> String {
        "fake-device".into()
    }
    fn batch_size(&self) -> usize {
        3
    }
    fn style_grams(&self, batch: &[NetInput], taps: &[usize]) -> nrw_style::Result<Vec<Grams>> {
        self.batches.lock().unwrap().push(batch.len());
        if self.fail {
            return Err(StyleError::Backend {
                device: self.device(),
                problem: "out of device memory".into(),
            });
        }
        Ok(batch.iter().map(|x| fake_grams(x, taps)).collect())
    }
}

fn fake(fail: bool) -> Fake {
    Fake {
        fail,
        batches: Mutex::new(Vec::new()),
    }
}

fn fake_grams(x: &NetInput, taps: &[usize]) -> Grams {
    let mean = x.chw.iter().map(|v| *v as f64).sum::<f64>() / x.chw.len() as f64;
    taps.iter()
        .map(|&t| (1, vec![t as f64 + mean + (x.height * x.width) as f64]))
        .collect()
}

fn demo_dataset(dir: &Path) -> PathBuf {
    crate::runner::demo(dir, None, None, None, &crate::Silent, &mut |_| {}).unwrap();
    dir.join("dataset")
}

fn cfg(dataset: &Path) -> StyleConfig {
    let mut c = StyleConfig {
        tier: Tier::parse("vgg16-64-l1").unwrap(),
        overwrite: true,
        ..StyleConfig::new(dataset)
    };
    c.settings.photos_per_part = 5;
    c
}

#[test]
fn the_stage_describes_through_any_backend_in_its_batches() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = demo_dataset(tmp.path());
    let fake = fake(false);
    let s = style_unit_on(&cfg(&ds), Unit::WHOLE, Some(&fake), &crate::Silent).unwrap();
    let batches = fake.batches.into_inner().unwrap();
    assert!(batches.iter().all(|b| (1..=3).contains(b)), "{batches:?}");
    assert_eq!(batches.iter().sum::<usize>(), s.photos);
    let store = Store::open(&ds.clone().into()).unwrap();
    let (kind, rows) = nrw_dataset::descriptors::read_all(&store).unwrap().unwrap();
    assert_eq!(kind.weights_sha256, "fake-weights");
    let data = Dataset::open(store.clone()).unwrap();
    let tier = cfg(&ds).tier;
    for r in &rows {
        let v = data
            .iter_ids(&[r.image_id])
            .unwrap()
            .next()
            .unwrap()
            .unwrap();
        let x = nrw_style::network_input(&tier, &v.photo().unwrap(), Preprocess::Imagenet)
            .unwrap()
            .unwrap();
        assert_eq!(
            r.descriptor,
            nrw_style::from_grams(&tier, &fake_grams(&x, &[0]))
        );
    }
    let records = units::unit_records(&store, units::STYLE).unwrap();
    assert!(records
        .iter()
        .all(|r| r.instruction_set.as_deref() == Some("fake-device")));
}

#[test]
fn a_failing_backend_names_the_part_and_its_photos() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = demo_dataset(tmp.path());
    let fake = fake(true);
    let e = style_unit_on(&cfg(&ds), Unit::WHOLE, Some(&fake), &crate::Silent)
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("descriptor part 0, photos ")
            && e.ends_with("style backend on fake-device: out of device memory"),
        "{e}"
    );
    // color-stats never calls a backend it is given, nor records its weights or device.
    let stats = StyleConfig {
        tier: Tier::ColorStats,
        ..cfg(&ds)
    };
    style_unit_on(&stats, Unit::WHOLE, Some(&fake), &crate::Silent).unwrap();
    let store = Store::open(&ds.clone().into()).unwrap();
    let (kind, _) = nrw_dataset::descriptors::read_all(&store).unwrap().unwrap();
    assert_eq!(
        (kind.tier.as_str(), kind.weights_sha256.as_str()),
        ("color-stats", "")
    );
    assert!(units::unit_records(&store, units::STYLE)
        .unwrap()
        .iter()
        .all(|r| r.instruction_set.is_none()));
    let e = style_unit_on(&cfg(&ds), Unit::WHOLE, None, &crate::Silent).unwrap_err();
    assert_eq!(
        e.to_string(),
        "`style.weights` tier vgg16-64-l1 runs a network and none was given"
    );
}
