//! `TubeAxisPose`: the grasp-ready output of pose refinement for one tube.
//!
//! A tube lying on the ground is a line in space: a centre `c` (metres, camera frame) and an
//! undirected unit axis `a`. Rotation about the axis is not observable and not reported.
//! Which end is the seal end is a separate, less certain decision, reported as
//! `end_direction` (unit, from the centre toward the seal end) with `end_confidence` in [0, 1].
//!
//! **Flip-free axis.** `axis` is `±a` with the sign fixed by [`canonical_axis`]: the first
//! component (x, then y, then z) whose magnitude exceeds `1e-9` is positive. Two estimates of
//! the same line therefore compare with `acos(|a1·a2|)` ([`axis_angle`]) whatever the flip.
//!
//! **Covariance.** 5x5 over `(c_x, c_y, c_z, δ1, δ2)`: the centre (m²) and the axis
//! perturbation in its tangent plane, `a' = normalize(a + δ1 b1 + δ2 b2)` with
//! `(b1, b2) = tangent_basis(axis)` (rad²).

use crate::error::CoreError;
use crate::pose::Pose;
use nalgebra::{Matrix3, Rotation3, Vector3};
use serde::{Deserialize, Serialize};

/// Why a refinement was rejected or did not converge.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FailureReason {
    /// The optimizer diverged (cost grew, pose left the valid range, or non-finite values).
    Diverged,
    /// Too few contour points found an image edge to constrain the pose.
    TooFewEdges,
    /// The image evidence does not support a tube at the seed (e.g. bare terrain).
    EmptyTerrain,
    /// The tube projects (mostly) outside the image or behind the camera.
    OutOfImage,
    /// The seed itself is unusable (missing, degenerate or non-finite).
    BadSeed,
    /// The iteration limit was reached before convergence.
    MaxIterations,
}

/// A failure reason with a human-readable explanation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RefineFailure {
    /// Machine-readable reason.
    pub reason: FailureReason,
    /// What happened, with numbers.
    pub message: String,
}

/// Residual statistics of a fit.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ResidualStats {
    /// Root mean square of the image residuals of the inliers, pixels (full resolution).
    pub rms_px: f64,
    /// Number of contour samples that found a matching edge within the robust threshold.
    pub inliers: usize,
    /// Number of visible contour samples.
    pub count: usize,
    /// Root mean square distance of stereo points to the surface, metres (0 without stereo).
    #[serde(default)]
    pub stereo_rms_m: f64,
    /// Number of stereo points used (0 without stereo).
    #[serde(default)]
    pub stereo_points: usize,
    /// Optimizer iterations run (all pyramid levels).
    #[serde(default)]
    pub iterations: usize,
}

/// A refined tube pose in the camera frame (OpenCV: x right, y down, z forward; metres).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TubeAxisPose {
    /// COCO image id of the detection this pose refines.
    pub image_id: u64,
    /// Detector score carried over from the detection.
    pub score: f64,
    /// Tube centre (half way along the tube), metres, camera frame.
    pub centre: Vector3<f64>,
    /// Flip-free unit axis ([`canonical_axis`]).
    pub axis: Vector3<f64>,
    /// Unit direction from the centre toward the seal end (`±axis`).
    pub end_direction: Vector3<f64>,
    /// Confidence in `end_direction`, in [0, 1] (0.5 = no evidence either way).
    pub end_confidence: f64,
    /// 5x5 covariance over centre (m²) and axis tangent (rad²), row-major. For mask seeds
    /// `tubeloc refine` adds the centre's along-axis freedom over the tube's unseen length.
    pub covariance: [[f64; 5]; 5],
    /// Residual statistics.
    pub residuals: ResidualStats,
    /// True when the optimizer converged and the fit passed the quality checks.
    pub converged: bool,
    /// Why the fit failed; `None` when `converged`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub failure: Option<RefineFailure>,
    /// Set when the centre and axis are the detector's seed rather than the fit, and why (the
    /// fitted silhouette disagreed with the detector's mask). The end decision is the fit's;
    /// the covariance is the fit's widened by the fit-to-seed difference.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed_kept: Option<String>,
    /// Set when the centre was moved along the axis because one end is hidden (stereo: the
    /// scene's depth shows an occluder or the image border beyond it), saying which end and by
    /// how much; the centre's along-axis variance is then the visible end's few pixels
    /// (`tubeloc refine`, `tubeloc_refine::hidden_end::unseen_length_variance`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub end_anchored: Option<String>,
}

