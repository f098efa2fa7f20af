//! Appearance-encoder pretraining on triplets: Adam (its moments are saved with the weights,
//! so a resumed run continues exactly where it stopped), checkpoints written atomically,
//! evaluation by held-out triplet accuracy and by how well embeddings separate known
//! appearance classes.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use candle_core::{Device, Tensor, Var};
use candle_nn::VarMap;
use nrw_dataset::reader::Dataset;
use serde::{Deserialize, Serialize};

use crate::error::{Result, TrainError};
use crate::loader::{Loader, LoaderConfig};
use crate::model::{input, triplet_loss, Encoder};
use nrw_dataset::sampling::{Triplet, TripletSampler};

/// Settings of a training run (the paper: α = 0.1, 8-D embedding, 256² crops).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct TrainConfig {
    pub steps: u64,
    /// Triplets per step.
    pub batch: usize,
    pub crop: u32,
    pub lr: f64,
    pub margin: f64,
    pub dim: usize,
    pub pos_k: usize,
    pub neg_k: usize,
    pub hold_out_every: u32,
    pub seed: u64,
    pub checkpoint_every: u64,
}

impl Default for TrainConfig {
    fn default() -> Self {
        TrainConfig {
            steps: 1000,
            batch: 8,
            crop: 256,
            lr: 1e-3,
            margin: 0.1,
            dim: 8,
            pos_k: 5,
            neg_k: 13,
            hold_out_every: 5,
            seed: 0,
            checkpoint_every: 100,
        }
    }
}

/// What a run did.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Report {
    pub losses: Vec<(u64, f64)>,
    pub accuracy_before: f64,
    pub accuracy_after: f64,
    pub held_out_triplets: usize,
    /// Fraction of each photo's 3 nearest embeddings with the same true appearance (synthetic
    /// scenes), before and after.
    pub class_agreement: Option<(f64, f64)>,
    pub resumed_from: Option<u64>,
}

#[derive(Serialize, Deserialize)]
struct State {
    step: u64,
    config: TrainConfig,
    losses: Vec<(u64, f64)>,
    accuracy_before: f64,
    class_before: Option<f64>,
}

/// Adam whose first and second moments are plain tensors, saved in checkpoints.
pub struct Adam {
    vars: Vec<(String, Var)>,
    m: Vec<Tensor>,
    v: Vec<Tensor>,
    t: u64,
    lr: f64,
}

impl Adam {
    /// Adam over every variable of `vm`, moments at zero.
    pub fn new(vm: &VarMap, lr: f64) -> Result<Adam> {
        let mut vars: Vec<(String, Var)> = vm
            .data()
            .lock()
            .expect("var map lock")
            .iter()
            .map(|(k, v)| (k.clone(), v.clone()))
            .collect();
        vars.sort_by(|a, b| a.0.cmp(&b.0));
        let zeros = |v: &Var| v.as_tensor().zeros_like();
        let m = vars
            .iter()
            .map(|(_, v)| zeros(v))
            .collect::<candle_core::Result<_>>()?;
        let v2 = vars
            .iter()
            .map(|(_, v)| zeros(v))
            .collect::<candle_core::Result<_>>()?;
        Ok(Adam {
            vars,
            m,
            v: v2,
            t: 0,
            lr,
        })
    }

    /// Backpropagate `loss` and update every variable.
    pub fn step(&mut self, loss: &Tensor) -> Result<()> {
        let (b1, b2, eps) = (0.9f64, 0.999f64, 1e-8f64);
        let grads = loss.backward()?;
        self.t += 1;
        let c1 = 1.0 - b1.powi(self.t as i32);
        let c2 = 1.0 - b2.powi(self.t as i32);
        for (i, (_, var)) in self.vars.iter().enumerate() {
            let Some(g) = grads.get(var) else { continue };
            self.m[i] = ((&self.m[i] * b1)? + (g * (1.0 - b1))?)?;
            self.v[i] = ((&self.v[i] * b2)? + (g.sqr()? * (1.0 - b2))?)?;
            let update = ((&self.m[i] / c1)? / ((&self.v[i] / c2)?.sqrt()? + eps)?)?;
            var.set(&(var.as_tensor() - (update * self.lr)?)?)?;
        }
        Ok(())
    }
}

