//! A SegFormer's `config.json` (Hugging Face `SegformerConfig`): the architecture's numbers,
//! checked before any weight is read, and the class list, checked against ADE20K-150.

use std::collections::BTreeMap;
use std::path::Path;

use crate::error::{Result, SegmentError};

/// The ADE20K-150 classes the model's outputs must be, in order (`schemas/ade20k.csv`).
pub const ADE20K_CSV: &str = include_str!("../../../schemas/ade20k.csv");

/// Classes of ADE20K SceneParsing: the model's logits, one per class, ids 1…150.
pub const ADE_CLASSES: usize = 150;

/// Share of `id2label` names that must equal the ADE20K-150 names (the rest may be spelled
/// differently); below it the model labels something else.
pub const MIN_NAME_AGREEMENT: f64 = 0.9;

/// The architecture, with the defaults of `SegformerConfig` (SegFormer-b0) for absent keys.
#[derive(Debug, Clone, PartialEq, serde::Deserialize)]
#[serde(default)]
pub struct SegformerConfig {
    pub model_type: Option<String>,
    pub num_channels: usize,
    pub num_encoder_blocks: usize,
    pub depths: Vec<usize>,
    pub sr_ratios: Vec<usize>,
    pub hidden_sizes: Vec<usize>,
    pub patch_sizes: Vec<usize>,
    pub strides: Vec<usize>,
    pub num_attention_heads: Vec<usize>,
    pub mlp_ratios: Vec<f64>,
    pub hidden_act: String,
    pub decoder_hidden_size: usize,
    pub id2label: Option<BTreeMap<String, String>>,
    pub num_labels: Option<usize>,
}

impl Default for SegformerConfig {
    fn default() -> Self {
        SegformerConfig {
            model_type: None,
            num_channels: 3,
            num_encoder_blocks: 4,
            depths: vec![2, 2, 2, 2],
            sr_ratios: vec![8, 4, 2, 1],
            hidden_sizes: vec![32, 64, 160, 256],
            patch_sizes: vec![7, 3, 3, 3],
            strides: vec![4, 2, 2, 2],
            num_attention_heads: vec![1, 2, 5, 8],
            mlp_ratios: vec![4.0; 4],
            hidden_act: "gelu".into(),
            decoder_hidden_size: 256,
            id2label: None,
            num_labels: None,
        }
    }
}

impl SegformerConfig {
    /// Read and check `config.json`.
    pub fn read(path: &Path) -> Result<SegformerConfig> {
        let text = std::fs::read_to_string(path).map_err(|e| SegmentError::Io {
            path: path.into(),
            source: e,
        })?;
        let cfg: SegformerConfig = serde_json::from_str(&text)
            .map_err(|e| SegmentError::model(path, format!("not a SegFormer config.json: {e}")))?;
        cfg.check(path)?;
        Ok(cfg)
    }

    /// MLP width of a stage: `int(hidden_size * mlp_ratio)`, as transformers computes it.
    pub fn mlp_width(&self, stage: usize) -> usize {
        (self.hidden_sizes[stage] as f64 * self.mlp_ratios[stage]) as usize
    }

    /// The number of classes the config declares (`id2label`'s size, else `num_labels`).
    pub fn classes(&self) -> Option<usize> {
        self.id2label.as_ref().map(|m| m.len()).or(self.num_labels)
    }

