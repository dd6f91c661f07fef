//! Tube pose from the mounted tag pair: PnP over all visible tag corners.
//!
//! Initialization: for each visible tag, a homography from its plane to undistorted normalized
//! coordinates gives `T_cam_tag` ([`crate::geometry::pose_from_homography`]), together with its
//! planar "flip" alternative (the normal mirrored about the line of sight). Each candidate,
//! mapped to `T_cam_tube = T_cam_tag·T_tube_tag⁻¹`, seeds a Levenberg-Marquardt fit of the
//! reprojection error of all corners (with the camera's distortion); the lowest cost wins. With
//! both tags the two planes fix the flip; with one tag the result is flagged `single_tag`, and
//! `ambiguous` when the flip candidate fits almost as well (cost ratio < 2).
//!
//! Covariance: 6x6, `σ²(JᵀJ)⁻¹` over `[δω (rad, left perturbation in the camera frame), δt (m)]`,
//! `σ²` from the residuals, floored at `(0.1 px)²` so a perfect fit does not claim zero error.

use crate::detect::TagDetection;
use crate::error::CalibError;
use crate::geometry::{homography, pose_from_homography, pose_from_vec, pose_vec, project};
use crate::lm::{BlockKind, Problem};
use crate::mount::{tag_corners, TagMount};
use nalgebra::{Point2, Point3, Rotation3, Unit, Vector3};
use serde::{Deserialize, Serialize};
use tubeloc_core::{CameraModel, Pose};

/// Tube pose from tags.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TagPoseEstimate {
    /// Pose of the tube in the camera frame.
    #[serde(rename = "T_cam_tube")]
    pub t_cam_tube: Pose,
    /// Ids of the tags used.
    pub tags_used: Vec<u32>,
    /// Only one tag was visible (planar pose ambiguity possible).
    pub single_tag: bool,
    /// The planar flip fits almost as well; the pose may be mirrored.
    pub ambiguous: bool,
    /// RMS reprojection error over the corners used (residual norm), pixels.
    pub rms_px: f64,
    /// 6x6 covariance of `[δω (rad), δt (m)]`, row-major.
    pub covariance: [[f64; 6]; 6],
}

/// The planar flip of `T_cam_tag`: normal mirrored about the line of sight through its centre.
fn flipped(t_cam_tag: &Pose) -> Pose {
    let t = t_cam_tag.translation();
    let n = t_cam_tag.transform_vector(&Vector3::z());
    let v = t.normalize();
    let n2 = v * (2.0 * n.dot(&v)) - n;
    let axis = n.cross(&n2);
    let rot = if axis.norm() < 1e-12 { Rotation3::identity() } else { Rotation3::from_axis_angle(&Unit::new_normalize(axis), n.dot(&n2).clamp(-1.0, 1.0).acos()) };
    Pose::from_parts(rot * Rotation3::from_matrix_unchecked(t_cam_tag.rotation()), t)
}

/// Estimates `T_cam_tube` from the detections of the mount's tags in an image of `camera`.
/// Detections of other ids are ignored; for a repeated id the one with the larger decision
/// margin is used. Fails with [`CalibError::NoTags`] when no mount tag is visible.
pub fn estimate_tube_pose(camera: &CameraModel, mount: &TagMount, detections: &[TagDetection]) -> Result<TagPoseEstimate, CalibError> {
    let mut used: Vec<(&crate::mount::MountedTag, &TagDetection)> = Vec::new();
    for tag in &mount.tags {
        let best = detections.iter().filter(|d| d.id == tag.id).max_by(|a, b| a.decision_margin.total_cmp(&b.decision_margin));
        if let Some(d) = best {
            used.push((tag, d));
        }
    }
    if used.is_empty() {
        let seen: Vec<u32> = detections.iter().map(|d| d.id).collect();
        return Err(CalibError::NoTags(format!("none of the mount's tags {:?} was detected (detected ids: {seen:?})", mount.tags.iter().map(|t| t.id).collect::<Vec<_>>())));
    }
    let k = crate::geometry::intrinsics_vec(camera);
    let mut object = Vec::new();
    let mut image = Vec::new();
    let mut candidates = Vec::new();
    for (tag, det) in &used {
        let norm: Vec<Point2<f64>> = det
            .corners
            .iter()
            .map(|c| {
                let (x, y) = camera.normalize(&Point2::new(c[0], c[1]));
                Point2::new(x, y)
            })
            .collect();
        let plane: Vec<Point2<f64>> = tag_corners(tag.size_m).iter().map(|p| Point2::new(p.x, p.y)).collect();
        let h = homography(&plane, &norm)?;
        let t_cam_tag = pose_from_homography(&h)?;
        for cand in [t_cam_tag, flipped(&t_cam_tag)] {
            candidates.push(cand * tag.t_tube_tag.inverse());
        }
        for (p, c) in tag.corners_tube().iter().zip(&det.corners) {
            object.push(*p);
            image.push(Point2::new(c[0], c[1]));
        }
    }
    let mut best: Option<(f64, Pose, Option<nalgebra::DMatrix<f64>>)> = None;
    let mut costs = Vec::new();
    for cand in &candidates {
        let (cost, pose, cov) = match fit(&k, &object, &image, cand) {
            Ok(x) => x,
            Err(_) => continue,
        };
        costs.push(cost);
        if best.as_ref().map(|b| cost < b.0).unwrap_or(true) {
            best = Some((cost, pose, cov));
        }
    }
    let (cost, pose, cov) = best.ok_or_else(|| CalibError::Optimization("no initial pose led to a valid fit".into()))?;
    let single = used.len() == 1;
    let second = costs.iter().copied().filter(|c| *c > cost * (1.0 + 1e-9) + 1e-12).fold(f64::INFINITY, f64::min);
    let ambiguous = single && second < 2.0 * cost.max(1e-6 * object.len() as f64);
    let mut covariance = [[0.0; 6]; 6];
    if let Some(c) = cov {
        for (i, row) in covariance.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = c[(i, j)];
            }
        }
    }
    Ok(TagPoseEstimate { t_cam_tube: pose, tags_used: used.iter().map(|(t, _)| t.id).collect(), single_tag: single, ambiguous, rms_px: (cost / object.len() as f64).sqrt(), covariance })
}

type Fit = (f64, Pose, Option<nalgebra::DMatrix<f64>>);

fn fit(k: &[f64; 9], object: &[Point3<f64>], image: &[Point2<f64>], init: &Pose) -> Result<Fit, CalibError> {
    let mut p = Problem::new();
    let b = p.add_block(pose_vec(init).to_vec(), BlockKind::Pose, false);
    for (x, u) in object.iter().zip(image) {
        let (x, u, k) = (*x, *u, *k);
        p.add_residual(
            vec![b],
            2,
            Box::new(move |v, r| match project(&k, v[0], &x) {
                Some(q) => {
                    r[0] = q.x - u.x;
                    r[1] = q.y - u.y;
                    true
                }
                None => false,
            }),
        );
    }
    let sol = p.solve(100)?;
    let m = (2 * object.len()) as f64;
    // Re-scale the covariance to a noise floor of 0.1 px.
    let sigma2 = if m > 6.0 { sol.cost / (m - 6.0) } else { f64::NAN };
    let floor = 0.01;
    let cov = sol.covariance.and_then(|c| c.block(b)).map(|c| if sigma2.is_finite() && sigma2 > 0.0 { c * (sigma2.max(floor) / sigma2) } else { c });
    Ok((sol.cost, pose_from_vec(&p.params[b]), cov))
}
