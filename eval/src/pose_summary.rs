//! Whole pose evaluation of matched tubes: per-pair errors, summaries and BOP average recalls.
//!
//! Summaries give the count, mean, median, 90th percentile and maximum (percentiles linearly
//! interpolated between order statistics, like numpy's default), and the fraction of pairs with
//! an error `<=` each threshold: 1/2/5 degrees for angles, 2/5/10 mm for distances,
//! 5/10/20 pixels for MSPD. Fractions are over matched pairs; BOP recalls are over all truths.
//!
//! Covariance consistency: for estimates that carry standard deviations
//! ([`crate::pose_match::PoseStd`]), the axis angle error over `σ_axis` and the centre distance
//! over `σ_centre` (σ = square root of the covariance block's trace), summarized at 1/2/3. A
//! consistent Gaussian covariance puts about 61-68 % of the errors within 1 and 95 % or more
//! within 2 (2-D isotropic: `1 - e^-1` and `1 - e^-4`; 3-D: 61 % and 99 %; one dominant
//! direction: 68 % and 95 %); fewer means the covariance is overconfident.

use crate::pose::{pose_axis_error, AxisError, PoseEvalError};
use crate::pose_bop::{bop_recalls, mspd, mspd_thresholds_640, mssd, mssd_thresholds, ModelPoints, Symmetries};
use crate::pose_match::{MatchMethod, Matching, TubeEstimate, TubeTruth};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use tubeloc_core::CameraModel;

/// Angle thresholds of the summaries, degrees.
pub const ANGLE_THRESHOLDS_DEG: [f64; 3] = [1.0, 2.0, 5.0];
/// Distance thresholds of the summaries, millimetres.
pub const DISTANCE_THRESHOLDS_MM: [f64; 3] = [2.0, 5.0, 10.0];
/// Image-distance thresholds of the summaries, pixels.
pub const PIXEL_THRESHOLDS_PX: [f64; 3] = [5.0, 10.0, 20.0];
/// Thresholds of the error-over-σ summaries (covariance consistency).
pub const SIGMA_THRESHOLDS: [f64; 3] = [1.0, 2.0, 3.0];

/// Fraction of values at or below a threshold.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Within {
    /// Threshold, in the unit of the summarized values.
    pub threshold: f64,
    /// Fraction of values `<= threshold`, in [0, 1].
    pub fraction: f64,
}

/// Distribution summary of one error; statistics are `None` when there are no values.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// Number of values.
    pub count: usize,
    /// Arithmetic mean.
    pub mean: Option<f64>,
    /// Median (50th percentile).
    pub median: Option<f64>,
    /// 90th percentile.
    pub p90: Option<f64>,
    /// Largest value.
    pub max: Option<f64>,
    /// Fractions within each threshold.
    pub within: Vec<Within>,
}

/// Percentile `q` in [0, 100] of sorted values, linear between order statistics
/// (`x[(n-1) q/100]` interpolated); `None` when empty.
pub fn percentile(sorted: &[f64], q: f64) -> Option<f64> {
    if sorted.is_empty() {
        return None;
    }
    let pos = (sorted.len() - 1) as f64 * (q / 100.0).clamp(0.0, 1.0);
    let lo = pos.floor() as usize;
    let hi = pos.ceil() as usize;
    Some(sorted[lo] + (sorted[hi] - sorted[lo]) * (pos - lo as f64))
}

/// Summarizes finite values (non-finite ones are dropped) with fractions at `thresholds`.
pub fn summarize(values: &[f64], thresholds: &[f64]) -> Summary {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    let n = v.len();
    let within = thresholds.iter().map(|&t| Within { threshold: t, fraction: if n == 0 { 0.0 } else { v.iter().filter(|&&x| x <= t).count() as f64 / n as f64 } }).collect();
    Summary { count: n, mean: (n > 0).then(|| v.iter().sum::<f64>() / n as f64), median: percentile(&v, 50.0), p90: percentile(&v, 90.0), max: v.last().copied(), within }
}

/// Errors of one matched pair.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PairErrors {
    /// Image id.
    pub image_id: u64,
    /// Index of the estimate in the evaluated slice.
    pub estimate: usize,
    /// Index of the truth.
    pub truth: usize,
    /// Score of the estimate.
    pub score: f64,
    /// Axis-line errors.
    pub axis: AxisError,
    /// MSSD with the continuous axial symmetry, mm.
    pub mssd_mm: f64,
    /// MSSD with axial symmetry and the end flip, mm.
    pub mssd_flip_mm: f64,
    /// MSPD with axial symmetry, pixels (`None` without a camera for the image).
    pub mspd_px: Option<f64>,
    /// MSPD with axial symmetry and the end flip, pixels.
    pub mspd_flip_px: Option<f64>,
    /// Width of the image in pixels (scales the MSPD thresholds), when a camera is known.
    pub image_width: Option<u32>,
    /// Axis angle error over the estimate's axis standard deviation (when it has one).
    #[serde(default)]
    pub axis_error_over_std: Option<f64>,
    /// Centre distance over the estimate's centre standard deviation (when it has one).
    #[serde(default)]
    pub centre_error_over_std: Option<f64>,
}