    fn check(&self, path: &Path) -> Result<()> {
        let bad = |problem: String| Err(SegmentError::model(path, problem));
        if let Some(t) = self.model_type.as_deref().filter(|t| *t != "segformer") {
            return bad(format!("model_type is `{t}`, expected `segformer`"));
        }
        let n = self.num_encoder_blocks;
        if n == 0 || n > 8 {
            return bad(format!(
                "num_encoder_blocks is {n}, expected 1..=8 (SegFormer has 4)"
            ));
        }
        let lists: [(&str, usize); 7] = [
            ("depths", self.depths.len()),
            ("sr_ratios", self.sr_ratios.len()),
            ("hidden_sizes", self.hidden_sizes.len()),
            ("patch_sizes", self.patch_sizes.len()),
            ("strides", self.strides.len()),
            ("num_attention_heads", self.num_attention_heads.len()),
            ("mlp_ratios", self.mlp_ratios.len()),
        ];
        for (name, len) in lists {
            if len != n {
                return bad(format!(
                    "{name} lists {len} stages but num_encoder_blocks is {n}"
                ));
            }
        }
        if self.num_channels != 3 {
            return bad(format!(
                "num_channels is {}, expected 3 (RGB photos)",
                self.num_channels
            ));
        }
        if self.hidden_act != "gelu" {
            return bad(format!(
                "hidden_act is `{}`; only `gelu` (exact, erf) is implemented",
                self.hidden_act
            ));
        }
        for s in 0..n {
            let (c, heads) = (self.hidden_sizes[s], self.num_attention_heads[s]);
            if c == 0 || heads == 0 || c % heads != 0 || c > 4096 {
                return bad(format!(
                    "stage {s}: hidden size {c} is not a positive multiple of its {heads} attention heads (at most 4096)"
                ));
            }
            let (k, st, sr) = (self.patch_sizes[s], self.strides[s], self.sr_ratios[s]);
            if !(1..=15).contains(&k) || !(1..=8).contains(&st) || !(1..=32).contains(&sr) {
                return bad(format!(
                    "stage {s}: patch size {k}, stride {st}, sr ratio {sr} are outside the SegFormer family (1..=15, 1..=8, 1..=32)"
                ));
            }
            let r = self.mlp_ratios[s];
            if !(r.is_finite() && r > 0.0 && r <= 16.0) || self.mlp_width(s) == 0 {
                return bad(format!("stage {s}: mlp ratio {r} is outside 0..=16"));
            }
            if self.depths[s] > 64 {
                return bad(format!(
                    "stage {s}: depth {} is more than 64 blocks",
                    self.depths[s]
                ));
            }
        }
        if self.decoder_hidden_size == 0 || self.decoder_hidden_size > 4096 {
            return bad(format!(
                "decoder_hidden_size is {}, expected 1..=4096",
                self.decoder_hidden_size
            ));
        }
        match self.classes() {
            Some(ADE_CLASSES) => {}
            Some(k) => {
                return bad(format!(
                    "the model has {k} classes (id2label), expected the {ADE_CLASSES} of ADE20K SceneParsing (ids 1..=150, without `other`)"
                ))
            }
            None => return bad("no id2label or num_labels: cannot tell the model's classes".into()),
        }
        self.check_names(path)
    }

    /// `id2label` must be ADE20K-150 in order, or generic (`LABEL_i`): a 150-class model of
    /// another label set, or one with `other` at index 0, would give every pixel a wrong id.
    fn check_names(&self, path: &Path) -> Result<()> {
        let Some(map) = &self.id2label else {
            return Ok(());
        };
        let ade = ade_names();
        let mut generic = 0;
        let mut agree = 0;
        let mut first_diff = None;
        for (i, ade_name) in ade.iter().enumerate().take(ADE_CLASSES) {
            let Some(name) = map.get(&i.to_string()) else {
                return Err(SegmentError::model(
                    path,
                    format!("id2label has no entry \"{i}\" (expected keys \"0\"..\"149\")"),
                ));
            };
            let name = name.trim().to_lowercase();
            if name == format!("label_{i}") {
                generic += 1;
            } else if name == *ade_name {
                agree += 1;
            } else if first_diff.is_none() {
                first_diff = Some((i, name));
            }
        }
        if generic == ADE_CLASSES || agree as f64 >= MIN_NAME_AGREEMENT * ADE_CLASSES as f64 {
            return Ok(());
        }
        let (i, name) = first_diff.unwrap_or_default();
        Err(SegmentError::model(
            path,
            format!(
                "id2label is not ADE20K-150 in order: {agree} of {ADE_CLASSES} names agree (at least {:.0}% must), e.g. id2label[\"{i}\"] is `{name}` where ADE20K class {} is `{}`",
                MIN_NAME_AGREEMENT * 100.0,
                i + 1,
                ade[i]
            ),
        ))
    }
}

/// ADE20K-150 names in logit order (index = class id − 1), lower case.
pub fn ade_names() -> Vec<String> {
    ADE20K_CSV
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with("id,"))
        .filter_map(|l| l.split(',').nth(1))
        .map(|n| n.trim().to_lowercase())
        .collect()
}
