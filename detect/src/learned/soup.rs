//! Weight averaging of fine-tuned models (a "model soup", Wortsman et al. 2022).
//!
//! Models fine-tuned from one warm start with different seeds lie in one basin of the loss;
//! the uniform average of their weights `θ = (1/K) Σ_k θ_k` is a single network (no extra
//! inference time) that is often better than any one of them. The network has no batch
//! statistics, so averaging the convolution weights and biases is the whole model.

use super::error::LearnedError;
use super::model::{sorted_vars, LearnedModel};
use candle_core::Tensor;

/// The uniform weight average of `models`, which must share the architecture
/// ([`super::NetConfig`]) and the preprocessing. The result's metadata is the first model's,
/// with `steps` the largest of them and `notes` naming the number averaged.
pub fn weight_average(models: &[LearnedModel]) -> Result<LearnedModel, LearnedError> {
    let first = models.first().ok_or_else(|| LearnedError::Invalid("weight average of no models".into()))?;
    for (k, m) in models.iter().enumerate().skip(1) {
        if m.meta.net != first.meta.net || m.meta.preprocess != first.meta.preprocess {
            return Err(LearnedError::Invalid(format!(
                "weight average: model {} is {:?} with {:?} preprocessing, model 1 is {:?} with {:?}; all must share the architecture and preprocessing",
                k + 1,
                m.meta.net,
                m.meta.preprocess,
                first.meta.net,
                first.meta.preprocess
            )));
        }
    }
    let mut out = LearnedModel::with_fine_mask(first.meta.preprocess, first.meta.net.width, first.meta.net.fine_mask, 0)?;
    let per_model: Vec<Vec<(String, candle_core::Var)>> = models.iter().map(|m| sorted_vars(&m.varmap)).collect();
    for (i, (name, var)) in sorted_vars(&out.varmap).into_iter().enumerate() {
        let mut sum: Option<Tensor> = None;
        for vars in &per_model {
            let (n, v) = &vars[i];
            debug_assert_eq!(n, &name, "same architecture, same parameter names");
            sum = Some(match sum {
                None => v.as_tensor().clone(),
                Some(s) => (s + v.as_tensor())?,
            });
        }
        let mean = (sum.expect("at least one model") / models.len() as f64)?;
        var.set(&mean)?;
    }
    out.meta = first.meta.clone();
    out.meta.steps = models.iter().map(|m| m.meta.steps).max().unwrap_or(0);
    out.meta.notes = format!("uniform weight average of {} models; first: {}", models.len(), first.meta.notes);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learned::Preprocess;

    fn weights(m: &LearnedModel) -> Vec<f32> {
        sorted_vars(&m.varmap).iter().flat_map(|(_, v)| v.as_tensor().flatten_all().unwrap().to_vec1::<f32>().unwrap()).collect()
    }

    #[test]
    fn average_is_the_elementwise_mean_and_predicts_like_a_model() {
        let a = LearnedModel::new(Preprocess::Rgb, 4, 1).unwrap();
        let b = LearnedModel::new(Preprocess::Rgb, 4, 2).unwrap();
        let avg = weight_average(&[a, b]).unwrap();
        let (a, b) = (LearnedModel::new(Preprocess::Rgb, 4, 1).unwrap(), LearnedModel::new(Preprocess::Rgb, 4, 2).unwrap());
        let (wa, wb, wm) = (weights(&a), weights(&b), weights(&avg));
        assert_eq!(wm.len(), wa.len());
        assert!(wa.iter().zip(&wb).zip(&wm).all(|((x, y), m)| (0.5 * (x + y) - m).abs() <= 1e-6 * (1.0 + m.abs())));
        assert!(wa != wb);
        // The average of a model with itself is the model: same outputs.
        let self_avg = weight_average(&[LearnedModel::new(Preprocess::Rgb, 4, 1).unwrap(), LearnedModel::new(Preprocess::Rgb, 4, 1).unwrap()]).unwrap();
        let input: Vec<f32> = (0..3 * 64 * 64).map(|i| ((i * 37 % 101) as f32 / 101.0 - 0.5) * 4.0).collect();
        assert_eq!(self_avg.predict(&input, 64, 64).unwrap().planes, a.predict(&input, 64, 64).unwrap().planes);
        // And it survives a save / load round trip.
        let back = LearnedModel::from_bytes(&avg.to_bytes().unwrap(), std::path::Path::new("soup.safetensors")).unwrap();
        assert_eq!(weights(&back), wm);
        assert!(back.meta.notes.starts_with("uniform weight average of 2 models"));
    }

    #[test]
    fn mismatched_or_missing_models_are_refused() {
        let a = LearnedModel::new(Preprocess::Rgb, 4, 1).unwrap();
        let b = LearnedModel::new(Preprocess::Rgb, 8, 1).unwrap();
        let e = weight_average(&[a, b]).err().expect("widths differ").to_string();
        assert!(e.contains("model 2") && e.contains("architecture"), "{e}");
        let e = weight_average(&[]).err().expect("no models").to_string();
        assert!(e.contains("no models"), "{e}");
    }
}
