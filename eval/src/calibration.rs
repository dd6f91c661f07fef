//! Calibrating detector scores into probabilities of a tube, and checking the calibration.
//!
//! [`fit_platt`] fits `P = σ(a · logit(s) + b)` ([`tubeloc_core::ScoreCalibration`]) to
//! detections labelled true or false positive at IoU 0.5 by maximum likelihood (Newton's
//! method with a small ridge `λ (a² + b²) / 2`, λ = 1e-3). [`choose_threshold`] picks the
//! lowest probability whose kept detections reach a target precision. [`reliability`] bins
//! predicted probabilities against observed frequencies (the reliability diagram) and gives
//! the expected calibration error `ECE = Σ_b (n_b / N) |mean p_b - freq_b|`.

use tubeloc_core::ScoreCalibration;

/// Fits `a`, `b` of Platt scaling to `(score, is_tube)` pairs. Returns `(a, b)`; with no
/// positives or no negatives the fit is degenerate and the identity `(1, 0)` is returned.
pub fn fit_platt(samples: &[(f64, bool)]) -> (f64, f64) {
    let pos = samples.iter().filter(|s| s.1).count();
    if pos == 0 || pos == samples.len() {
        return (1.0, 0.0);
    }
    let lambda = 1e-3;
    let (mut a, mut b) = (1.0f64, 0.0f64);
    for _ in 0..100 {
        // Gradient and Hessian of the negative log-likelihood plus the ridge.
        let (mut ga, mut gb, mut haa, mut hab, mut hbb) = (lambda * a, lambda * b, lambda, 0.0, lambda);
        for &(s, y) in samples {
            let x = ScoreCalibration::logit(s);
            let p = 1.0 / (1.0 + (-(a * x + b)).exp());
            let r = p - if y { 1.0 } else { 0.0 };
            let w = (p * (1.0 - p)).max(1e-12);
            ga += r * x;
            gb += r;
            haa += w * x * x;
            hab += w * x;
            hbb += w;
        }
        let det = haa * hbb - hab * hab;
        if det.abs() < 1e-18 {
            break;
        }
        let (da, db) = ((hbb * ga - hab * gb) / det, (haa * gb - hab * ga) / det);
        a -= da;
        b -= db;
        if da.abs() + db.abs() < 1e-10 {
            break;
        }
    }
    (a, b)
}

/// The lowest probability threshold `t` such that the detections with `p >= t` have a
/// precision of at least `target` (and at least one of them is kept); 1 when none reaches it.
pub fn choose_threshold(probs: &[(f64, bool)], target: f64) -> f64 {
    choose_threshold_bounded(probs, target, None)
}

/// [`choose_threshold`] with, when `max_false` is `Some((f, images))`, also at most `f · images`
/// false detections (`p >= t`, not a tube) kept: the lowest `t` meeting both bounds.
pub fn choose_threshold_bounded(probs: &[(f64, bool)], target: f64, max_false: Option<(f64, usize)>) -> f64 {
    choose_threshold_counted(probs, None, target, max_false)
}

/// [`choose_threshold_bounded`] where only the detections flagged in `counted` (one flag per
/// detection; None = all) count toward the false-detection bound: e.g. the detections on
/// tube-free images, with `images` their number, for a bound per frame without a tube.
pub fn choose_threshold_counted(probs: &[(f64, bool)], counted: Option<&[bool]>, target: f64, max_false: Option<(f64, usize)>) -> f64 {
    let mut v: Vec<(f64, bool, bool)> = probs.iter().enumerate().map(|(i, &(p, y))| (p, y, counted.is_none_or(|c| c[i]))).collect();
    v.sort_by(|x, y| y.0.total_cmp(&x.0));
    let (mut tp, mut false_counted, mut best) = (0usize, 0usize, 1.0f64);
    for (i, &(p, y, c)) in v.iter().enumerate() {
        tp += y as usize;
        false_counted += (!y && c) as usize;
        // Only cut between distinct probabilities.
        if i + 1 < v.len() && v[i + 1].0 == p {
            continue;
        }
        if max_false.is_some_and(|(f, images)| false_counted as f64 > f * images as f64) {
            // More false detections only come with lower thresholds.
            break;
        }
        if tp as f64 / (i + 1) as f64 >= target {
            best = p;
        }
    }
    best
}

/// One bin of a reliability diagram.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ReliabilityBin {
    /// Lower edge of the bin.
    pub lo: f64,
    /// Upper edge of the bin.
    pub hi: f64,
    /// Detections in the bin.
    pub count: usize,
    /// Mean predicted probability (NaN when empty).
    pub mean_probability: f64,
    /// Observed fraction of true positives (NaN when empty).
    pub frequency: f64,
}