/// The canonical sign of an undirected axis: the first component (x, y, z order) with magnitude
/// above `1e-9` is made positive. Returns a unit vector; `None` for a zero or non-finite input.
pub fn canonical_axis(a: &Vector3<f64>) -> Option<Vector3<f64>> {
    let n = a.norm();
    if !n.is_finite() || n < 1e-12 {
        return None;
    }
    let u = a / n;
    let first = u.iter().copied().find(|c| c.abs() > 1e-9).unwrap_or(1.0);
    Some(if first < 0.0 { -u } else { u })
}

/// Angle between two undirected axes, radians in `[0, π/2]`: `acos(|a·b| / (|a||b|))`.
pub fn axis_angle(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    let d = (a.dot(b) / (a.norm() * b.norm())).abs().min(1.0);
    d.acos()
}

/// A deterministic orthonormal basis `(b1, b2)` of the plane perpendicular to unit `a`:
/// `b1 = normalize(a × e)` with `e` the coordinate axis least aligned with `a`, `b2 = a × b1`.
pub fn tangent_basis(a: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let ax = a.abs();
    let e = if ax.x <= ax.y && ax.x <= ax.z {
        Vector3::x()
    } else if ax.y <= ax.z {
        Vector3::y()
    } else {
        Vector3::z()
    };
    let b1 = a.cross(&e).normalize();
    let b2 = a.cross(&b1);
    (b1, b2)
}

impl TubeAxisPose {
    /// A pose from a centre and a directed axis (toward the seal end), with zero covariance,
    /// `converged = true` and no residuals. Fails on a non-finite centre or zero axis.
    pub fn new(image_id: u64, score: f64, centre: Vector3<f64>, seal_direction: Vector3<f64>, end_confidence: f64) -> Result<Self, CoreError> {
        if centre.iter().any(|v| !v.is_finite()) {
            return Err(CoreError::invalid("tube pose", "non-finite centre"));
        }
        let axis = canonical_axis(&seal_direction).ok_or_else(|| CoreError::invalid("tube pose", "zero or non-finite axis"))?;
        let end = seal_direction.normalize();
        Ok(TubeAxisPose {
            image_id,
            score,
            centre,
            axis,
            end_direction: end,
            end_confidence: end_confidence.clamp(0.0, 1.0),
            covariance: [[0.0; 5]; 5],
            residuals: ResidualStats::default(),
            converged: true,
            failure: None,
            seed_kept: None,
            end_anchored: None,
        })
    }

    /// Marks the pose as failed with a reason (keeps the last finite estimate).
    pub fn fail(mut self, reason: FailureReason, message: impl Into<String>) -> Self {
        self.converged = false;
        self.failure = Some(RefineFailure { reason, message: message.into() });
        self
    }