/// Embeddings of photos from one fixed crop each (evaluation is deterministic).
pub fn embed(enc: &Encoder, loader: &Loader, ids: &[u32]) -> Result<HashMap<u32, Vec<f32>>> {
    let mut out = HashMap::new();
    for chunk in ids.chunks(32) {
        let b = loader.batch_of(chunk, u64::MAX, 0)?;
        let e = enc.forward(&input(&b)?)?.to_vec2::<f32>()?;
        for (id, v) in chunk.iter().zip(e) {
            out.insert(*id, v);
        }
    }
    Ok(out)
}

fn d2(a: &[f32], b: &[f32]) -> f64 {
    a.iter().zip(b).map(|(x, y)| ((x - y) as f64).powi(2)).sum()
}

/// Fraction of triplets with d(a, p) < d(a, n) in the embedding.
pub fn triplet_accuracy(emb: &HashMap<u32, Vec<f32>>, triplets: &[Triplet]) -> f64 {
    if triplets.is_empty() {
        return f64::NAN;
    }
    let ok = triplets
        .iter()
        .filter(|(a, p, n)| d2(&emb[a], &emb[p]) < d2(&emb[a], &emb[n]))
        .count();
    ok as f64 / triplets.len() as f64
}

/// Fraction of each photo's `k` nearest embeddings sharing its label.
pub fn class_agreement(
    emb: &HashMap<u32, Vec<f32>>,
    labels: &HashMap<u32, String>,
    k: usize,
) -> f64 {
    let ids: Vec<u32> = labels
        .keys()
        .copied()
        .filter(|i| emb.contains_key(i))
        .collect();
    let (mut hit, mut all) = (0usize, 0usize);
    for &i in &ids {
        let mut d: Vec<(f64, u32)> = ids
            .iter()
            .filter(|&&j| j != i)
            .map(|&j| (d2(&emb[&i], &emb[&j]), j))
            .collect();
        d.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        for (_, j) in d.iter().take(k) {
            hit += (labels[j] == labels[&i]) as usize;
            all += 1;
        }
    }
    hit as f64 / all.max(1) as f64
}

/// True appearance labels of a synthetic scene's photos (ground_truth/appearance.json next to
/// the scene the dataset was made from), by image id; None for real scenes.
pub fn appearance_labels(ds: &Dataset) -> Option<HashMap<u32, String>> {
    let path = Path::new(&ds.manifest.scene.scene_dir).join(nrw_synth::truth::APPEARANCE);
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(path).ok()?).ok()?;
    let by_name: HashMap<String, String> = v
        .as_array()?
        .iter()
        .filter_map(|t| {
            Some((
                t["name"].as_str()?.to_string(),
                t["label"].as_str()?.to_string(),
            ))
        })
        .collect();
    // Names from the scene table: decoding every view's row for its name would read every photo.
    let names = nrw_dataset::scene::read_verdicts(&ds.store).ok()?;
    let mut out = HashMap::new();
    for (id, name, verdict) in names {
        if let (true, Some(l)) = (
            verdict == nrw_dataset::scene::VERDICT_KEPT,
            by_name.get(&name),
        ) {
            out.insert(id, l.clone());
        }
    }
    Some(out)
}

