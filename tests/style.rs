//! `style`: one image's Grams against PyTorch, a dataset's descriptors resumed and never mixed.

use super::*;

#[test]
fn style_image_writes_the_five_grams_that_match_pytorch() {
    let Some(_) = shared::shared("fixtures") else {
        return;
    };
    let shared = shared::shared_dir();
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("g.safetensors");
    let png = shared.join("fixtures/vgg16/02928139_3448003521_320x240.png");
    ok(&[
        "style",
        "--image",
        png.to_str().unwrap(),
        "--weights",
        shared
            .join("weights/vgg16_imagenet.safetensors")
            .to_str()
            .unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let ours = std::fs::read(&out).unwrap();
    let ours = safetensors::SafeTensors::deserialize(&ours).unwrap();
    let fix = std::fs::read(shared.join("fixtures/vgg16/02928139_3448003521_320x240.safetensors"))
        .unwrap();
    let fix = safetensors::SafeTensors::deserialize(&fix).unwrap();
    for layer in ["relu1_2", "relu2_2", "relu3_2", "relu4_2", "relu5_2"] {
        let name = format!("gram_{layer}");
        let a = ours.tensor(&name).unwrap();
        assert_eq!(a.dtype(), safetensors::Dtype::F32);
        let a: Vec<f64> = a
            .data()
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().unwrap()) as f64)
            .collect();
        let b: Vec<f64> = fix
            .tensor(&name)
            .unwrap()
            .data()
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
            .collect();
        let scale = b.iter().fold(0f64, |m, v| m.max(v.abs()));
        let worst = a
            .iter()
            .zip(&b)
            .map(|(x, y)| (x - y).abs())
            .fold(0f64, f64::max)
            / scale;
        assert!(worst < 1e-4, "{layer}: {worst:e}");
    }
    let err = fails(&[
        "style",
        "--image",
        png.to_str().unwrap(),
        "--weights",
        png.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(err.contains("not a safetensors file"), "{err}");
}

#[test]
fn style_describes_a_dataset_resumably_and_never_mixes_kinds() {
    let Some(_) = shared::shared("weights") else {
        return;
    };
    let shared = shared::shared_dir();
    let weights = shared.join("weights/vgg16_imagenet.safetensors");
    let tmp = tempfile::tempdir().unwrap();
    let ds = small_dataset(tmp.path(), 5, false);
    let d = ds.to_str().unwrap();
    // Without weights a VGG tier is refused with the explicit fallback named.
    let err = fails(&["style", d, "--tier", "vgg16-128"]);
    assert!(
        err.contains("--weights") && err.contains("color-stats"),
        "{err}"
    );
    let o = nrw(&["style", d, "--tier", "color-stats"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (kind, rows) = nrw_dataset::descriptors::read_all(&nrw_dataset::Store::from(&ds))
        .unwrap()
        .unwrap();
    assert_eq!(
        (kind.tier.as_str(), rows.len(), rows[0].descriptor.len()),
        ("color-stats", 5, 9)
    );
    // Rerun: nothing recomputed.
    let o = nrw(&["style", d, "--tier", "color-stats"]);
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("0 parts written, 1 already there"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    // Another kind is refused unless asked to overwrite.
    let w = weights.to_str().unwrap();
    let err = fails(&["style", d, "--tier", "vgg16-128", "--weights", w]);
    assert!(
        err.contains("--overwrite") && err.contains("color-stats"),
        "{err}"
    );
    ok(&[
        "style",
        d,
        "--tier",
        "vgg16-128",
        "--weights",
        w,
        "--overwrite",
        "--quiet",
    ]);
    let (kind, rows) = nrw_dataset::descriptors::read_all(&nrw_dataset::Store::from(&ds))
        .unwrap()
        .unwrap();
    assert_eq!(kind.tier, "vgg16-128");
    assert_eq!(kind.weights_sha256.len(), 64);
    assert_eq!(
        rows[0].descriptor.len(),
        [64usize, 128, 256, 512, 512]
            .iter()
            .map(|c| c * (c + 1) / 2)
            .sum::<usize>()
    );
    // The squared distance of two descriptors is the style distance Σ‖ΔG‖²_F.
    let net = nrw_style::Vgg::load(&weights).unwrap();
    let reader = nrw_dataset::reader::Dataset::open(&ds).unwrap();
    let g = |id: u32| {
        let img =
            nrw_style::descriptor::prepare(&reader.get(id).unwrap().photo().unwrap(), Some(128));
        nrw_style::grams(
            &net,
            &nrw_style::to_input(&img, nrw_style::Preprocess::Imagenet),
            128,
            128,
            nrw_style::Parallelism::None,
        )
    };
    let (ga, gb) = (g(rows[0].image_id), g(rows[1].image_id));
    let direct: f64 = ga
        .iter()
        .zip(&gb)
        .flat_map(|(a, b)| a.1.iter().zip(&b.1).map(|(x, y)| (x - y).powi(2)))
        .sum();
    let via = nrw_style::distance2(&rows[0].descriptor, &rows[1].descriptor);
    assert!((via - direct).abs() <= 1e-4 * direct, "{via} vs {direct}");
    // The official code's [-1, 1] scaling in dataset mode: recorded, refused as a mix with the
    // ImageNet descriptors, and what the network sees.
    let with = |pre: &'static str, overwrite: bool| {
        let mut a = vec![
            "style",
            d,
            "--tier",
            "vgg16-128",
            "--weights",
            w,
            "--quiet",
            "--preprocess",
            pre,
        ];
        if overwrite {
            a.push("--overwrite");
        }
        a
    };
    let err = fails(&with("minus-one-to-one", false));
    assert!(
        err.contains("MinusOneToOne") && err.contains("--overwrite"),
        "{err}"
    );
    ok(&with("minus-one-to-one", true));
    let (kind, rows) = nrw_dataset::descriptors::read_all(&nrw_dataset::Store::from(&ds))
        .unwrap()
        .unwrap();
    assert_eq!(kind.preprocess, "MinusOneToOne");
    let img = nrw_style::descriptor::prepare(
        &reader.get(rows[0].image_id).unwrap().photo().unwrap(),
        Some(128),
    );
    let g = nrw_style::grams(
        &net,
        &nrw_style::to_input(&img, nrw_style::Preprocess::MinusOneToOne),
        128,
        128,
        nrw_style::Parallelism::None,
    );
    let relu1_2 = &g[0].1;
    let worst = relu1_2.iter().fold(0f64, |m, v| m.max(v.abs()));
    assert!(
        (rows[0].descriptor[0] as f64 - relu1_2[0]).abs() <= 1e-5 * worst,
        "{} vs {}",
        rows[0].descriptor[0],
        relu1_2[0]
    );
}

#[test]
fn an_nrw_isa_the_tool_cannot_honour_is_an_error_before_any_work() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("demo");
    let demo_with = |isa: &str| {
        Command::new(env!("CARGO_BIN_EXE_nrw-etl"))
            .args(["demo", "--out", out.to_str().unwrap()])
            .env("NRW_ISA", isa)
            .output()
            .unwrap()
    };
    let o = demo_with("avx2");
    assert_eq!(o.status.code(), Some(1));
    assert_eq!(
        String::from_utf8_lossy(&o.stderr).trim(),
        "error: NRW_ISA=\"avx2\" names no instruction set (known: avx512f, avx2+fma, baseline)"
    );
    assert!(!out.exists(), "nothing is written");
    // Wider than this CPU: refused too (on an AVX-512 machine nothing is wider to ask for).
    if let Some(wider) = nrw_gemm::Isa::ALL
        .into_iter()
        .find(|i| *i > nrw_gemm::widest())
    {
        let o = demo_with(wider.name());
        assert_eq!(o.status.code(), Some(1));
        assert!(
            String::from_utf8_lossy(&o.stderr).contains("asks for instructions this CPU lacks"),
            "{}",
            String::from_utf8_lossy(&o.stderr)
        );
        assert!(!out.exists());
    }
}
