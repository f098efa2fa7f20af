//! SegFormer (Xie et al. 2021) for semantic segmentation, as `transformers`'
//! `SegformerForSemanticSegmentation` computes it, from a user's `config.json` and
//! `model.safetensors` in the Hugging Face layout (the names the released checkpoints use).
//! Every tensor's presence, dtype and shape is checked against the config before use.
//!
//! The all-MLP decode head is evaluated in a cheaper but equal form: the per-stage linear
//! layer, the 1 × 1 fuse convolution and the (inference) batch norm are one linear map per
//! stage, applied at the stage's own resolution before the bilinear upsampling (which is
//! linear and preserves constants, so the two commute). See [`Head`].

use std::path::{Path, PathBuf};

use nrw_gemm::Parallelism;
use rayon::prelude::*;

use crate::config::{SegformerConfig, ADE_CLASSES};
use crate::error::{Result, SegmentError};
use crate::ops::{matmul, softmax_rows, upsample_add, Conv, DwConv, Linear, Map, Mat, Norm};

/// Batch norm's epsilon (`nn.BatchNorm2d` default, the decode head's).
pub const BN_EPS: f64 = 1e-5;

/// Largest weights file read (the largest released SegFormer, b5, is about 340 MB).
pub const MAX_WEIGHTS_BYTES: u64 = 4 << 30;

/// Query rows per attention work item: scores for this many rows stay in cache.
const ATTN_ROWS: usize = 128;

/// Efficient self-attention: keys and values from a map reduced `sr` times.
#[derive(Debug, Clone)]
struct Attention {
    heads: usize,
    query: Linear,
    /// Keys and values in one product: weight rows 0..C are the key's, C..2C the value's.
    kv: Linear,
    sr: Option<(Conv, Norm)>,
    out: Linear,
}

/// One transformer block: attention and Mix-FFN, each after a layer norm, each residual.
#[derive(Debug, Clone)]
struct Block {
    ln1: Norm,
    attn: Attention,
    ln2: Norm,
    dense1: Linear,
    dw: DwConv,
    dense2: Linear,
}

/// One encoder stage: overlapping patch embedding, blocks, a final layer norm.
#[derive(Debug, Clone)]
struct Stage {
    embed: Conv,
    embed_ln: Norm,
    blocks: Vec<Block>,
    ln: Norm,
}

/// The decode head, folded: stage i contributes `upsample(x_i · A_i)`; the sum plus `bias`,
/// through ReLU, is the classifier's input. `A_i = W_iᵀ · F_i · diag(s)` where `W_i` is the
/// stage's linear layer, `F_i` its slice of the fuse convolution and `s` the batch norm's
/// scale; `bias` gathers the linear layers' biases through `F`, and the norm's shift.
/// Folded in f64, stored in f32 (the only precision given up, once, at load).
#[derive(Debug, Clone)]
struct Head {
    /// Per stage, C_i × D row-major.
    fold: Vec<Vec<f32>>,
    bias: Vec<f32>,
    classifier: Linear,
}

/// A loaded SegFormer.
#[derive(Debug, Clone)]
pub struct Segformer {
    pub config: SegformerConfig,
    stages: Vec<Stage>,
    head: Head,
    /// The folder (or file) the model came from.
    pub path: PathBuf,
    /// SHA-256 of `model.safetensors`: recorded with the labels so runs are never mixed.
    pub sha256: String,
}

/// The model's files: a folder with `config.json` and `model.safetensors`, or the weights
/// file with `config.json` beside it.
pub fn model_files(path: &Path) -> Result<(PathBuf, PathBuf)> {
    let (dir, weights) = if path.is_dir() {
        (path.to_path_buf(), path.join("model.safetensors"))
    } else {
        let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        (dir, path.to_path_buf())
    };
    let config = dir.join("config.json");
    for (f, what) in [(&config, "config.json"), (&weights, "model.safetensors")] {
        if !f.is_file() {
            return Err(SegmentError::model(
                f,
                format!("no {what}: a SegFormer in the Hugging Face layout (config.json + model.safetensors, as `save_pretrained` writes) is expected"),
            ));
        }
    }
    Ok((config, weights))
}