    /// `T_cam_tube` with +z along `end_direction` (toward the seal end) and an arbitrary but
    /// deterministic rotation about the axis (x = first vector of [`tangent_basis`]).
    pub fn to_pose(&self) -> Pose {
        let z = self.end_direction.normalize();
        let (x, y) = tangent_basis(&z);
        Pose::from_parts(Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, z])), self.centre)
    }

    /// Standard deviation of the axis direction, radians: `sqrt(σ²_δ1 + σ²_δ2)`.
    pub fn axis_std_rad(&self) -> f64 {
        (self.covariance[3][3] + self.covariance[4][4]).max(0.0).sqrt()
    }

    /// Standard deviation of the centre, metres: `sqrt(trace of the 3x3 centre block)`.
    pub fn centre_std_m(&self) -> f64 {
        (self.covariance[0][0] + self.covariance[1][1] + self.covariance[2][2]).max(0.0).sqrt()
    }

    /// Position error against a ground-truth centre, split into the part perpendicular to the
    /// ground-truth axis and the part along it: `(perp, along)` in metres.
    pub fn position_error(&self, gt_centre: &Vector3<f64>, gt_axis: &Vector3<f64>) -> (f64, f64) {
        let d = self.centre - gt_centre;
        let a = gt_axis.normalize();
        let along = d.dot(&a);
        ((d - a * along).norm(), along.abs())
    }

    /// Grasp frame `T_cam_grasp` for the arm planner, camera frame, origin at the tube centre.
    ///
    /// `up` is the upward direction (against gravity / the ground normal) in the camera frame.
    /// The gripper approaches from above: grasp +z (approach) = `-up` made perpendicular to the
    /// axis; grasp +x = the flip-free axis; grasp +y = z × x, the direction in which the fingers
    /// close, across the axis. When `up` is zero, non-finite or parallel to the axis (a standing
    /// tube), the approach falls back to the viewing ray from the camera to the centre, and then
    /// to camera +z, made perpendicular to the axis. Always returns a valid rotation.
    pub fn grasp_frame(&self, up: &Vector3<f64>) -> Pose {
        let x = canonical_axis(&self.axis).unwrap_or_else(Vector3::x);
        let perp = |v: Vector3<f64>| -> Option<Vector3<f64>> {
            if v.iter().any(|c| !c.is_finite()) {
                return None;
            }
            let p = v - x * v.dot(&x);
            let n = p.norm();
            (n > 1e-6 * v.norm().max(1e-300) && n > 1e-12).then(|| p / n)
        };
        let z = perp(-up).or_else(|| perp(self.centre)).or_else(|| perp(Vector3::z())).or_else(|| perp(Vector3::y())).unwrap_or_else(|| tangent_basis(&x).0);
        let y = z.cross(&x);
        Pose::from_parts(Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, z])), self.centre)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn canonical_axis_is_flip_free() {
        let a = Vector3::new(-0.3, 0.5, 0.8);
        assert_eq!(canonical_axis(&a), canonical_axis(&-a));
        assert!(canonical_axis(&a).unwrap().x > 0.0);
        let b = Vector3::new(0.0, -1.0, 0.0);
        assert_eq!(canonical_axis(&b).unwrap(), Vector3::y());
        assert!(canonical_axis(&Vector3::zeros()).is_none());
        assert!((axis_angle(&a, &-a)).abs() < 1e-7);
        assert!((axis_angle(&Vector3::x(), &Vector3::y()) - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    }

    #[test]
    fn grasp_frame_approaches_from_above_and_closes_across_axis() {
        // Camera looking down at 45 degrees: world up is (0, -1, -1)/√2 in the camera frame.
        let up = Vector3::new(0.0, -1.0, -1.0).normalize();
        let p = TubeAxisPose::new(0, 1.0, Vector3::new(0.1, 0.2, 1.0), Vector3::new(-1.0, 0.0, 0.0), 0.9).unwrap();
        let g = p.grasp_frame(&up);
        let r = g.rotation();
        assert!((r.determinant() - 1.0).abs() < 1e-12);
        let (x, y, z) = (r.column(0).into_owned(), r.column(1).into_owned(), r.column(2).into_owned());
        assert!((x - Vector3::x()).norm() < 1e-12, "x follows the flip-free axis");
        assert!((z + up).norm() < 1e-12, "approach is straight down here");
        assert!(y.dot(&p.axis).abs() < 1e-12);
        assert_eq!(g.translation(), p.centre);
        // Flipped estimate: same grasp frame.
        let q = TubeAxisPose::new(0, 1.0, p.centre, Vector3::x(), 0.9).unwrap();
        assert!(q.grasp_frame(&up).distance(&g).0 < 1e-12);
        // Standing tube and degenerate up still give a rotation.
        let s = TubeAxisPose::new(0, 1.0, Vector3::new(0.0, 0.0, 1.0), up, 0.5).unwrap();
        for u in [up, Vector3::zeros(), Vector3::new(f64::NAN, 0.0, 0.0)] {
            let r = s.grasp_frame(&u).rotation();
            assert!(r.iter().all(|v| v.is_finite()) && (r.determinant() - 1.0).abs() < 1e-9);
        }
    }

    #[test]
    fn json_round_trip_and_errors() {
        let mut p = TubeAxisPose::new(5, 0.7, Vector3::new(0.0, 0.1, 0.9), Vector3::new(0.0, 0.0, -1.0), 0.8).unwrap();
        p.covariance[0][0] = 1e-6;
        let p = p.fail(FailureReason::TooFewEdges, "3 of 200 samples");
        let text = serde_json::to_string(&p).unwrap();
        assert!(text.contains("too_few_edges"), "{text}");
        let back: TubeAxisPose = serde_json::from_str(&text).unwrap();
        assert_eq!(back, p);
        assert_eq!(p.axis, Vector3::z());
        let (perp, along) = p.position_error(&Vector3::new(0.003, 0.1, 0.95), &Vector3::z());
        assert!((perp - 0.003).abs() < 1e-12 && (along - 0.05).abs() < 1e-12);
        assert!(TubeAxisPose::new(0, 1.0, Vector3::zeros(), Vector3::zeros(), 0.5).is_err());
        let t = p.to_pose();
        assert!((t.transform_vector(&Vector3::z()) - p.end_direction).norm() < 1e-12);
    }
}
