//! VGG19 weights (torchvision names) are recognised by their tensors and run to relu5_2.

use nrw_style::{grams, Arch, Parallelism, Vgg};

#[test]
fn vgg19_weights_are_recognised_and_run() {
    // A VGG19 with zero kernels and unit biases: every activation is 1 after each ReLU,
    // so every Gram entry is 1/(C·H·W) · H·W = 1/C.
    let convs = Arch::Vgg19.convs_to_relu5_2();
    let mut tensors: Vec<(String, Vec<usize>, Vec<u8>)> = Vec::new();
    let mut in_ch = 3;
    for (idx, out) in &convs {
        tensors.push((
            format!("features.{idx}.weight"),
            vec![*out, in_ch, 3, 3],
            vec![0u8; out * in_ch * 9 * 4],
        ));
        tensors.push((
            format!("features.{idx}.bias"),
            vec![*out],
            (0..*out).flat_map(|_| 1f32.to_le_bytes()).collect(),
        ));
        in_ch = *out;
    }
    // The tensor that tells VGG19 from VGG16 (conv5_4), present in real files.
    tensors.push((
        "features.34.weight".into(),
        vec![1],
        0f32.to_le_bytes().to_vec(),
    ));
    let views: Vec<(String, safetensors::tensor::TensorView)> = tensors
        .iter()
        .map(|(n, s, b)| {
            (
                n.clone(),
                safetensors::tensor::TensorView::new(safetensors::Dtype::F32, s.clone(), b)
                    .unwrap(),
            )
        })
        .collect();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("vgg19.safetensors");
    std::fs::write(&path, safetensors::serialize(views, None).unwrap()).unwrap();
    let net = Vgg::load(&path).unwrap();
    assert_eq!(net.arch, Arch::Vgg19);
    assert_eq!(net.convs.len(), 14);
    let g = grams(&net, &vec![0.3f32; 3 * 32 * 32], 32, 32, Parallelism::None);
    assert_eq!(
        g.iter().map(|(c, _)| *c).collect::<Vec<_>>(),
        [64, 128, 256, 512, 512]
    );
    for (c, m) in &g {
        assert!(
            m.iter().all(|v| (v - 1.0 / *c as f64).abs() < 1e-12),
            "Gram entries are 1/C"
        );
    }
    // A file missing a layer names the tensor.
    let short: Vec<_> = tensors
        .iter()
        .filter(|t| t.0 != "features.30.bias")
        .map(|(n, s, b)| {
            (
                n.clone(),
                safetensors::tensor::TensorView::new(safetensors::Dtype::F32, s.clone(), b)
                    .unwrap(),
            )
        })
        .collect();
    std::fs::write(&path, safetensors::serialize(short, None).unwrap()).unwrap();
    let e = Vgg::load(&path).unwrap_err().to_string();
    assert!(
        e.contains("vgg19.safetensors") && e.contains("features.30.bias"),
        "{e}"
    );
}