/// Reads tensors by name, checking dtype and shape; remembers which were used.
struct Tensors<'a> {
    st: safetensors::SafeTensors<'a>,
    path: &'a Path,
    used: std::collections::BTreeSet<String>,
}

impl Tensors<'_> {
    fn get(&mut self, name: &str, shape: &[usize]) -> Result<Vec<f32>> {
        let t = self.st.tensor(name).map_err(|_| {
            SegmentError::model(
                self.path,
                format!("tensor `{name}` is missing (expected {shape:?} for this config.json)"),
            )
        })?;
        if t.dtype() != safetensors::Dtype::F32 || t.shape() != shape {
            return Err(SegmentError::model(
                self.path,
                format!(
                    "tensor `{name}` is {:?} {:?}, expected F32 {shape:?} for this config.json",
                    t.dtype(),
                    t.shape()
                ),
            ));
        }
        self.used.insert(name.to_string());
        let v: Vec<f32> = t
            .data()
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        if let Some(i) = v.iter().position(|x| !x.is_finite()) {
            return Err(SegmentError::model(
                self.path,
                format!(
                    "tensor `{name}` holds {} at index {i}: a damaged or diverged model",
                    v[i]
                ),
            ));
        }
        Ok(v)
    }

    fn linear(&mut self, name: &str, din: usize, dout: usize) -> Result<Linear> {
        Ok(Linear {
            din,
            dout,
            w: self.get(&format!("{name}.weight"), &[dout, din])?,
            b: self.get(&format!("{name}.bias"), &[dout])?,
        })
    }

    fn norm(&mut self, name: &str, c: usize) -> Result<Norm> {
        Ok(Norm {
            g: self.get(&format!("{name}.weight"), &[c])?,
            b: self.get(&format!("{name}.bias"), &[c])?,
        })
    }

    fn conv(
        &mut self,
        name: &str,
        cin: usize,
        cout: usize,
        k: usize,
        stride: usize,
        pad: usize,
    ) -> Result<Conv> {
        let w = self.get(&format!("{name}.weight"), &[cout, cin, k, k])?;
        let b = self.get(&format!("{name}.bias"), &[cout])?;
        Ok(Conv::from_oihw(cout, cin, k, stride, pad, &w, b))
    }

    /// Tensors in the file that this config does not use: a config of another model.
    fn unused(&self) -> Vec<String> {
        self.st
            .names()
            .into_iter()
            .filter(|n| !self.used.contains(*n) && !n.ends_with("num_batches_tracked"))
            .map(|n| n.to_string())
            .collect()
    }
}

impl Segformer {
    /// Load a model folder (or weights file); see [`model_files`].
    pub fn load(path: &Path) -> Result<Segformer> {
        let (config_path, weights) = model_files(path)?;
        let config = SegformerConfig::read(&config_path)?;
        let bytes = read_weights(&weights)?;
        let sha256 = {
            use sha2::{Digest, Sha256};
            Sha256::digest(&bytes)
                .iter()
                .map(|b| format!("{b:02x}"))
                .collect()
        };
        let st = safetensors::SafeTensors::deserialize(&bytes).map_err(|e| {
            SegmentError::model(
                &weights,
                format!("not a safetensors file (truncated or damaged?): {e}"),
            )
        })?;
        let mut t = Tensors {
            st,
            path: &weights,
            used: Default::default(),
        };
        let stages = (0..config.num_encoder_blocks)
            .map(|s| load_stage(&mut t, &config, s))
            .collect::<Result<Vec<_>>>()?;
        let head = load_head(&mut t, &config)?;
        let unused = t.unused();
        if !unused.is_empty() {
            return Err(SegmentError::model(
                &weights,
                format!(
                    "{} tensors are not used by {} (e.g. `{}`): the config describes another model",
                    unused.len(),
                    config_path.display(),
                    unused[0]
                ),
            ));
        }
        Ok(Segformer {
            config,
            stages,
            head,
            path: path.to_path_buf(),
            sha256,
        })
    }

