//! Fitting [`PoseEvidence`], the probability that a refined pose is a tube from its score and
//! its fit's evidence, by logistic regression.
//!
//! Each feature is standardized, `z_i = (f_i - μ_i) / s_i` with the fitting data's mean and
//! standard deviation, and `(w, b)` minimize the mean negative log-likelihood plus a ridge on
//! the weights, `L = -(1/n) Σ [y ln p + (1 - y) ln(1 - p)] + (λ/2) |w|²`, λ = 1e-3, by Newton's
//! method (the loss is convex, so the minimum is unique and reached in a few steps).

use nalgebra::{SMatrix, SVector};
use tubeloc_core::pose_evidence::{EVIDENCE_FEATURES, EVIDENCE_FEATURE_NAMES, MIN_EVIDENCE_SCALE};
use tubeloc_core::{CocoDataset, CocoResult, PoseEvidence, Rle, TubeAxisPose};

const N: usize = EVIDENCE_FEATURES + 1;

/// Ridge λ on the standardized weights (not the offset).
pub const RIDGE: f64 = 1e-3;

/// Fits a [`PoseEvidence`] to `(features, is_tube)` samples ([`PoseEvidence::features`]).
/// Errors when there are no positives or no negatives (the fit is then degenerate).
pub fn fit_pose_evidence(samples: &[([f64; EVIDENCE_FEATURES], bool)], fitted_on: &str) -> Result<PoseEvidence, String> {
    let pos = samples.iter().filter(|s| s.1).count();
    if pos == 0 || pos == samples.len() {
        return Err(format!("{} samples, {pos} of them tubes: the fit needs tubes and non-tubes", samples.len()));
    }
    let n = samples.len() as f64;
    let mut mean = [0.0; EVIDENCE_FEATURES];
    let mut scale = [0.0; EVIDENCE_FEATURES];
    for i in 0..EVIDENCE_FEATURES {
        mean[i] = samples.iter().map(|s| s.0[i]).sum::<f64>() / n;
        let var = samples.iter().map(|s| (s.0[i] - mean[i]).powi(2)).sum::<f64>() / n;
        // A constant feature carries nothing: scale 1 keeps it at z = 0 (below the smallest
        // scale a model file may carry, the feature counts as constant).
        scale[i] = if var.sqrt() >= MIN_EVIDENCE_SCALE { var.sqrt() } else { 1.0 };
    }
    let rows: Vec<(SVector<f64, N>, f64)> = samples
        .iter()
        .map(|(f, y)| {
            let mut z = SVector::<f64, N>::zeros();
            for i in 0..EVIDENCE_FEATURES {
                z[i] = (f[i] - mean[i]) / scale[i];
            }
            z[EVIDENCE_FEATURES] = 1.0;
            (z, if *y { 1.0 } else { 0.0 })
        })
        .collect();
    let mut ridge = SMatrix::<f64, N, N>::identity() * RIDGE;
    ridge[(EVIDENCE_FEATURES, EVIDENCE_FEATURES)] = 0.0;
    let mut w = SVector::<f64, N>::zeros();
    for _ in 0..100 {
        let mut g = ridge * w;
        let mut h = ridge;
        for (z, y) in &rows {
            let p = 1.0 / (1.0 + (-w.dot(z)).exp());
            g += z * ((p - y) / n);
            h += z * z.transpose() * ((p * (1.0 - p)).max(1e-12) / n);
        }
        let Some(step) = h.lu().solve(&g) else { return Err("singular Hessian: the features are degenerate".into()) };
        w -= step;
        if step.amax() < 1e-10 {
            break;
        }
    }
    let mut weights = [0.0; EVIDENCE_FEATURES];
    weights.copy_from_slice(&w.as_slice()[..EVIDENCE_FEATURES]);
    let model = PoseEvidence { features: EVIDENCE_FEATURE_NAMES.iter().map(|s| s.to_string()).collect(), mean, scale, weights, bias: w[EVIDENCE_FEATURES], fitted_on: fitted_on.to_string() };
    model.validate()?;
    Ok(model)
}

