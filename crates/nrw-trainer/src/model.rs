//! The appearance encoder: photo + deep buffer (render RGB, depth) → an 8-dimensional
//! embedding, and the paper's triplet loss max(‖e_a − e_p‖² − ‖e_a − e_n‖² + α, 0).

use candle_core::{DType, Device, Tensor, D};
use candle_nn::{conv2d, linear, Conv2d, Conv2dConfig, Linear, Module, VarBuilder, VarMap};

use crate::error::Result;
use crate::loader::Batch;

/// Input channels: photo RGB, render RGB, depth.
pub const IN_CHANNELS: usize = 7;

/// Four stride-2 3×3 convolutions (16, 32, 64, 64 channels), global average pool, linear,
/// L2-normalised.
pub struct Encoder {
    convs: Vec<Conv2d>,
    head: Linear,
}

impl Encoder {
    /// A freshly initialised encoder whose variables live in `vm` (for the optimiser and
    /// checkpoints).
    pub fn new(vm: &VarMap, dim: usize) -> Result<Encoder> {
        let vb = VarBuilder::from_varmap(vm, DType::F32, &Device::Cpu);
        let cfg = Conv2dConfig {
            stride: 2,
            padding: 1,
            ..Default::default()
        };
        let widths = [IN_CHANNELS, 16, 32, 64, 64];
        let convs = (0..4)
            .map(|i| conv2d(widths[i], widths[i + 1], 3, cfg, vb.pp(format!("conv{i}"))))
            .collect::<candle_core::Result<Vec<_>>>()?;
        let head = linear(64, dim, vb.pp("head"))?;
        Ok(Encoder { convs, head })
    }

    /// Embeddings (B × dim) of a B × 7 × S × S input.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let mut h = x.clone();
        for c in &self.convs {
            h = c.forward(&h)?.relu()?;
        }
        let e = self.head.forward(&h.mean(D::Minus1)?.mean(D::Minus1)?)?;
        // Unit length (as FaceNet's triplet embedding): the margin α then has a fixed scale,
        // and the loss cannot grow by inflating the embedding.
        let norm = (e.sqr()?.sum_keepdim(1)? + 1e-12)?.sqrt()?;
        Ok(e.broadcast_div(&norm)?)
    }
}

/// The network input of a batch: photo, colour render and depth stacked on the channel axis.
pub fn input(b: &Batch) -> Result<Tensor> {
    let (n, s) = (b.len(), b.crop);
    let dev = Device::Cpu;
    let photo = Tensor::from_slice(&b.photo, (n, 3, s, s), &dev)?;
    let color = Tensor::from_slice(&b.color, (n, 3, s, s), &dev)?;
    let depth = Tensor::from_slice(&b.depth, (n, 1, s, s), &dev)?;
    Ok(Tensor::cat(&[&photo, &color, &depth], 1)?)
}

/// Mean triplet loss over anchors, positives and negatives (each B × dim).
pub fn triplet_loss(a: &Tensor, p: &Tensor, n: &Tensor, margin: f64) -> Result<Tensor> {
    let dp = (a - p)?.sqr()?.sum(1)?;
    let dn = (a - n)?.sqr()?.sum(1)?;
    Ok(((dp - dn)? + margin)?.relu()?.mean_all()?)
}