/// BOP average recalls and per-threshold recalls.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BopRecalls {
    /// Object diameter used for the MSSD thresholds, mm.
    pub diameter_mm: f64,
    /// Step of the discretized axial symmetry, degrees.
    pub symmetry_step_deg: f64,
    /// MSSD thresholds, mm.
    pub mssd_thresholds_mm: Vec<f64>,
    /// MSPD thresholds for a 640-pixel-wide image, pixels.
    pub mspd_thresholds_px_640: Vec<f64>,
    /// Recall at each MSSD threshold (axial symmetry).
    pub mssd_recalls: Vec<f64>,
    /// Recall at each MSSD threshold (axial symmetry + flip).
    pub mssd_flip_recalls: Vec<f64>,
    /// Recall at each MSPD threshold (axial), empty without cameras.
    pub mspd_recalls: Vec<f64>,
    /// Recall at each MSPD threshold (axial + flip).
    pub mspd_flip_recalls: Vec<f64>,
    /// AR_MSSD (axial).
    pub ar_mssd: f64,
    /// AR_MSSD (axial + flip).
    pub ar_mssd_flip: f64,
    /// AR_MSPD (axial), `None` without cameras.
    pub ar_mspd: Option<f64>,
    /// AR_MSPD (axial + flip).
    pub ar_mspd_flip: Option<f64>,
}

/// Summaries of every error over the matched pairs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseSummaries {
    /// Axis angle error, degrees.
    pub axis_angle_deg: Summary,
    /// Perpendicular distance of the centre to the true axis, mm.
    pub perpendicular_mm: Summary,
    /// Absolute along-axis offset of the centre, mm.
    pub along_axis_abs_mm: Summary,
    /// Centre distance, mm.
    pub centre_distance_mm: Summary,
    /// MSSD (axial), mm.
    pub mssd_mm: Summary,
    /// MSSD (axial + flip), mm.
    pub mssd_flip_mm: Summary,
    /// MSPD (axial), pixels.
    pub mspd_px: Summary,
    /// MSPD (axial + flip), pixels.
    pub mspd_flip_px: Summary,
    /// Axis angle error over the estimate's σ (pairs whose estimate has a covariance).
    #[serde(default)]
    pub axis_error_over_std: Summary,
    /// Centre distance over the estimate's σ (pairs whose estimate has a covariance).
    #[serde(default)]
    pub centre_error_over_std: Summary,
}

/// Everything a pose evaluation produces; serializable to JSON.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseEvaluation {
    /// Matching method, in words (e.g. "greedy by score, highest mask IoU >= 0.5").
    pub method: String,
    /// Matching method and its gate.
    pub matching: MatchMethod,
    /// Number of truths.
    pub n_truths: usize,
    /// Number of estimates.
    pub n_estimates: usize,
    /// Number of matched pairs.
    pub n_matched: usize,
    /// Fraction of matched pairs whose end direction is right.
    pub end_correct_fraction: f64,
    /// Summaries over the matched pairs.
    pub summaries: PoseSummaries,
    /// BOP recalls over all truths.
    pub bop: BopRecalls,
    /// Per-pair errors.
    pub pairs: Vec<PairErrors>,
}

/// Settings of [`evaluate_poses`].
#[derive(Clone, Debug, PartialEq)]
pub struct PoseEvalConfig {
    /// Step of the discretized axial symmetry, degrees (BOP uses about 1°).
    pub symmetry_step_deg: f64,
    /// Camera of each image, for MSPD.
    pub cameras: BTreeMap<u64, CameraModel>,
    /// Camera of images not in `cameras`; `None` skips MSPD for them.
    pub default_camera: Option<CameraModel>,
}

impl Default for PoseEvalConfig {
    fn default() -> Self {
        PoseEvalConfig { symmetry_step_deg: 1.0, cameras: BTreeMap::new(), default_camera: None }
    }
}