/// Seeded initialisation (candle's CPU generator cannot be seeded): weights uniform in
/// ±1/√fan_in (PyTorch's default bound), biases zero; variables in name order.
fn init_weights(vm: &VarMap, seed: u64) -> Result<()> {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let data = vm.data().lock().expect("var map lock");
    let mut names: Vec<&String> = data.keys().collect();
    names.sort();
    for name in names {
        let var = &data[name];
        let dims = var.dims().to_vec();
        let n: usize = dims.iter().product();
        let values: Vec<f32> = if name.ends_with("bias") {
            vec![0.0; n]
        } else {
            let fan_in: usize = dims[1..].iter().product::<usize>().max(1);
            let bound = 1.0 / (fan_in as f32).sqrt();
            (0..n).map(|_| rng.random_range(-bound..bound)).collect()
        };
        var.set(&Tensor::from_vec(values, dims, &Device::Cpu)?)?;
    }
    Ok(())
}

fn ckpt_paths(dir: &Path) -> (PathBuf, PathBuf) {
    (
        dir.join("checkpoint.safetensors"),
        dir.join("checkpoint.json"),
    )
}

fn save(dir: &Path, adam: &Adam, state: &State) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|source| TrainError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let (weights, meta) = ckpt_paths(dir);
    let mut tensors: HashMap<String, Tensor> = HashMap::new();
    for (i, (name, var)) in adam.vars.iter().enumerate() {
        tensors.insert(format!("w/{name}"), var.as_tensor().clone());
        tensors.insert(format!("m/{name}"), adam.m[i].clone());
        tensors.insert(format!("v/{name}"), adam.v[i].clone());
    }
    // Weights first, then the state naming their step: both through temp file + rename.
    let tmp = weights.with_extension("safetensors.tmp");
    candle_core::safetensors::save(&tensors, &tmp)?;
    std::fs::rename(&tmp, &weights).map_err(|source| TrainError::Io {
        path: weights.clone(),
        source,
    })?;
    let text = serde_json::to_string_pretty(state).expect("state serialises");
    nrw_dataset::atomic::write_bytes_atomic(&meta, text.as_bytes())?;
    Ok(())
}

fn load(dir: &Path, adam: &mut Adam) -> Result<Option<State>> {
    let (weights, meta) = ckpt_paths(dir);
    if !meta.is_file() {
        return Ok(None);
    }
    let bad = |problem: String| TrainError::Checkpoint {
        path: meta.clone(),
        problem,
    };
    let state: State =
        serde_json::from_str(
            &std::fs::read_to_string(&meta).map_err(|source| TrainError::Io {
                path: meta.clone(),
                source,
            })?,
        )
        .map_err(|e| bad(e.to_string()))?;
    let t = candle_core::safetensors::load(&weights, &Device::Cpu)?;
    for (i, (name, var)) in adam.vars.iter().enumerate() {
        let get = |k: String| {
            t.get(&k).cloned().ok_or_else(|| TrainError::Checkpoint {
                path: weights.clone(),
                problem: format!("tensor `{k}` is missing (another model?)"),
            })
        };
        var.set(&get(format!("w/{name}"))?)?;
        adam.m[i] = get(format!("m/{name}"))?;
        adam.v[i] = get(format!("v/{name}"))?;
    }
    adam.t = state.step;
    Ok(Some(state))
}

