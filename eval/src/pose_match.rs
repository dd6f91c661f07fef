//! Matching tube estimates to ground truth, per image.
//!
//! Greedy, like COCO: estimates in decreasing score (ties keep input order) each take the
//! still-unmatched truth of the same image with the best similarity that passes the gate:
//! the highest mask IoU `>= min_iou`, or the smallest centre distance `<= max_distance` metres.
//! The method used is recorded in the result so every report states it.

use nalgebra::Point3;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use tubeloc_core::{Pose, Rle, TubeAxisPose};

/// A ground-truth tube: image and pose `T_cam_tube` (metres).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TubeTruth {
    /// Image id (as in the COCO dataset).
    pub image_id: u64,
    /// `T_cam_tube`, tube axis = tube frame +z.
    pub pose: Pose,
}

/// An estimated tube: image, pose `T_cam_tube` and detection score (higher is better).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TubeEstimate {
    /// Image id.
    pub image_id: u64,
    /// `T_cam_tube`.
    pub pose: Pose,
    /// Confidence score.
    pub score: f64,
    /// The estimate's own standard deviations, when it carries a covariance (for the
    /// covariance consistency of [`crate::pose_summary`]).
    #[serde(default)]
    pub std: Option<PoseStd>,
}

/// Standard deviations of a pose estimate, from its covariance.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseStd {
    /// Axis direction, radians: `sqrt(σ²_δ1 + σ²_δ2)` (tangent-plane block).
    pub axis_rad: f64,
    /// Centre, metres: `sqrt(trace of the 3x3 centre block)`.
    pub centre_m: f64,
}

impl TubeEstimate {
    /// The estimate of a refined grasp pose: `T_cam_tube` with +z along its end direction
    /// (rotation about the axis is arbitrary, which every symmetric metric ignores), with the
    /// pose's standard deviations when its covariance is not zero.
    pub fn from_axis_pose(p: &TubeAxisPose) -> Self {
        let std = PoseStd { axis_rad: p.axis_std_rad(), centre_m: p.centre_std_m() };
        let std = (std.axis_rad > 0.0 && std.centre_m > 0.0 && std.axis_rad.is_finite() && std.centre_m.is_finite()).then_some(std);
        TubeEstimate { image_id: p.image_id, pose: p.to_pose(), score: p.score, std }
    }
}

/// How estimates were matched to truths.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "method", rename_all = "snake_case")]
pub enum MatchMethod {
    /// Highest mask IoU, at least `min_iou`.
    MaskIou {
        /// Gate on the IoU, in [0, 1].
        min_iou: f64,
    },
    /// Smallest distance between the centres (metres), at most `max_distance`.
    CentreDistance {
        /// Gate on the distance, metres.
        max_distance: f64,
    },
}

impl std::fmt::Display for MatchMethod {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            MatchMethod::MaskIou { min_iou } => write!(f, "greedy by score, highest mask IoU >= {min_iou}"),
            MatchMethod::CentreDistance { max_distance } => {
                write!(f, "greedy by score, nearest 3D centre within {:.1} mm", max_distance * 1e3)
            }
        }
    }
}

/// One matched pair: indices into the estimate and truth slices given to the matcher.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseMatch {
    /// Index of the estimate.
    pub estimate: usize,
    /// Index of the truth.
    pub truth: usize,
    /// The similarity that matched them (IoU, or centre distance in metres).
    pub similarity: f64,
}

/// Result of matching: pairs, the unmatched on both sides, and the method.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Matching {
    /// Method used.
    pub method: MatchMethod,
    /// Matched pairs, in the order they were made.
    pub pairs: Vec<PoseMatch>,
    /// Truth indices without an estimate.
    pub unmatched_truths: Vec<usize>,
    /// Estimate indices without a truth (false positives).
    pub unmatched_estimates: Vec<usize>,
}