/// Evaluates matched estimates: per-pair axis and BOP errors (in parallel), summaries and
/// recalls. Pair indices in `matching` refer to `truths` and `estimates`.
pub fn evaluate_poses(truths: &[TubeTruth], estimates: &[TubeEstimate], matching: &Matching, model: &ModelPoints, config: &PoseEvalConfig) -> Result<PoseEvaluation, PoseEvalError> {
    let axial = Symmetries::tube(config.symmetry_step_deg, false)?;
    let flip = Symmetries::tube(config.symmetry_step_deg, true)?;
    for m in &matching.pairs {
        if m.truth >= truths.len() || m.estimate >= estimates.len() {
            return Err(PoseEvalError::invalid("matching", format!("pair ({}, {}) out of range", m.estimate, m.truth)));
        }
    }
    let pairs: Vec<PairErrors> = matching
        .pairs
        .par_iter()
        .map(|m| {
            let (e, g) = (&estimates[m.estimate], &truths[m.truth]);
            let cam = config.cameras.get(&g.image_id).or(config.default_camera.as_ref());
            let axis = pose_axis_error(&e.pose, &g.pose);
            PairErrors {
                image_id: g.image_id,
                estimate: m.estimate,
                truth: m.truth,
                score: e.score,
                axis_error_over_std: e.std.map(|s| axis.axis_angle_deg.to_radians() / s.axis_rad),
                centre_error_over_std: e.std.map(|s| axis.centre_distance_mm * 1e-3 / s.centre_m),
                axis,
                mssd_mm: mssd(&e.pose, &g.pose, model, &axial) * 1e3,
                mssd_flip_mm: mssd(&e.pose, &g.pose, model, &flip) * 1e3,
                mspd_px: cam.map(|c| mspd(&e.pose, &g.pose, model, &axial, c)),
                mspd_flip_px: cam.map(|c| mspd(&e.pose, &g.pose, model, &flip, c)),
                image_width: cam.map(|c| c.width),
            }
        })
        .collect();
    let col = |f: &dyn Fn(&PairErrors) -> Option<f64>| -> Vec<f64> { pairs.iter().filter_map(f).collect() };
    let summaries = PoseSummaries {
        axis_angle_deg: summarize(&col(&|p| Some(p.axis.axis_angle_deg)), &ANGLE_THRESHOLDS_DEG),
        perpendicular_mm: summarize(&col(&|p| Some(p.axis.perpendicular_mm)), &DISTANCE_THRESHOLDS_MM),
        along_axis_abs_mm: summarize(&col(&|p| Some(p.axis.along_axis_mm.abs())), &DISTANCE_THRESHOLDS_MM),
        centre_distance_mm: summarize(&col(&|p| Some(p.axis.centre_distance_mm)), &DISTANCE_THRESHOLDS_MM),
        mssd_mm: summarize(&col(&|p| Some(p.mssd_mm)), &DISTANCE_THRESHOLDS_MM),
        mssd_flip_mm: summarize(&col(&|p| Some(p.mssd_flip_mm)), &DISTANCE_THRESHOLDS_MM),
        mspd_px: summarize(&col(&|p| p.mspd_px), &PIXEL_THRESHOLDS_PX),
        mspd_flip_px: summarize(&col(&|p| p.mspd_flip_px), &PIXEL_THRESHOLDS_PX),
        axis_error_over_std: summarize(&col(&|p| p.axis_error_over_std), &SIGMA_THRESHOLDS),
        centre_error_over_std: summarize(&col(&|p| p.centre_error_over_std), &SIGMA_THRESHOLDS),
    };
    let n = truths.len();
    let diameter_mm = model.diameter * 1e3;
    let mssd_thr = mssd_thresholds(diameter_mm);
    let px_thr = mspd_thresholds_640();
    // MSPD errors normalized to a 640-pixel-wide image, so one threshold list serves all.
    let norm = |f: &dyn Fn(&PairErrors) -> Option<f64>| -> Vec<f64> { pairs.iter().filter_map(|p| Some(f(p)? * 640.0 / p.image_width? as f64)).collect() };
    let has_cam = pairs.iter().any(|p| p.mspd_px.is_some()) || (pairs.is_empty() && (config.default_camera.is_some() || !config.cameras.is_empty()));
    let mean = |r: &[f64]| if r.is_empty() { 0.0 } else { r.iter().sum::<f64>() / r.len() as f64 };
    let mssd_recalls = bop_recalls(&col(&|p| Some(p.mssd_mm)), n, &mssd_thr);
    let mssd_flip_recalls = bop_recalls(&col(&|p| Some(p.mssd_flip_mm)), n, &mssd_thr);
    let (mspd_recalls, mspd_flip_recalls) = if has_cam { (bop_recalls(&norm(&|p| p.mspd_px), n, &px_thr), bop_recalls(&norm(&|p| p.mspd_flip_px), n, &px_thr)) } else { (Vec::new(), Vec::new()) };
    let bop = BopRecalls {
        diameter_mm,
        symmetry_step_deg: 360.0 / axial.rotations.len() as f64,
        ar_mssd: mean(&mssd_recalls),
        ar_mssd_flip: mean(&mssd_flip_recalls),
        ar_mspd: has_cam.then(|| mean(&mspd_recalls)),
        ar_mspd_flip: has_cam.then(|| mean(&mspd_flip_recalls)),
        mssd_thresholds_mm: mssd_thr,
        mspd_thresholds_px_640: px_thr,
        mssd_recalls,
        mssd_flip_recalls,
        mspd_recalls,
        mspd_flip_recalls,
    };
    let n_matched = pairs.len();
    let end_correct_fraction = if n_matched == 0 { 0.0 } else { pairs.iter().filter(|p| p.axis.end_correct).count() as f64 / n_matched as f64 };
    Ok(PoseEvaluation { method: matching.method.to_string(), matching: matching.method.clone(), n_truths: n, n_estimates: estimates.len(), n_matched, end_correct_fraction, summaries, bop, pairs })
}
