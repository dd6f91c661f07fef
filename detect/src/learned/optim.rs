//! AdamW with a state that can be saved and restored, so a resumed run continues exactly.
//!
//! For each parameter `θ` with gradient `g` at step `t` (counted from 1):
//! `m ← β₁ m + (1 - β₁) g`, `v ← β₂ v + (1 - β₂) g²`,
//! `θ ← θ (1 - η λ) - η m̂ / (√v̂ + ε)` with `m̂ = m / (1 - β₁ᵗ)`, `v̂ = v / (1 - β₂ᵗ)`,
//! learning rate `η`, weight decay `λ`, `β₁ = 0.9`, `β₂ = 0.999`, `ε = 1e-8`.
//!
//! State file (safetensors): tensors `m.<param>` and `v.<param>` for every parameter, metadata
//! `format = "tubeloc-learned-optimizer"` and `t` (steps taken).

use super::error::LearnedError;
use super::model::{sorted_vars, LearnedModel};
use candle_core::backprop::GradStore;
use candle_core::{Device, Tensor, Var};
use std::collections::HashMap;
use std::path::Path;

const FORMAT: &str = "tubeloc-learned-optimizer";

/// The optimizer and its moments.
pub struct AdamW {
    params: Vec<(String, Var)>,
    m: Vec<Tensor>,
    v: Vec<Tensor>,
    /// Steps taken.
    pub t: u64,
    /// Learning rate `η`.
    pub lr: f64,
    /// Weight decay `λ`.
    pub weight_decay: f64,
}

impl AdamW {
    /// Fresh state (zero moments) for every parameter of `model`.
    pub fn new(model: &LearnedModel, lr: f64, weight_decay: f64) -> Result<Self, LearnedError> {
        let params = sorted_vars(&model.varmap);
        let zeros = |p: &Var| p.as_tensor().zeros_like();
        let m = params.iter().map(|(_, p)| zeros(p)).collect::<Result<Vec<_>, _>>()?;
        let v = params.iter().map(|(_, p)| zeros(p)).collect::<Result<Vec<_>, _>>()?;
        Ok(AdamW { params, m, v, t: 0, lr, weight_decay })
    }

    /// One update from the gradients of a backward pass (parameters without a gradient keep
    /// their value and moments).
    pub fn step(&mut self, grads: &GradStore) -> Result<(), LearnedError> {
        let (b1, b2, eps) = (0.9f64, 0.999f64, 1e-8f64);
        self.t += 1;
        let c1 = 1.0 - b1.powi(self.t as i32);
        let c2 = 1.0 - b2.powi(self.t as i32);
        for (i, (_, p)) in self.params.iter().enumerate() {
            let Some(g) = grads.get(p.as_tensor()) else { continue };
            let m = ((&self.m[i] * b1)? + (g * (1.0 - b1))?)?;
            let v = ((&self.v[i] * b2)? + (g.sqr()? * (1.0 - b2))?)?;
            let upd = ((&m / c1)? / ((&v / c2)?.sqrt()? + eps)?)?;
            let theta = ((p.as_tensor() * (1.0 - self.lr * self.weight_decay))? - (upd * self.lr)?)?;
            p.set(&theta)?;
            self.m[i] = m;
            self.v[i] = v;
        }
        Ok(())
    }

    /// Writes the state atomically to `path`.
    pub fn save(&self, path: &Path) -> Result<(), LearnedError> {
        let mut blobs = Vec::new();
        for (i, (name, p)) in self.params.iter().enumerate() {
            for (tag, t) in [("m", &self.m[i]), ("v", &self.v[i])] {
                let vals: Vec<f32> = t.flatten_all()?.to_vec1()?;
                blobs.push((format!("{tag}.{name}"), p.dims().to_vec(), vals.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>()));
            }
        }
        let views =
            blobs.iter().map(|(n, s, b)| Ok((n.clone(), safetensors::tensor::TensorView::new(safetensors::Dtype::F32, s.clone(), b)?))).collect::<Result<Vec<_>, safetensors::SafeTensorError>>().map_err(|e| LearnedError::Invalid(e.to_string()))?;
        let md = HashMap::from([("format".to_string(), FORMAT.to_string()), ("t".to_string(), self.t.to_string())]);
        let bytes = safetensors::serialize(views, Some(md)).map_err(|e| LearnedError::Invalid(e.to_string()))?;
        tubeloc_core::files::write_atomic(path, &bytes).map_err(|e| LearnedError::Io { path: path.to_path_buf(), error: std::io::Error::other(e.to_string()) })
    }

    /// Restores the state written by [`AdamW::save`]; every parameter's moments must be
    /// present with the parameter's shape.
    pub fn load_state(&mut self, path: &Path) -> Result<(), LearnedError> {
        let bad = |m: String| LearnedError::bad_model(path, m);
        let bytes = std::fs::read(path).map_err(|e| LearnedError::Io { path: path.to_path_buf(), error: e })?;
        let st = safetensors::SafeTensors::deserialize(&bytes).map_err(|e| bad(format!("not a safetensors file ({e})")))?;
        let (_, header) = safetensors::SafeTensors::read_metadata(&bytes).map_err(|e| bad(e.to_string()))?;
        let md = header.metadata().clone().unwrap_or_default();
        if md.get("format").map(String::as_str) != Some(FORMAT) {
            return Err(bad("not a tubeloc optimizer state".into()));
        }
        let t: u64 = md.get("t").and_then(|s| s.parse().ok()).ok_or_else(|| bad("missing step count".into()))?;
        for (i, (name, p)) in self.params.iter().enumerate() {
            for (tag, slot) in [("m", &mut self.m[i]), ("v", &mut self.v[i])] {
                let key = format!("{tag}.{name}");
                let view = st.tensor(&key).map_err(|_| bad(format!("missing {key}")))?;
                if view.shape() != p.dims() || view.dtype() != safetensors::Dtype::F32 {
                    return Err(bad(format!("{key} has shape {:?}, the model's is {:?}", view.shape(), p.dims())));
                }
                let vals: Vec<f32> = view.data().chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
                *slot = Tensor::from_vec(vals, view.shape(), &Device::Cpu)?;
            }
        }
        self.t = t;
        Ok(())
    }
}
