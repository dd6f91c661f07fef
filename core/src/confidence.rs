//! The probability that a detection is a tube, from its detector score (Platt scaling).
//!
//! `P(tube | s) = σ(a · logit(s) + b)` with `logit(s) = ln(s / (1 - s))` (scores clamped to
//! `[1e-6, 1 - 1e-6]`) and `σ(x) = 1 / (1 + e^-x)`. `a` and `b` are fitted on real validation
//! composites (`tubeloc eval --calibrate`); `threshold` is the lowest probability at which the
//! validation detections kept have a precision of at least `target_precision` and, when
//! `max_false_per_image` is set, at most that many false detections per validation image
//! (`max_false_per_negative_image`: per tube-free validation image, counting those only).

use serde::{Deserialize, Serialize};

/// A fitted score-to-probability map and the acceptance threshold chosen with it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScoreCalibration {
    /// Slope on the score's logit.
    pub a: f64,
    /// Offset.
    pub b: f64,
    /// Default acceptance threshold on the probability.
    pub threshold: f64,
    /// Precision the threshold was chosen for on the fitting data.
    pub target_precision: f64,
    /// What it was fitted on (free text: data set, detector, model).
    #[serde(default)]
    pub fitted_on: String,
    /// Most false detections per image the threshold allowed on the fitting data (`None`: no
    /// such bound).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_false_per_image: Option<f64>,
    /// Most false detections per tube-free image the threshold allowed on the fitting data,
    /// counting the detections on tube-free images only (`None`: no such bound).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_false_per_negative_image: Option<f64>,
}

impl ScoreCalibration {
    /// The identity map (`P = s`) with threshold 0.5.
    pub fn identity() -> Self {
        ScoreCalibration { a: 1.0, b: 0.0, threshold: 0.5, target_precision: 0.0, fitted_on: "identity".into(), max_false_per_image: None, max_false_per_negative_image: None }
    }

    /// `logit(s)` with `s` clamped to `[1e-6, 1 - 1e-6]`.
    pub fn logit(s: f64) -> f64 {
        let s = s.clamp(1e-6, 1.0 - 1e-6);
        (s / (1.0 - s)).ln()
    }

    /// The probability of a tube for score `s`.
    pub fn probability(&self, s: f64) -> f64 {
        1.0 / (1.0 + (-(self.a * Self::logit(s) + self.b)).exp())
    }

    /// Checks the fields are finite and the threshold a probability.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.a.is_finite() && self.b.is_finite()) {
            return Err(format!("a {} and b {} must be finite", self.a, self.b));
        }
        if !(0.0..=1.0).contains(&self.threshold) || !(0.0..=1.0).contains(&self.target_precision) {
            return Err(format!("threshold {} and target_precision {} must be in [0, 1]", self.threshold, self.target_precision));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identity_returns_the_score() {
        let c = ScoreCalibration::identity();
        for s in [0.01, 0.3, 0.5, 0.9] {
            assert!((c.probability(s) - s).abs() < 1e-9);
        }
        assert!(ScoreCalibration { a: f64::NAN, ..c }.validate().is_err());
    }
}
