//! The last check of a mask seed's fit ([`crate::Refiner::refine`]): a converged fit whose
//! silhouette disagrees with the detector's mask went to the wrong edges, and the seed is kept
//! (`docs/design/0017-mask-agreement-and-visibility.md`).

use crate::refiner::Refiner;
use crate::seed::Seed;
use crate::silhouette;
use tubeloc_core::{BoundedMask, CameraModel, TubeAxisPose};

/// Dilation of the detector's mask in the agreement test, pixels (the snapping default before
/// it was chosen again on real frames; `mask.min_agreement` was chosen with it).
const MASK_CHECK_DILATE_PX: usize = 4;

/// `pose` of a mask seed, checked against the detector's mask: when
/// `IoU(silhouette ∩ dilate(mask, 4 px), mask) < mask.min_agreement` (see
/// [`silhouette::snap_mask`]), the seed's centre and axis are returned instead, with the fit's
/// end decision, the covariance widened by the squared fit-to-seed differences, and
/// [`TubeAxisPose::seed_kept`] saying why.
pub(crate) fn checked_against_mask(refiner: &Refiner, mut pose: TubeAxisPose, seed: &Seed, mask: &BoundedMask, camera: &CameraModel) -> TubeAxisPose {
    let tau = refiner.config().mask.min_agreement;
    if !(pose.converged && tau > 0.0) {
        return pose;
    }
    let Some(iou) = silhouette::mask_agreement(mask, &refiner.model, &pose, camera, MASK_CHECK_DILATE_PX) else { return pose };
    if iou >= tau {
        return pose;
    }
    let a = if seed.state.a.dot(&pose.end_direction) >= 0.0 { seed.state.a } else { -seed.state.a };
    let Ok(kept) = TubeAxisPose::new(pose.image_id, pose.score, seed.state.c, a, pose.end_confidence) else { return pose };
    let dc = pose.centre - kept.centre;
    let angle = tubeloc_core::tube_pose::axis_angle(&pose.axis, &kept.axis);
    for i in 0..3 {
        pose.covariance[i][i] += dc[i] * dc[i];
    }
    for i in 3..5 {
        pose.covariance[i][i] += angle * angle;
    }
    pose.centre = kept.centre;
    pose.axis = kept.axis;
    pose.end_direction = kept.end_direction;
    pose.seed_kept = Some(format!("the fitted silhouette agrees with the detector's mask at IoU {iou:.2} < {tau}"));
    pose
}
