//! Function-preserving widening of a trained [`TubeNet`](super::net::TubeNet) (Net2WiderNet,
//! Chen, Goodfellow and Shlens 2016): a wider network that computes exactly what the trained
//! one does, so that fine-tuning starts from its accuracy with more capacity.
//!
//! Every channel space of width `c` (the output of a convolution, shared by the layers its
//! features are added to) grows to `c'`: new channel `j` copies old channel `g(j)`, with
//! `g(j) = j` for `j < c` and a seeded random old channel otherwise. A layer producing the
//! space copies its rows, `W'[j] = W[g(j)]`, `b'[j] = b[g(j)]`, so the copies carry equal
//! activations (ReLU, pooling and upsampling act per channel); a layer consuming it splits
//! each old input column among the copies, `W'[:, j] = f_j W[:, g(j)]` with positive
//! `f_j` summing to 1 over each group of copies, so `Σ_j W'[:, j] h_j = W[:, i] h_i`. The
//! shares are drawn unequal (`u_j ~ U(0.5, 1.5)`, normalized per group): with equal shares
//! the copies would receive equal gradients and stay copies forever.
//!
//! Spaces (encoder level `l`: `a` = first convolution's output, `b` = second's, the skip):
//! `enc3b` writes into `b2` (its features are added to `enc2b`'s before `dec0`), `dec0` into
//! `b1`, `dec1` into `b0`, `dec2` into its own space read by `head` (and `fine_proj`).

use super::error::LearnedError;
use super::model::{sorted_vars, LearnedModel};
use candle_core::{Device, Tensor};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::collections::HashMap;

/// The channel map of one space: the old channel each new one copies and its share.
struct ChannelMap {
    source: Vec<usize>,
    share: Vec<f32>,
}

impl ChannelMap {
    fn new(old: usize, new: usize, rng: &mut ChaCha8Rng) -> Self {
        let source: Vec<usize> = (0..new).map(|j| if j < old { j } else { rng.random_range(0..old) }).collect();
        let mut share: Vec<f32> = (0..new).map(|_| rng.random_range(0.5f32..1.5)).collect();
        let mut total = vec![0f32; old];
        for (j, &i) in source.iter().enumerate() {
            total[i] += share[j];
        }
        for (j, &i) in source.iter().enumerate() {
            share[j] /= total[i];
        }
        ChannelMap { source, share }
    }
}

/// `(parameter prefix, input space, output space)`; `None`: a space that keeps its width.
const LAYERS: [(&str, Option<&str>, Option<&str>); 13] = [
    ("enc0a", None, Some("a0")),
    ("enc0b", Some("a0"), Some("b0")),
    ("enc1a", Some("b0"), Some("a1")),
    ("enc1b", Some("a1"), Some("b1")),
    ("enc2a", Some("b1"), Some("a2")),
    ("enc2b", Some("a2"), Some("b2")),
    ("enc3a", Some("b2"), Some("a3")),
    ("enc3b", Some("a3"), Some("b2")),
    ("dec0", Some("b2"), Some("b1")),
    ("dec1", Some("b1"), Some("b0")),
    ("dec2", Some("b0"), Some("d2")),
    ("head", Some("d2"), None),
    ("fine_proj", Some("d2"), None),
];

/// Every widened space and its width as a multiple of the base width (`w`, `2w` or `4w`), in
/// the order their channel maps are drawn.
const SPACES: [(&str, usize); 8] = [("a0", 1), ("b0", 1), ("a1", 2), ("b1", 2), ("a2", 4), ("b2", 4), ("a3", 4), ("d2", 1)];

