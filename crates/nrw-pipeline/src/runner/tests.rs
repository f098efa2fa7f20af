use super::*;
use crate::split::SplitConfig;
use nrw_export::Layout;

#[test]
fn every_export_layout_parses_by_its_cli_name_and_others_are_refused() {
    for l in Layout::ALL {
        let p: Pipeline =
            toml::from_str(&format!("name = \"x\"\n[export]\nlayout = \"{l}\"\n")).unwrap();
        assert_eq!(p.export.unwrap().layout, l);
        assert_eq!(l.name().parse::<Layout>(), Ok(l));
    }
    let e = toml::from_str::<Pipeline>("name = \"x\"\n[export]\nlayout = \"nerf\"\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("layout") && e.contains("nerfstudio"), "{e}");
    assert!("nerf".parse::<Layout>().unwrap_err().contains("nerfstudio"));
}

#[test]
fn a_densify_table_of_one_setting_takes_densifys_defaults() {
    let p: Pipeline = toml::from_str("name = \"x\"\n[densify]\nmax_image_size = 320\n").unwrap();
    let d = p.densify.unwrap();
    let c = densify_config(&d, Path::new("s"));
    let defaults = crate::densify::DensifyConfig::new(Path::new("s"));
    assert_eq!(c.settings.max_image_size(), Some(320));
    assert_eq!(
        (
            c.settings.matching(),
            c.settings.geometric,
            c.settings.overwrite,
            c.settings.stereo()
        ),
        (
            defaults.settings.matching(),
            true,
            false,
            defaults.settings.stereo()
        )
    );
    let none: Pipeline = toml::from_str("name = \"x\"\n[densify]\nmax_image_size = 0\n").unwrap();
    assert_eq!(
        densify_config(&none.densify.unwrap(), Path::new("s"))
            .settings
            .max_image_size(),
        None
    );
}

#[test]
fn a_table_of_one_setting_takes_the_papers_others() {
    let p: Pipeline = toml::from_str(
        "name = \"x\"\n[ingest]\nmax_empty = 0.99\n[split]\nseed = 3\n[style]\n[triplets]\n[export]\nsemantics = false\n",
    )
    .unwrap();
    assert!(p.densify.is_none(), "no [densify] table, no densify");
    let (i, paper) = (p.ingest.unwrap(), IngestConfig::new("", ""));
    assert_eq!(i.max_empty, 0.99);
    assert_eq!(
        (i.min_dim, i.radius, i.min_photo_side, i.rows_per_shard),
        (600, 1.0, 450, paper.settings.rows_per_shard)
    );
    let s = p.split.unwrap();
    assert_eq!((s.val, s.val_fraction, s.seed), (None, None, 3));
    assert_eq!(p.style.unwrap().tier, "vgg16-512");
    assert_eq!(p.triplets.unwrap().k, 20);
    let e = p.export.unwrap();
    assert_eq!(
        (e.layout, e.semantics, e.crop),
        (Layout::Official, false, None)
    );
    // The shipped file says what the defaults are: the two agree.
    let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../pipelines/paper.toml");
    let shipped = Pipeline::load(&file).unwrap();
    let (a, b) = (shipped.ingest.unwrap(), IngestTable::default());
    assert_eq!(
        (
            a.min_dim,
            a.radius,
            a.max_empty,
            a.min_photo_side,
            a.rows_per_shard
        ),
        (
            b.min_dim,
            b.radius,
            b.max_empty,
            b.min_photo_side,
            b.rows_per_shard
        )
    );
    assert_eq!(shipped.split.unwrap().val, Some(SplitConfig::new("").val));
    assert_eq!(shipped.triplets.unwrap().k, TripletsTable::default().k);
    assert_eq!(shipped.style.unwrap().tier, StyleTable::default().tier);
    assert!(toml::from_str::<Pipeline>("name = \"x\"\n[ingest]\nmax_emty = 0.9\n").is_err());
}
