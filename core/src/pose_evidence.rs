//! The probability that a refined pose is a tube, from its detector score and the evidence of
//! its fit (logistic regression).
//!
//! A detector's score says how tube-like the pixels look; the pose fit then says whether a
//! cylinder of the tube's size, lying on the ground, explains the image's edges there. The
//! evidence of the fit is five numbers ([`EVIDENCE_FEATURES`], [`PoseEvidence::features`]):
//!
//! - `f0 = logit(s)`, the detector score `s` clamped to `[1e-6, 1 - 1e-6]`;
//! - `f1 = inliers / count`, the share of the visible contour samples that found an edge;
//! - `f2 = ln(1 + count)`, how much contour the tube shows (pixels of limb and rim);
//! - `f3 = end_confidence`, how clearly one end is the seal end;
//! - `f4 = ln σ_axis`, the axis's standard deviation in radians ([`TubeAxisPose::axis_std_rad`],
//!   floored at 1e-6).
//!
//! A pose that did not converge has no evidence: `f1 = f2 = f3 = f4 = 0` (`σ_axis` = 1 rad).
//! With `z_i = (f_i - μ_i) / s_i`, `P(tube) = σ(b + Σ w_i z_i)`, `σ(x) = 1 / (1 + e^-x)`.
//! `μ`, `s`, `w` and `b` are fitted on real validation composites (`tubeloc eval
//! --fit-pose-evidence`, labels: the snapped mask at IoU >= 0.5 with a true tube).

use crate::tube_pose::TubeAxisPose;
use serde::{Deserialize, Serialize};

/// Number of evidence features.
pub const EVIDENCE_FEATURES: usize = 5;

/// Names of the evidence features, in order (for reports and the JSON file's readers).
pub const EVIDENCE_FEATURE_NAMES: [&str; EVIDENCE_FEATURES] = ["logit_score", "inlier_fraction", "ln_1_plus_contour_samples", "end_confidence", "ln_axis_sigma_rad"];

/// Largest magnitude [`PoseEvidence::validate`] accepts for a mean, a weight or the bias.
pub const MAX_EVIDENCE_PARAMETER: f64 = 1e9;

/// Smallest feature scale [`PoseEvidence::validate`] accepts.
pub const MIN_EVIDENCE_SCALE: f64 = 1e-9;

/// A fitted logistic model of the probability that a refined pose is a tube.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseEvidence {
    /// Feature names, in the order of the arrays ([`EVIDENCE_FEATURE_NAMES`]).
    pub features: Vec<String>,
    /// Mean `μ` of each feature on the fitting data.
    pub mean: [f64; EVIDENCE_FEATURES],
    /// Scale `s` of each feature (its standard deviation on the fitting data, > 0).
    pub scale: [f64; EVIDENCE_FEATURES],
    /// Weight `w` of each standardized feature.
    pub weights: [f64; EVIDENCE_FEATURES],
    /// Offset `b`.
    pub bias: f64,
    /// What it was fitted on (free text: data set, detector, model).
    #[serde(default)]
    pub fitted_on: String,
}

impl PoseEvidence {
    /// The evidence features `f` of a pose (see the module docs).
    pub fn features(pose: &TubeAxisPose) -> [f64; EVIDENCE_FEATURES] {
        let s = pose.score.clamp(1e-6, 1.0 - 1e-6);
        let logit = (s / (1.0 - s)).ln();
        if !pose.converged {
            return [logit, 0.0, 0.0, 0.0, 0.0];
        }
        let r = &pose.residuals;
        let inlier_fraction = if r.count == 0 { 0.0 } else { r.inliers as f64 / r.count as f64 };
        [logit, inlier_fraction, (1.0 + r.count as f64).ln(), pose.end_confidence, pose.axis_std_rad().max(1e-6).ln()]
    }

    /// `P(tube) = σ(b + Σ w_i (f_i - μ_i) / s_i)` for features `f`.
    pub fn probability_of(&self, f: &[f64; EVIDENCE_FEATURES]) -> f64 {
        let x = self.bias + (0..EVIDENCE_FEATURES).map(|i| self.weights[i] * (f[i] - self.mean[i]) / self.scale[i]).sum::<f64>();
        1.0 / (1.0 + (-x).exp())
    }

    /// The probability that `pose` is a tube.
    pub fn probability(&self, pose: &TubeAxisPose) -> f64 {
        self.probability_of(&Self::features(pose))
    }

