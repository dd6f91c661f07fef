//! Training: batches of augmented crops, a multi-task loss, AdamW with warm-up and cosine decay.
//!
//! Loss for raw outputs `o` and targets `t` (see [`super::targets`]), with `b(x, y) =
//! max(x, 0) - x y + ln(1 + e^{-|x|})` the binary cross-entropy with logits:
//!
//! `L = mean((1 + 4 t₀) b(o₀, t₀)) + Σ (1 + 20 t₁) b(o₁, t₁) / Σ (1 + 20 t₁)
//!      + Σ w (|o₂ - t₂| + |o₃ - t₃|) / (Σ w + 1) + Σ w |o₄ - t₄| / (Σ w + 1)`
//!
//! where `w` marks instance cells. A model with the full-resolution mask branch adds
//! `mean(b(f, m))` for its logits `f` and the binary tube mask `m` of the crop (unweighted, so
//! that logit 0 is the calibrated threshold).
//! Learning rate: linear warm-up over the first
//! `warmup` steps, then cosine decay to 5% of `lr` at `total_steps`.
//!
//! Checkpoints ([`Trainer::save_checkpoint`]) hold the weights with the step count and, beside
//! them (`<file>.opt`), the AdamW moments ([`super::optim::AdamW`]); batches are drawn from
//! `(seed, step)`, so a run resumed from a checkpoint continues exactly as it would have.

use super::augment::{sample_crop, AugmentConfig, TrainImage};
use super::error::LearnedError;
use super::model::LearnedModel;
use super::net::{NetOutput, HEADS, STRIDE};
use super::optim::AdamW;
use super::targets::make_targets;
use candle_core::{Device, Tensor};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// Where the optimizer state of checkpoint `path` lives: `<path>.opt`.
pub fn opt_path(path: &Path) -> PathBuf {
    PathBuf::from(format!("{}.opt", path.display()))
}

/// Optimizer and batch settings.
#[derive(Clone, Copy, Debug)]
pub struct TrainConfig {
    /// Crops per step.
    pub batch: usize,
    /// Peak learning rate.
    pub lr: f64,
    /// AdamW weight decay.
    pub weight_decay: f64,
    /// Warm-up steps.
    pub warmup: u64,
    /// Total steps of the schedule.
    pub total_steps: u64,
    /// Seed of the crop sampler.
    pub seed: u64,
    /// Augmentation.
    pub augment: AugmentConfig,
}

impl Default for TrainConfig {
    fn default() -> Self {
        TrainConfig { batch: 8, lr: 2e-3, weight_decay: 1e-4, warmup: 100, total_steps: 3000, seed: 0, augment: AugmentConfig::default() }
    }
}

/// A batch ready for the network.
pub struct Batch {
    /// `(B, C, S, S)` input.
    pub input: Tensor,
    /// `(B, HEADS, S/4, S/4)` targets.
    pub target: Tensor,
    /// `(B, 1, S/4, S/4)` instance-cell weights.
    pub weight: Tensor,
    /// `(B, 1, S, S)` binary tube mask (1 on any instance's pixels).
    pub mask: Tensor,
}

/// Builds a batch of `n` crops, crop `b` drawn with `ChaCha8Rng::seed_from_u64(seed ^ step·1000003 ^ b)`
/// from image `rng % images.len()` (deterministic, parallel over crops).
pub fn make_batch(images: &[TrainImage], aug: &AugmentConfig, n: usize, seed: u64, step: u64) -> Result<Batch, LearnedError> {
    if images.is_empty() {
        return Err(LearnedError::Invalid("no training images".into()));
    }
    if aug.crop == 0 || aug.crop % 32 != 0 {
        return Err(LearnedError::Invalid(format!("crop size {} must be a positive multiple of 32", aug.crop)));
    }
    let s = aug.crop;
    let o = s / STRIDE;
    let ch = images[0].channels();
    let crops: Vec<_> = (0..n)
        .into_par_iter()
        .map(|b| {
            let mut rng = ChaCha8Rng::seed_from_u64(seed ^ step.wrapping_mul(1_000_003) ^ ((b as u64) << 48));
            let img = &images[rand::Rng::random_range(&mut rng, 0..images.len())];
            let (input, labels) = sample_crop(img, aug, &mut rng);
            let t = make_targets(&labels, s);
            let m: Vec<f32> = labels.iter().map(|&l| (l != 0) as u8 as f32).collect();
            (input, t, m)
        })
        .collect();
    let mut input = Vec::with_capacity(n * ch * s * s);
    let mut target = Vec::with_capacity(n * HEADS * o * o);
    let mut weight = Vec::with_capacity(n * o * o);
    let mut mask = Vec::with_capacity(n * s * s);
    for (i, t, m) in crops {
        input.extend_from_slice(&i);
        target.extend_from_slice(&t.values);
        weight.extend_from_slice(&t.weight);
        mask.extend_from_slice(&m);
    }
    Ok(Batch {
        input: Tensor::from_vec(input, (n, ch, s, s), &Device::Cpu)?,
        target: Tensor::from_vec(target, (n, HEADS, o, o), &Device::Cpu)?,
        weight: Tensor::from_vec(weight, (n, 1, o, o), &Device::Cpu)?,
        mask: Tensor::from_vec(mask, (n, 1, s, s), &Device::Cpu)?,
    })
}