    /// Logits (150 channels, ADE ids 1…150 in order) at a quarter of the input's size, for a
    /// preprocessed CHW input (see [`crate::preprocess`]).
    pub fn logits(&self, input_chw: &[f32], h: usize, w: usize, par: Parallelism) -> Map {
        let mut x = Map::from_chw(input_chw, 3, h, w);
        let mut features = Vec::with_capacity(self.stages.len());
        for stage in &self.stages {
            x = stage.forward(&x, par);
            features.push(x.clone());
        }
        self.head.forward(&features, par)
    }

    /// The smallest input side for which every stage has at least one pixel and at least
    /// its reduction ratio's worth for the key/value convolution.
    pub fn min_side(&self) -> usize {
        let mut req = 1;
        for (s, stage) in self.stages.iter().enumerate().rev() {
            req = req.max(self.config.sr_ratios[s]);
            let e = &stage.embed;
            req = ((req - 1) * e.stride + e.k)
                .saturating_sub(2 * e.pad)
                .max(1);
        }
        req
    }
}

fn read_weights(path: &Path) -> Result<Vec<u8>> {
    let len = std::fs::metadata(path)
        .map_err(|e| SegmentError::Io {
            path: path.into(),
            source: e,
        })?
        .len();
    if len > MAX_WEIGHTS_BYTES {
        return Err(SegmentError::model(
            path,
            format!("{len} bytes is more than the {MAX_WEIGHTS_BYTES} a SegFormer needs"),
        ));
    }
    std::fs::read(path).map_err(|e| SegmentError::Io {
        path: path.into(),
        source: e,
    })
}

fn load_stage(t: &mut Tensors, cfg: &SegformerConfig, s: usize) -> Result<Stage> {
    let c = cfg.hidden_sizes[s];
    let cin = if s == 0 {
        cfg.num_channels
    } else {
        cfg.hidden_sizes[s - 1]
    };
    let (k, stride) = (cfg.patch_sizes[s], cfg.strides[s]);
    let pe = format!("segformer.encoder.patch_embeddings.{s}");
    let embed = t.conv(&format!("{pe}.proj"), cin, c, k, stride, k / 2)?;
    let embed_ln = t.norm(&format!("{pe}.layer_norm"), c)?;
    let hidden = cfg.mlp_width(s);
    let sr = cfg.sr_ratios[s];
    let mut blocks = Vec::with_capacity(cfg.depths[s]);
    for j in 0..cfg.depths[s] {
        let b = format!("segformer.encoder.block.{s}.{j}");
        let att = format!("{b}.attention.self");
        let query = t.linear(&format!("{att}.query"), c, c)?;
        let key = t.linear(&format!("{att}.key"), c, c)?;
        let value = t.linear(&format!("{att}.value"), c, c)?;
        let kv = Linear {
            din: c,
            dout: 2 * c,
            w: [key.w, value.w].concat(),
            b: [key.b, value.b].concat(),
        };
        let sr = if sr > 1 {
            Some((
                t.conv(&format!("{att}.sr"), c, c, sr, sr, 0)?,
                t.norm(&format!("{att}.layer_norm"), c)?,
            ))
        } else {
            None
        };
        let dw_w = t.get(&format!("{b}.mlp.dwconv.dwconv.weight"), &[hidden, 1, 3, 3])?;
        let dw_b = t.get(&format!("{b}.mlp.dwconv.dwconv.bias"), &[hidden])?;
        blocks.push(Block {
            ln1: t.norm(&format!("{b}.layer_norm_1"), c)?,
            attn: Attention {
                heads: cfg.num_attention_heads[s],
                query,
                kv,
                sr,
                out: t.linear(&format!("{b}.attention.output.dense"), c, c)?,
            },
            ln2: t.norm(&format!("{b}.layer_norm_2"), c)?,
            dense1: t.linear(&format!("{b}.mlp.dense1"), c, hidden)?,
            dw: DwConv::from_weight(hidden, &dw_w, dw_b),
            dense2: t.linear(&format!("{b}.mlp.dense2"), hidden, c)?,
        });
    }
    let ln = t.norm(&format!("segformer.encoder.layer_norm.{s}"), c)?;
    Ok(Stage {
        embed,
        embed_ln,
        blocks,
        ln,
    })
}