/// The reliability diagram over `bins` equal-width bins, and the expected calibration error.
pub fn reliability(probs: &[(f64, bool)], bins: usize) -> (Vec<ReliabilityBin>, f64) {
    let bins = bins.max(1);
    let mut acc = vec![(0usize, 0.0f64, 0usize); bins];
    for &(p, y) in probs {
        let k = ((p * bins as f64) as usize).min(bins - 1);
        acc[k].0 += 1;
        acc[k].1 += p;
        acc[k].2 += y as usize;
    }
    let n = probs.len().max(1) as f64;
    let mut ece = 0.0;
    let out = acc
        .iter()
        .enumerate()
        .map(|(k, &(c, sp, sy))| {
            let (mp, fr) = if c > 0 { (sp / c as f64, sy as f64 / c as f64) } else { (f64::NAN, f64::NAN) };
            if c > 0 {
                ece += c as f64 / n * (mp - fr).abs();
            }
            ReliabilityBin { lo: k as f64 / bins as f64, hi: (k + 1) as f64 / bins as f64, count: c, mean_probability: mp, frequency: fr }
        })
        .collect();
    (out, ece)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Scores whose true-positive rate is exactly sigmoid(2 logit(s) - 1), drawn on a grid.
    fn synthetic() -> Vec<(f64, bool)> {
        let truth = ScoreCalibration { a: 2.0, b: -1.0, threshold: 0.5, target_precision: 0.0, fitted_on: String::new(), max_false_per_image: None, max_false_per_negative_image: None };
        let mut v = Vec::new();
        for i in 1..100 {
            let s = i as f64 / 100.0;
            let p = truth.probability(s);
            let pos = (p * 200.0).round() as usize;
            v.extend((0..200).map(|k| (s, k < pos)));
        }
        v
    }

    #[test]
    fn platt_recovers_the_generating_map() {
        let (a, b) = fit_platt(&synthetic());
        assert!((a - 2.0).abs() < 0.05 && (b + 1.0).abs() < 0.05, "a {a} b {b}");
    }

    #[test]
    fn calibrated_probabilities_have_small_ece_and_the_threshold_meets_the_precision() {
        let data = synthetic();
        let (a, b) = fit_platt(&data);
        let c = ScoreCalibration { a, b, threshold: 0.5, target_precision: 0.95, fitted_on: String::new(), max_false_per_image: None, max_false_per_negative_image: None };
        let probs: Vec<(f64, bool)> = data.iter().map(|&(s, y)| (c.probability(s), y)).collect();
        let (_, ece) = reliability(&probs, 10);
        assert!(ece < 0.02, "{ece}");
        let raw: Vec<(f64, bool)> = data.clone();
        assert!(reliability(&raw, 10).1 > 0.05, "the raw scores are miscalibrated by construction");
        let t = choose_threshold(&probs, 0.95);
        let kept: Vec<_> = probs.iter().filter(|p| p.0 >= t).collect();
        let prec = kept.iter().filter(|p| p.1).count() as f64 / kept.len() as f64;
        assert!(prec >= 0.95 && t < 1.0, "t {t} precision {prec}");
        // One step lower would miss the target.
        let lower: Vec<_> = probs.iter().filter(|p| p.0 < t).map(|p| p.0).collect();
        let next = lower.iter().cloned().fold(f64::MIN, f64::max);
        let kept2: Vec<_> = probs.iter().filter(|p| p.0 >= next).collect();
        let prec2 = kept2.iter().filter(|p| p.1).count() as f64 / kept2.len() as f64;
        assert!(prec2 < 0.95, "{prec2}");
    }

    #[test]
    fn a_bound_on_false_detections_per_image_raises_the_threshold_to_meet_it() {
        let probs: Vec<(f64, bool)> = synthetic();
        let free = choose_threshold(&probs, 0.5);
        let false_at = |t: f64| probs.iter().filter(|p| p.0 >= t && !p.1).count();
        let images = 100;
        // Half the false detections the precision bound alone keeps, per image.
        let f = false_at(free) as f64 / 2.0 / images as f64;
        let t = choose_threshold_bounded(&probs, 0.5, Some((f, images)));
        assert!(t > free, "bounded {t} vs free {free}");
        assert!(false_at(t) as f64 <= f * images as f64, "{} false kept, bound {}", false_at(t), f * images as f64);
        // The next lower distinct probability would break the bound.
        let next = probs.iter().map(|p| p.0).filter(|&p| p < t).fold(f64::MIN, f64::max);
        assert!(false_at(next) as f64 > f * images as f64);
        // No bound: the same as the precision bound alone.
        assert_eq!(choose_threshold_bounded(&probs, 0.5, None), free);
        // Counting only some detections (every other one, e.g. those on tube-free frames):
        // the bound holds on the counted false detections, and the threshold lies between the
        // unbounded one and the one counting all.
        let counted: Vec<bool> = (0..probs.len()).map(|i| i % 2 == 0).collect();
        let tc = choose_threshold_counted(&probs, Some(&counted), 0.5, Some((f, images)));
        let counted_false = |t: f64| probs.iter().zip(&counted).filter(|(p, &c)| c && p.0 >= t && !p.1).count();
        assert!(counted_false(tc) as f64 <= f * images as f64);
        assert!(tc <= t && tc >= free, "counted {tc}, all {t}, free {free}");
        assert_eq!(choose_threshold_counted(&probs, None, 0.5, Some((f, images))), t);
    }
}