fn bce_logits(x: &Tensor, t: &Tensor) -> candle_core::Result<Tensor> {
    let a = x.relu()?;
    let b = (x * t)?;
    let c = (x.abs()?.neg()?.exp()? + 1.0)?.log()?;
    (a - b)? + c
}

/// The multi-task loss of the module doc (a scalar tensor).
pub fn loss(net_out: &NetOutput, batch: &Batch) -> Result<Tensor, LearnedError> {
    let out = &net_out.coarse;
    let o = |k: usize, len: usize| out.narrow(1, k, len);
    let t = |k: usize, len: usize| batch.target.narrow(1, k, len);
    let (o0, t0) = (o(0, 1)?, t(0, 1)?);
    let l_fg = (bce_logits(&o0, &t0)? * (t0.affine(4.0, 1.0)?))?.mean_all()?;
    let (o1, t1) = (o(1, 1)?, t(1, 1)?);
    let wh = t1.affine(20.0, 1.0)?;
    let l_heat = ((bce_logits(&o1, &t1)? * &wh)?.sum_all()? / wh.sum_all()?.to_scalar::<f32>()? as f64)?;
    let wsum = batch.weight.sum_all()?.to_scalar::<f32>()? as f64 + 1.0;
    let l_dir = ((o(2, 2)? - t(2, 2)?)?.abs()?.broadcast_mul(&batch.weight)?.sum_all()? / wsum)?;
    let l_len = ((o(4, 1)? - t(4, 1)?)?.abs()?.broadcast_mul(&batch.weight)?.sum_all()? / wsum)?;
    let total = (((l_fg + l_heat)? + l_dir)? + l_len)?;
    Ok(match &net_out.fine {
        Some(f) => (total + bce_logits(f, &batch.mask)?.mean_all()?)?,
        None => total,
    })
}

/// Trains a [`LearnedModel`] in place.
pub struct Trainer {
    /// The model being trained (its `meta.steps` counts steps).
    pub model: LearnedModel,
    /// Settings.
    pub config: TrainConfig,
    opt: AdamW,
}

impl Trainer {
    /// Wraps a model (fresh or resumed) for training.
    pub fn new(model: LearnedModel, config: TrainConfig) -> Result<Self, LearnedError> {
        let opt = AdamW::new(&model, config.lr, config.weight_decay)?;
        Ok(Trainer { model, config, opt })
    }

    /// Resumes from a checkpoint written by [`Trainer::save_checkpoint`]: the weights and step
    /// count from `path`, the optimizer moments from `<path>.opt` (a plain model file without
    /// one starts with fresh moments, which is reported as `false`).
    pub fn resume(path: &Path, config: TrainConfig) -> Result<(Self, bool), LearnedError> {
        let model = LearnedModel::load(path)?;
        let mut t = Trainer::new(model, config)?;
        let opt = opt_path(path);
        let found = opt.exists();
        if found {
            t.opt.load_state(&opt)?;
            if t.opt.t != t.model.meta.steps {
                return Err(LearnedError::bad_model(&opt, format!("optimizer state is at step {} but the weights at step {}", t.opt.t, t.model.meta.steps)));
            }
        }
        Ok((t, found))
    }

    /// Writes the weights to `path` and the optimizer state to `<path>.opt` (both atomically).
    pub fn save_checkpoint(&self, path: &Path) -> Result<(), LearnedError> {
        self.opt.save(&opt_path(path))?;
        self.model.save(path)
    }

    /// Learning rate at step `k` (warm-up then cosine, see the module doc).
    pub fn learning_rate(&self, k: u64) -> f64 {
        let c = &self.config;
        if k < c.warmup {
            return c.lr * (k + 1) as f64 / c.warmup as f64;
        }
        let p = ((k - c.warmup) as f64 / (c.total_steps.saturating_sub(c.warmup)).max(1) as f64).min(1.0);
        c.lr * (0.05 + 0.95 * 0.5 * (1.0 + (std::f64::consts::PI * p).cos()))
    }

    /// One optimizer step on a fresh batch; returns the batch loss before the step.
    pub fn step(&mut self, images: &[TrainImage]) -> Result<f32, LearnedError> {
        let k = self.model.meta.steps;
        let batch = make_batch(images, &self.config.augment, self.config.batch, self.config.seed, k)?;
        self.opt.lr = self.learning_rate(k);
        let out = self.model.forward(&batch.input)?;
        let l = loss(&out, &batch)?;
        let grads = l.backward()?;
        self.opt.step(&grads)?;
        self.model.meta.steps += 1;
        Ok(l.to_scalar::<f32>()?)
    }

    /// Loss of the current model on a batch (no update).
    pub fn eval_loss(&self, batch: &Batch) -> Result<f32, LearnedError> {
        let out = self.model.forward(&batch.input)?;
        Ok(loss(&out, batch)?.to_scalar::<f32>()?)
    }
}