fn load_head(t: &mut Tensors, cfg: &SegformerConfig) -> Result<Head> {
    let n = cfg.num_encoder_blocks;
    let d = cfg.decoder_hidden_size;
    let fuse = t.get("decode_head.linear_fuse.weight", &[d, n * d, 1, 1])?;
    let get_d = |t: &mut Tensors, name: &str| -> Result<Vec<f64>> {
        Ok(t.get(&format!("decode_head.batch_norm.{name}"), &[d])?
            .iter()
            .map(|v| *v as f64)
            .collect())
    };
    let (gamma, beta) = (get_d(t, "weight")?, get_d(t, "bias")?);
    let (mean, var) = (get_d(t, "running_mean")?, get_d(t, "running_var")?);
    if let Some(i) = var.iter().position(|v| v.is_nan() || *v < 0.0) {
        return Err(SegmentError::model(
            t.path,
            format!(
                "decode_head.batch_norm.running_var[{i}] is {}, a variance cannot be negative",
                var[i]
            ),
        ));
    }
    let scale: Vec<f64> = (0..d)
        .map(|o| gamma[o] / (var[o] + BN_EPS).sqrt())
        .collect();
    let mut bias: Vec<f64> = (0..d).map(|o| beta[o] - mean[o] * scale[o]).collect();
    let mut fold = Vec::with_capacity(n);
    for i in 0..n {
        let ci = cfg.hidden_sizes[i];
        let lin = t.linear(&format!("decode_head.linear_c.{i}.proj"), ci, d)?;
        // The concatenation is in reverse stage order: stage i's block of fuse inputs is p.
        let p = n - 1 - i;
        let columns: Vec<(Vec<f64>, f64)> = (0..d)
            .into_par_iter()
            .map(|o| {
                let f = &fuse[o * n * d + p * d..][..d];
                let mut col = vec![0f64; ci];
                let mut b = 0f64;
                for (k, fk) in f.iter().map(|v| *v as f64).enumerate() {
                    let row = &lin.w[k * ci..(k + 1) * ci];
                    col.iter_mut()
                        .zip(row)
                        .for_each(|(a, w)| *a += *w as f64 * fk);
                    b += lin.b[k] as f64 * fk;
                }
                (col, b)
            })
            .collect();
        let mut a = vec![0f32; ci * d];
        for (o, (col, b)) in columns.iter().enumerate() {
            // Precision: the folded map is rounded to f32 here, once.
            for (c, v) in col.iter().enumerate() {
                a[c * d + o] = (v * scale[o]) as f32;
            }
            bias[o] += b * scale[o];
        }
        fold.push(a);
    }
    let cls_w = t.get("decode_head.classifier.weight", &[ADE_CLASSES, d, 1, 1])?;
    let cls_b = t.get("decode_head.classifier.bias", &[ADE_CLASSES])?;
    Ok(Head {
        fold,
        bias: bias.iter().map(|v| *v as f32).collect(),
        classifier: Linear {
            din: d,
            dout: ADE_CLASSES,
            w: cls_w,
            b: cls_b,
        },
    })
}

impl Stage {
    fn forward(&self, input: &Map, par: Parallelism) -> Map {
        let mut x = self.embed.apply(input, par);
        self.embed_ln.apply(&mut x.data);
        for b in &self.blocks {
            b.forward(&mut x, par);
        }
        self.ln.apply(&mut x.data);
        x
    }
}