/// Whether each detection is a tube: its mask overlaps a (non-crowd) ground-truth mask of its
/// image at IoU >= 0.5. Not one-to-one: a second detection of the same tube is a tube too
/// (the label says what the pixels are, not how a ranking is scored). Errors name the
/// detection's index and the problem (no mask, unknown image, a mask of another size).
pub fn tube_labels(gt: &CocoDataset, dt: &[CocoResult]) -> Result<Vec<bool>, String> {
    let sizes: std::collections::HashMap<u64, (u32, u32)> = gt.images.iter().map(|i| (i.id, (i.height, i.width))).collect();
    let mut truths: std::collections::HashMap<u64, Vec<Rle>> = std::collections::HashMap::new();
    for (k, a) in gt.annotations.iter().enumerate().filter(|(_, a)| a.iscrowd == 0) {
        let (h, w) = sizes.get(&a.image_id).copied().ok_or_else(|| format!("annotation {k} is on unknown image {}", a.image_id))?;
        let seg = a.segmentation.as_ref().ok_or_else(|| format!("annotation {k} has no segmentation"))?;
        truths.entry(a.image_id).or_default().push(seg.to_rle(h, w).map_err(|e| format!("annotation {k}: {e}"))?);
    }
    dt.iter()
        .enumerate()
        .map(|(k, d)| {
            let (h, w) = sizes.get(&d.image_id).copied().ok_or_else(|| format!("detection {k} is on image {}, which the ground truth does not hold", d.image_id))?;
            let seg = d.segmentation.as_ref().ok_or_else(|| format!("detection {k} has no segmentation (mask)"))?;
            let rle = seg.to_rle(h, w).map_err(|e| format!("detection {k}: {e}"))?;
            let Some(t) = truths.get(&d.image_id) else { return Ok(false) };
            Ok(Rle::iou(std::slice::from_ref(&rle), t, &vec![false; t.len()]).iter().any(|&v| v >= 0.5))
        })
        .collect()
}

/// `results` each scored by `model`'s probability of its refined pose (`poses`, one per result
/// in order): what `tubeloc refine --pose-evidence` writes, for ranking by the evidence.
pub fn scored_by_evidence(results: &[CocoResult], poses: &[TubeAxisPose], model: &PoseEvidence) -> Vec<CocoResult> {
    results.iter().zip(poses).map(|(d, p)| CocoResult { score: model.probability(p), ..d.clone() }).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn recovers_the_weights_of_a_known_model() {
        // Samples drawn from a known logistic model on standardized features.
        let truth = [1.5, 0.0, -2.0, 0.8, 0.5];
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let samples: Vec<([f64; EVIDENCE_FEATURES], bool)> = (0..20000)
            .map(|_| {
                let f: [f64; EVIDENCE_FEATURES] = std::array::from_fn(|i| 3.0 + i as f64 + 2.0 * (rng.random::<f64>() * 2.0 - 1.0) * 3f64.sqrt());
                let x = 0.3 + (0..EVIDENCE_FEATURES).map(|i| truth[i] * (f[i] - 3.0 - i as f64) / 2.0).sum::<f64>();
                (f, rng.random::<f64>() < 1.0 / (1.0 + (-x).exp()))
            })
            .collect();
        let m = fit_pose_evidence(&samples, "synthetic").unwrap();
        for (i, w) in truth.iter().enumerate() {
            assert!((m.mean[i] - 3.0 - i as f64).abs() < 0.1, "mean {i}: {}", m.mean[i]);
            assert!((m.scale[i] - 2.0).abs() < 0.1, "scale {i}: {}", m.scale[i]);
            assert!((m.weights[i] - w).abs() < 0.1, "weight {i}: {} vs {w}", m.weights[i]);
        }
        assert!((m.bias - 0.3).abs() < 0.1, "bias {}", m.bias);
        assert_eq!(m.fitted_on, "synthetic");
    }

    #[test]
    fn a_detection_is_a_tube_where_its_mask_overlaps_a_true_one_at_iou_half() {
        let gt: CocoDataset = serde_json::from_value(serde_json::json!({
            "images": [{"id": 1, "width": 20, "height": 20, "file_name": "a.png"}, {"id": 2, "width": 20, "height": 20, "file_name": "b.png"}],
            "annotations": [{"id": 1, "image_id": 1, "category_id": 1, "area": 40.0, "bbox": [2, 2, 10, 4], "segmentation": [[2, 2, 12, 2, 12, 6, 2, 6]]}],
            "categories": [{"id": 1, "name": "tube"}]
        }))
        .unwrap();
        let det = |image: u64, poly: [f64; 8]| -> CocoResult { serde_json::from_value(serde_json::json!({"image_id": image, "category_id": 1, "score": 0.5, "segmentation": [poly]})).unwrap() };
        let dt = vec![
            det(1, [2.0, 2.0, 12.0, 2.0, 12.0, 6.0, 2.0, 6.0]), // the tube itself
            det(1, [2.0, 2.0, 8.0, 2.0, 8.0, 6.0, 2.0, 6.0]),   // its left 60 %: IoU 0.6
            det(1, [2.0, 2.0, 5.0, 2.0, 5.0, 6.0, 2.0, 6.0]),   // its left 30 %
            det(2, [2.0, 2.0, 12.0, 2.0, 12.0, 6.0, 2.0, 6.0]), // an image without a tube
        ];
        assert_eq!(tube_labels(&gt, &dt).unwrap(), vec![true, true, false, false]);
        let err = tube_labels(&gt, &[det(9, [0.0; 8])]).unwrap_err();
        assert!(err.contains("detection 0 is on image 9"), "{err}");
    }

    #[test]
    fn a_fit_without_both_outcomes_is_refused() {
        let s = vec![([0.0; EVIDENCE_FEATURES], true); 3];
        assert!(fit_pose_evidence(&s, "").unwrap_err().contains("3 samples, 3 of them tubes"));
        assert!(fit_pose_evidence(&[], "").is_err());
    }
}