    /// Checks the feature names, and numbers that keep every term of the sum finite: mean,
    /// weights and bias within ±[`MAX_EVIDENCE_PARAMETER`], scales from
    /// [`MIN_EVIDENCE_SCALE`] (a fitted model's are far inside; beyond them a term can
    /// overflow to ±∞ and two such terms sum to NaN).
    pub fn validate(&self) -> Result<(), String> {
        if self.features != EVIDENCE_FEATURE_NAMES {
            return Err(format!("features {:?} must be {:?}", self.features, EVIDENCE_FEATURE_NAMES));
        }
        let bounded = self.mean.iter().chain(&self.weights).chain(std::iter::once(&self.bias)).all(|v| v.is_finite() && v.abs() <= MAX_EVIDENCE_PARAMETER);
        if !bounded {
            return Err(format!("mean, weights and bias must be finite and within ±{MAX_EVIDENCE_PARAMETER:e}"));
        }
        if let Some(s) = self.scale.iter().find(|s| !(s.is_finite() && **s >= MIN_EVIDENCE_SCALE)) {
            return Err(format!("scale {s} must be finite and at least {MIN_EVIDENCE_SCALE:e}"));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn pose(score: f64, inliers: usize, count: usize, end_confidence: f64, axis_var: f64, converged: bool) -> TubeAxisPose {
        let mut p = TubeAxisPose::new(1, score, Vector3::new(0.0, 0.0, 2.0), Vector3::x(), end_confidence).unwrap();
        p.residuals.inliers = inliers;
        p.residuals.count = count;
        p.covariance[3][3] = axis_var;
        p.covariance[4][4] = axis_var;
        p.converged = converged;
        p
    }

    fn model() -> PoseEvidence {
        PoseEvidence { features: EVIDENCE_FEATURE_NAMES.iter().map(|s| s.to_string()).collect(), mean: [0.0, 0.5, 4.0, 0.7, -4.0], scale: [2.0, 0.25, 1.0, 0.2, 1.0], weights: [2.0, 1.0, 2.0, 1.0, -1.5], bias: -1.0, fitted_on: String::new() }
    }

    #[test]
    fn features_follow_the_formulas() {
        let f = PoseEvidence::features(&pose(0.8, 30, 40, 0.9, 0.5e-4, true));
        assert!((f[0] - 4f64.ln()).abs() < 1e-12);
        assert!((f[1] - 0.75).abs() < 1e-12);
        assert!((f[2] - 41f64.ln()).abs() < 1e-12);
        assert!((f[3] - 0.9).abs() < 1e-12);
        assert!((f[4] - 0.01f64.ln()).abs() < 1e-9, "σ = sqrt(2 · 0.5e-4) = 0.01 rad");
        // A pose that did not converge keeps only its score.
        assert_eq!(PoseEvidence::features(&pose(0.8, 30, 40, 0.9, 0.5e-4, false))[1..], [0.0; 4]);
    }

    #[test]
    fn probability_is_the_logistic_of_the_standardized_sum() {
        let m = model();
        let f = [1.0, 0.75, 5.0, 0.9, -5.0];
        let x: f64 = -1.0 + 2.0 * 0.5 + 1.0 * 1.0 + 2.0 * 1.0 + 1.0 * 1.0 + -1.5 * -1.0;
        assert!((m.probability_of(&f) - 1.0 / (1.0 + (-x).exp())).abs() < 1e-12);
        // More contour found, a sharper axis: more likely a tube.
        let weak = m.probability(&pose(0.5, 10, 40, 0.6, 1e-2, true));
        let strong = m.probability(&pose(0.5, 38, 40, 0.95, 1e-5, true));
        assert!(strong > weak, "{strong} > {weak}");
        assert!(m.validate().is_ok());
        assert!(PoseEvidence { scale: [0.0, 1.0, 1.0, 1.0, 1.0], ..model() }.validate().unwrap_err().contains("scale 0"));
        assert!(PoseEvidence { features: vec!["x".into()], ..model() }.validate().unwrap_err().contains("features"));
        assert!(PoseEvidence { bias: f64::NAN, ..model() }.validate().is_err());
        // Numbers that would overflow a term to ±∞ (two such terms of opposite signs sum to
        // NaN) are refused; at the bounds every probability is a number.
        let overflowing = PoseEvidence { scale: [1e-300; 5], weights: [1e300, -1e300, 0.0, 0.0, 0.0], ..model() };
        assert!(overflowing.probability_of(&[13.9, 1.0, 0.0, 0.0, 0.0]).is_nan(), "the file the check is for");
        assert!(overflowing.validate().unwrap_err().contains("within"));
        assert!(PoseEvidence { scale: [1e-12; 5], ..model() }.validate().unwrap_err().contains("at least"));
        let extreme = PoseEvidence { scale: [MIN_EVIDENCE_SCALE; 5], weights: [MAX_EVIDENCE_PARAMETER, -MAX_EVIDENCE_PARAMETER, MAX_EVIDENCE_PARAMETER, -MAX_EVIDENCE_PARAMETER, MAX_EVIDENCE_PARAMETER], mean: [-MAX_EVIDENCE_PARAMETER; 5], ..model() };
        assert!(extreme.validate().is_ok());
        for f in [[13.9, 1.0, 30.0, 1.0, 5.0], [-13.9, 0.0, 0.0, 0.0, -13.9]] {
            let p = extreme.probability_of(&f);
            assert!((0.0..=1.0).contains(&p), "{p}");
        }
    }
}