impl Block {
    fn forward(&self, x: &mut Map, par: Parallelism) {
        let mut t = x.data.clone();
        self.ln1.apply(&mut t);
        let ctx = self.attn.context(&Map { data: t, ..*x }, par);
        self.attn.out.apply_into(&mut x.data, 1.0, &ctx, par);
        let mut t = x.data.clone();
        self.ln2.apply(&mut t);
        let h1 = Map {
            h: x.h,
            w: x.w,
            c: self.dense1.dout,
            data: self.dense1.apply(&t, par),
        };
        let h2 = self.dw.apply_gelu(&h1);
        self.dense2.apply_into(&mut x.data, 1.0, &h2.data, par);
    }
}

impl Attention {
    /// The heads' outputs, concatenated (before the output projection).
    fn context(&self, t: &Map, par: Parallelism) -> Vec<f32> {
        let c = t.c;
        let q = self.query.apply(&t.data, par);
        let kv = match &self.sr {
            Some((conv, ln)) => {
                let mut r = conv.apply(t, par);
                ln.apply(&mut r.data);
                self.kv.apply(&r.data, par)
            }
            None => self.kv.apply(&t.data, par),
        };
        let m = kv.len() / (2 * c);
        let d = c / self.heads;
        let scale = 1.0 / (d as f32).sqrt();
        let mut ctx = vec![0f32; q.len()];
        // Work items of ATTN_ROWS query rows, all heads: each writes its own rows.
        ctx.par_chunks_mut(ATTN_ROWS * c)
            .zip(q.par_chunks(ATTN_ROWS * c))
            .for_each(|(out, qb)| {
                let rows = qb.len() / c;
                let mut scores = vec![0f32; rows * m];
                for h in 0..self.heads {
                    let qh = Mat {
                        data: &qb[h * d..],
                        rows,
                        cols: d,
                        rs: c,
                        cs: 1,
                    };
                    // Kᵀ of head h: element (i, j) is key j's channel h·d + i.
                    let kt = Mat {
                        data: &kv[h * d..],
                        rows: d,
                        cols: m,
                        rs: 1,
                        cs: 2 * c,
                    };
                    matmul(&mut scores, m, 0.0, qh, kt, scale, Parallelism::None);
                    softmax_rows(&mut scores, m);
                    let p = Mat {
                        data: &scores,
                        rows,
                        cols: m,
                        rs: m,
                        cs: 1,
                    };
                    let vh = Mat {
                        data: &kv[c + h * d..],
                        rows: m,
                        cols: d,
                        rs: 2 * c,
                        cs: 1,
                    };
                    matmul(&mut out[h * d..], c, 0.0, p, vh, 1.0, Parallelism::None);
                }
            });
        ctx
    }
}

impl Head {
    fn forward(&self, features: &[Map], par: Parallelism) -> Map {
        let d = self.bias.len();
        let (h0, w0) = (features[0].h, features[0].w);
        let mut acc = Map::zeros(h0, w0, d);
        for (x, a) in features.iter().zip(&self.fold) {
            let lhs = Mat {
                data: &x.data,
                rows: x.h * x.w,
                cols: x.c,
                rs: x.c,
                cs: 1,
            };
            let rhs = Mat {
                data: a,
                rows: x.c,
                cols: d,
                rs: d,
                cs: 1,
            };
            if (x.h, x.w) == (h0, w0) {
                matmul(&mut acc.data, d, 1.0, lhs, rhs, 1.0, par);
            } else {
                let mut y = Map::zeros(x.h, x.w, d);
                matmul(&mut y.data, d, 0.0, lhs, rhs, 1.0, par);
                upsample_add(&mut acc, &y);
            }
        }
        acc.data.par_chunks_mut(d * 64).for_each(|rows| {
            for r in rows.chunks_exact_mut(d) {
                r.iter_mut()
                    .zip(&self.bias)
                    .for_each(|(v, b)| *v = (*v + b).max(0.0));
            }
        });
        Map {
            h: h0,
            w: w0,
            c: ADE_CLASSES,
            data: self.classifier.apply(&acc.data, par),
        }
    }
}