/// Train (or resume training) the appearance encoder; `progress(step, loss)` is called after
/// every step. Checkpoints go to `out`; a run whose `out` holds a checkpoint of the same
/// settings continues from it.
pub fn train(
    ds: &Dataset,
    split: &str,
    cfg: &TrainConfig,
    out: &Path,
    progress: &mut dyn FnMut(u64, f64),
) -> Result<Report> {
    let rows = nrw_dataset::triplets::read_triplets(&ds.store)?.ok_or_else(|| {
        TrainError::NoTripletTable {
            dataset: ds.dir.clone(),
        }
    })?;
    let mut sampler =
        TripletSampler::new(&rows, cfg.pos_k, cfg.neg_k, cfg.hold_out_every, cfg.seed)?;
    let loader = Loader::new(
        ds,
        split,
        LoaderConfig {
            crop: cfg.crop,
            batch: cfg.batch * 3,
            seed: cfg.seed,
            semantics: false,
        },
    )?;
    let vm = VarMap::new();
    let enc = Encoder::new(&vm, cfg.dim)?;
    init_weights(&vm, cfg.seed)?;
    let mut adam = Adam::new(&vm, cfg.lr)?;
    let held = sampler.held_out_triplets();
    let mut eval_ids: Vec<u32> = held.iter().flat_map(|t| [t.0, t.1, t.2]).collect();
    eval_ids.sort_unstable();
    eval_ids.dedup();
    let labels = appearance_labels(ds);
    let evaluate = |enc: &Encoder| -> Result<(f64, Option<f64>)> {
        let mut ids = eval_ids.clone();
        if let Some(l) = &labels {
            ids.extend(l.keys());
            ids.sort_unstable();
            ids.dedup();
        }
        let emb = embed(enc, &loader, &ids)?;
        Ok((
            triplet_accuracy(&emb, &held),
            labels.as_ref().map(|l| class_agreement(&emb, l, 3)),
        ))
    };
    let mut state = starting_state(out, &mut adam, cfg, || evaluate(&enc))?;
    let resumed_from = (state.step > 0).then_some(state.step);
    // The sampler's stream is replayed up to the step reached, so a resumed run draws the
    // same triplets as an uninterrupted one.
    for _ in 0..state.step {
        sampler.sample(cfg.batch);
    }
    while state.step < cfg.steps {
        let t = sampler.sample(cfg.batch);
        let l = step_loss(&enc, &mut adam, &loader, &t, state.step, cfg)?;
        state.step += 1;
        state.losses.push((state.step, l));
        progress(state.step, l);
        if state.step % cfg.checkpoint_every == 0 || state.step == cfg.steps {
            save(out, &adam, &state)?;
        }
    }
    let (acc, class) = evaluate(&enc)?;
    Ok(Report {
        losses: state.losses.clone(),
        accuracy_before: state.accuracy_before,
        accuracy_after: acc,
        held_out_triplets: held.len(),
        class_agreement: state.class_before.zip(class),
        resumed_from,
    })
}

/// Where a run starts: the checkpoint in `out` when every setting but the step count matches
/// (raising --steps extends a finished run), else step 0 with the untrained encoder's
/// figures (`evaluate`).
fn starting_state(
    out: &Path,
    adam: &mut Adam,
    cfg: &TrainConfig,
    evaluate: impl FnOnce() -> Result<(f64, Option<f64>)>,
) -> Result<State> {
    let same = |c: &TrainConfig| {
        TrainConfig {
            steps: cfg.steps,
            ..c.clone()
        } == *cfg
    };
    Ok(match load(out, adam)? {
        Some(s) if same(&s.config) => State {
            config: cfg.clone(),
            ..s
        },
        Some(_) => return Err(TrainError::OtherSettings { out: out.into() }),
        None => {
            let (acc, class) = evaluate()?;
            State {
                step: 0,
                config: cfg.clone(),
                losses: Vec::new(),
                accuracy_before: acc,
                class_before: class,
            }
        }
    })
}

/// One optimiser step on a batch of triplets (anchors, then positives, then negatives, in
/// one forward pass); its loss.
fn step_loss(
    enc: &Encoder,
    adam: &mut Adam,
    loader: &Loader,
    t: &[Triplet],
    step: u64,
    cfg: &TrainConfig,
) -> Result<f64> {
    let ids: Vec<u32> = t
        .iter()
        .map(|x| x.0)
        .chain(t.iter().map(|x| x.1))
        .chain(t.iter().map(|x| x.2))
        .collect();
    let b = loader.batch_of(&ids, step, 0)?;
    let e = enc.forward(&input(&b)?)?;
    let n = cfg.batch;
    let loss = triplet_loss(
        &e.narrow(0, 0, n)?,
        &e.narrow(0, n, n)?,
        &e.narrow(0, 2 * n, n)?,
        cfg.margin,
    )?;
    let l = loss.to_scalar::<f32>()? as f64;
    adam.step(&loss)?;
    Ok(l)
}