impl LearnedModel {
    /// This model widened to base width `width` (at least its own), computing the same
    /// outputs (up to float rounding); `seed` draws the copied channels and their shares.
    /// Metadata (preprocessing, steps) is kept, with the widening noted.
    pub fn widened(&self, width: usize, seed: u64) -> Result<LearnedModel, LearnedError> {
        let w = self.meta.net.width;
        if width < w {
            return Err(LearnedError::Invalid(format!("widening: the new width {width} is below the model's {w}")));
        }
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let maps: HashMap<&str, ChannelMap> = SPACES.iter().map(|&(s, k)| (s, ChannelMap::new(k * w, k * width, &mut rng))).collect();
        let mut out = LearnedModel::with_fine_mask(self.meta.preprocess, width, self.meta.net.fine_mask, seed)?;
        let theirs: HashMap<String, candle_core::Var> = sorted_vars(&self.varmap).into_iter().collect();
        for (name, var) in sorted_vars(&out.varmap) {
            let old = theirs.get(&name).ok_or_else(|| LearnedError::Invalid(format!("widening: the model has no tensor {name}")))?;
            let (prefix, kind) = name.rsplit_once('.').unwrap_or((name.as_str(), ""));
            let layer = LAYERS.iter().find(|(p, _, _)| *p == prefix);
            let new_dims = var.dims().to_vec();
            let vals: Vec<f32> = old.as_tensor().flatten_all()?.to_vec1()?;
            let widened = match layer {
                None => {
                    if old.dims() != new_dims.as_slice() {
                        return Err(LearnedError::Invalid(format!("widening: {name} is {:?}, expected {new_dims:?}", old.dims())));
                    }
                    vals
                }
                Some(&(_, input, output)) => {
                    let out_map = output.map(|s| &maps[s]);
                    if kind == "bias" {
                        match out_map {
                            Some(m) => m.source.iter().map(|&i| vals[i]).collect(),
                            None => vals,
                        }
                    } else {
                        let (_, ci, kh, kw) = old.as_tensor().dims4()?;
                        let k2 = kh * kw;
                        let in_map = input.map(|s| &maps[s]);
                        let (nco, nci) = (new_dims[0], new_dims[1]);
                        let mut v = vec![0f32; nco * nci * k2];
                        for o in 0..nco {
                            let so = out_map.map_or(o, |m| m.source[o]);
                            for i in 0..nci {
                                let (si, f) = in_map.map_or((i, 1.0), |m| (m.source[i], m.share[i]));
                                for t in 0..k2 {
                                    v[(o * nci + i) * k2 + t] = f * vals[(so * ci + si) * k2 + t];
                                }
                            }
                        }
                        v
                    }
                }
            };
            var.set(&Tensor::from_vec(widened, new_dims, &Device::Cpu)?)?;
        }
        out.meta.steps = self.meta.steps;
        out.meta.notes = format!("widened from width {w} to {width} (seed {seed}): {}", self.meta.notes);
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learned::Preprocess;

    fn outputs(m: &LearnedModel, x: &Tensor) -> Vec<f32> {
        m.forward(x).unwrap().coarse.flatten_all().unwrap().to_vec1().unwrap()
    }

    #[test]
    fn a_widened_model_computes_what_the_narrow_one_does_and_its_copies_differ() {
        // A random (untrained) narrow model: He-normal weights; biases made non-zero so that
        // copied biases are exercised too.
        let narrow = LearnedModel::new(Preprocess::GrayNorm, 4, 3).unwrap();
        for (name, var) in sorted_vars(&narrow.varmap) {
            if name.ends_with(".bias") {
                let n = var.dims().iter().product::<usize>();
                let v: Vec<f32> = (0..n).map(|k| 0.05 * ((k * 7 % 11) as f32 - 5.0)).collect();
                var.set(&Tensor::from_vec(v, var.dims(), &Device::Cpu).unwrap()).unwrap();
            }
        }
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let x: Vec<f32> = (0..64 * 96).map(|_| rng.random_range(-2.0f32..2.0)).collect();
        let x = Tensor::from_vec(x, (1, 1, 64, 96), &Device::Cpu).unwrap();
        let wide = narrow.widened(7, 5).unwrap();
        assert_eq!(wide.meta.net.width, 7);
        let (a, b) = (outputs(&narrow, &x), outputs(&wide, &x));
        assert_eq!(a.len(), b.len());
        let scale = a.iter().fold(0f32, |m, v| m.max(v.abs()));
        let worst = a.iter().zip(&b).fold(0f32, |m, (p, q)| m.max((p - q).abs()));
        assert!(scale > 0.1 && worst < 1e-4 * scale.max(1.0), "max difference {worst} (outputs up to {scale})");
        // The split shares differ within a group of copies, so the head's columns for
        // copies of one channel are not equal.
        let head: Vec<f32> = sorted_vars(&wide.varmap).into_iter().find(|(n, _)| n == "head.weight").unwrap().1.as_tensor().flatten_all().unwrap().to_vec1().unwrap();
        let cols: Vec<f32> = (0..7).map(|i| head[i]).collect();
        let distinct = cols.iter().filter(|&&c| cols.iter().filter(|&&d| (c - d).abs() < 1e-9).count() == 1).count();
        assert!(distinct >= 6, "head row 0 across the 7 channels: {cols:?}");
        assert!(narrow.widened(3, 0).is_err());
    }
}
