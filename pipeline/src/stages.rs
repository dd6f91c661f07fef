//! The stages after the fit and their policies: hidden-end anchoring, the photometric / rims /
//! two-view stage with the settings of each seed kind, the covariance widening over the unseen
//! part of a tube, and the snap-or-trim policy for masks.

use crate::settings::StageSettings;
use tubeloc_core::{CameraModel, Plane, TubeAxisPose, TubeDetection};
use tubeloc_refine::hidden_end::{anchor_visible_end, unseen_length_variance, widen_along_axis, HiddenEnd};
use tubeloc_refine::silhouette::{silhouette_mask, snap_mask, trim_kept_mask, MaskSnap};
use tubeloc_refine::stereo_stage::{self, PhotoStage, RectifiedPair};
use tubeloc_refine::{GroundPlane, Refiner, SeedKind};

/// The stages after the fit of one pose, in order:
/// 1. with a scene depth map `depth` (stereo) and [`StageSettings::hidden_end`], a pose refined
///    from a mask detection `det` is moved along its axis onto its visible end when its other
///    end is hidden ([`anchor_visible_end`]; template-pose detections' masks are the template's
///    silhouette, not what is visible);
/// 2. with a rectified `pair` and a positive [`StageSettings::photo_range_mm`], the
///    photometric / rims / two-view stage with the settings of the pose's seed kind
///    ([`photo_stage`]; `det` is `None` for an explicit seed);
/// 3. the centre's covariance is widened along the axis over the part of the tube the mask
///    does not show ([`unseen_length_variance`], [`StageSettings::unseen_anchor_px`]).
///
/// The anchoring comes first so that the two-view fit starts from the anchored centre.
/// `camera` is the image's (left) camera, `ground` the pose's ground plane (camera frame).
#[allow(clippy::too_many_arguments)]
pub fn after_fit(settings: &StageSettings, pose: &mut TubeAxisPose, det: Option<&TubeDetection>, depth: Option<&Plane<f32>>, pair: Option<&RectifiedPair>, ground: Option<&GroundPlane>, refiner: &Refiner, camera: &CameraModel) {
    // The mask of a mask seed (the learned segmenter's kind; not a template pose's).
    let mask = det.filter(|d| d.t_cam_tube.is_none()).and_then(|d| d.mask.as_ref()).and_then(|m| m.to_bounded_mask().ok());
    if let (Some(depth), Some(mask), true) = (depth, &mask, settings.hidden_end) {
        anchor_visible_end(pose, refiner.model.length, mask, depth, camera, &HiddenEnd::default());
    }
    if let (Some(pair), true) = (pair, settings.photo_range_mm > 0.0) {
        let kind = det.map_or(SeedKind::Explicit, SeedKind::of);
        stereo_stage::photo_refine(pose, &refiner.model, pair, &photo_stage(settings, ground, refiner, kind));
    }
    // The centre's along-axis freedom over the part of the tube the mask does not show.
    if let Some(v) = mask.as_ref().and_then(|m| unseen_length_variance(pose, refiner.model.length, m, camera, settings.unseen_anchor_px)) {
        widen_along_axis(pose, v);
    }
}

/// Whether the photometric stage moves each end along its own ray (distance and tilt) rather
/// than the centre alone: not with [`StageSettings::photo_centre_only`], and not with a ground
/// plane, whose tilt prior fixes the tilt better.
pub fn photo_moves_ends(settings: &StageSettings, has_ground: bool) -> bool {
    !settings.photo_centre_only && !has_ground
}

/// The photometric / rims stage's settings ([`stereo_stage::photo_refine`]) for a pose refined
/// from a seed of `kind`; with a ground plane the two-view fit's tilt prior and the rims' tilt
/// change have the deviation of that kind's ground tilt prior
/// ([`tubeloc_refine::settings::SeedProfile::ground_tilt_sigma_deg`]), as in the fit before
/// them: mask seeds are taken to lie parallel to the ground, other seeds may tilt.
pub fn photo_stage(settings: &StageSettings, ground: Option<&GroundPlane>, refiner: &Refiner, kind: SeedKind) -> PhotoStage {
    let has_ground = ground.is_some();
    let tilt_sigma_deg = refiner.settings(kind).seed.ground_tilt_sigma_deg;
    PhotoStage {
        two_view: settings.two_view,
        ground: ground.map(|g| (g.normal, tilt_sigma_deg)),
        range_m: settings.photo_range_mm * 1e-3,
        min_zncc: settings.photo_min_zncc,
        ends: photo_moves_ends(settings, has_ground),
        occlusion: settings.scene_occlusion,
        rim_max_epipolar_deg: settings.rim_max_epipolar_deg,
        rim_tilt_prior_deg: has_ground.then_some(tilt_sigma_deg),
    }
}

/// Width of `pose`'s tube body in the image, pixels: `2 r f_x / z` at its centre's depth
/// (infinite behind the camera).
fn tube_width_px(refiner: &Refiner, pose: &TubeAxisPose, camera: &CameraModel) -> f64 {
    if pose.centre.z > 0.0 {
        2.0 * refiner.model.body_radius() * camera.fx / pose.centre.z
    } else {
        f64::INFINITY
    }
}

/// `det` with its mask snapped to `pose`'s silhouette ([`snap_mask`]) when the pose converged
/// and agrees with the mask; otherwise with its mask trimmed ([`trim_kept_mask`]), or unchanged
/// without a mask. Returns whether it was snapped. `camera` is the image's camera.
///
/// A pose that kept its detector seed ([`TubeAxisPose::seed_kept`]) is snapped too, to the
/// silhouette of the seed's centre and axis, when the tube is narrower than
/// `snap.kept_seed_max_width_px` in the image: the seed was kept because the fitted silhouette
/// disagreed with the mask, which on small tubes is mostly the mask being too narrow
/// (`docs/design/0051-verifier-features-and-seed-keeping-on-real-grey.md`).
pub fn snapped_detection(det: &mut TubeDetection, pose: &TubeAxisPose, refiner: &Refiner, camera: &CameraModel, snap: &MaskSnap) -> bool {
    let Some(mask) = det.mask.as_ref().and_then(|m| m.to_mask().ok()) else { return false };
    let width = tube_width_px(refiner, pose, camera);
    let kept_too_wide = pose.seed_kept.is_some() && (width.is_nan() || width >= snap.kept_seed_max_width_px);
    let snapped = (pose.converged && !kept_too_wide).then(|| snap_mask(&mask, &silhouette_mask(&refiner.model, pose, camera), snap)).flatten();
    let was_snapped = snapped.is_some();
    if let Some(m) = snapped.or_else(|| trim_kept_mask(&mask, snap)) {
        det.bbox = m.bbox();
        det.mask = Some(tubeloc_core::Rle::from_mask(&m));
    }
    was_snapped
}