/// Greedy matching with a caller-given similarity. `similarity(e, t)` is called only for an
/// estimate and truth of the same image; `None` means "not allowed". With `higher_is_better`
/// the largest similarity wins, otherwise the smallest.
pub fn greedy_match(truths: &[TubeTruth], estimates: &[TubeEstimate], method: MatchMethod, higher_is_better: bool, mut similarity: impl FnMut(usize, usize) -> Option<f64>) -> Matching {
    let mut by_image: BTreeMap<u64, Vec<usize>> = BTreeMap::new();
    for (i, t) in truths.iter().enumerate() {
        by_image.entry(t.image_id).or_default().push(i);
    }
    let mut order: Vec<usize> = (0..estimates.len()).collect();
    order.sort_by(|&a, &b| estimates[b].score.total_cmp(&estimates[a].score));
    let mut taken = vec![false; truths.len()];
    let mut pairs = Vec::new();
    let mut unmatched_estimates = Vec::new();
    for e in order {
        let mut best: Option<(usize, f64)> = None;
        for &t in by_image.get(&estimates[e].image_id).map(|v| v.as_slice()).unwrap_or(&[]) {
            if taken[t] {
                continue;
            }
            let Some(s) = similarity(e, t).filter(|s| s.is_finite()) else { continue };
            let better = match best {
                None => true,
                Some((_, b)) => (higher_is_better && s > b) || (!higher_is_better && s < b),
            };
            if better {
                best = Some((t, s));
            }
        }
        match best {
            Some((t, s)) => {
                taken[t] = true;
                pairs.push(PoseMatch { estimate: e, truth: t, similarity: s });
            }
            None => unmatched_estimates.push(e),
        }
    }
    unmatched_estimates.sort_unstable();
    let unmatched_truths = (0..truths.len()).filter(|&t| !taken[t]).collect();
    Matching { method, pairs, unmatched_truths, unmatched_estimates }
}

/// Matches by the distance between tube centres (metres), gated at `max_distance`.
pub fn match_by_centre_distance(truths: &[TubeTruth], estimates: &[TubeEstimate], max_distance: f64) -> Matching {
    greedy_match(truths, estimates, MatchMethod::CentreDistance { max_distance }, false, |e, t| {
        let d = (Point3::from(estimates[e].pose.translation()) - Point3::from(truths[t].pose.translation())).norm();
        (d <= max_distance).then_some(d)
    })
}

/// Matches by mask IoU, gated at `min_iou`; `iou(e, t)` gives the IoU of estimate `e`'s mask
/// with truth `t`'s mask (e.g. `Rle::iou` of the core mask module).
pub fn match_by_iou(truths: &[TubeTruth], estimates: &[TubeEstimate], min_iou: f64, mut iou: impl FnMut(usize, usize) -> f64) -> Matching {
    greedy_match(truths, estimates, MatchMethod::MaskIou { min_iou }, true, |e, t| {
        let v = iou(e, t);
        (v >= min_iou).then_some(v)
    })
}

/// Matches by the IoU of COCO RLE masks (`Rle::iou`, no crowd), gated at `min_iou`;
/// `estimate_masks[e]` and `truth_masks[t]` belong to `estimates[e]` and `truths[t]`. Masks of
/// different image sizes never match. Fails when the mask counts differ from the tube counts.
pub fn match_by_mask_iou(truths: &[TubeTruth], estimates: &[TubeEstimate], truth_masks: &[Rle], estimate_masks: &[Rle], min_iou: f64) -> Result<Matching, crate::pose::PoseEvalError> {
    if truth_masks.len() != truths.len() || estimate_masks.len() != estimates.len() {
        return Err(crate::pose::PoseEvalError::invalid("masks", format!("{} truth masks for {} truths and {} estimate masks for {} estimates", truth_masks.len(), truths.len(), estimate_masks.len(), estimates.len())));
    }
    Ok(match_by_iou(truths, estimates, min_iou, |e, t| Rle::iou(std::slice::from_ref(&estimate_masks[e]), std::slice::from_ref(&truth_masks[t]), &[false])[0]))
}
