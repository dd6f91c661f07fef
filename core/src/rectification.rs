//! Geometry of a rectified stereo pair (Bouguet-style): the rotations that make both image
//! planes coplanar with rows along the baseline, the shared distortion-free rectified camera and
//! the projection matrices `P1`, `P2` and disparity-to-depth matrix `Q`.
//!
//! Both cameras are rotated about their optical centres into a common orientation whose x
//! axis is the baseline (left → right optical centre) and whose z axis is the mean of the two
//! optical axes made orthogonal to the baseline; the y axis completes a right-handed frame.
//! Rotations `R1`, `R2` map original left/right camera coordinates into that rectified frame:
//! `p_rect = R1 p_left`, and with `T_left_right = (R, t)`, `R2 = R1 R`. Both rectified cameras
//! share the intrinsics `K' = [f 0 cx; 0 f cy; 0 0 1]` (no distortion, size of the left image)
//! with `f = min(fx, fy)` over both cameras, and the right camera sits at `x = B` in the
//! rectified frame:
//!
//! ```text
//! P1 = K' [I | 0],   P2 = K' [I | (-B, 0, 0)ᵀ]
//! Q  = [[1, 0, 0, -cx], [0, 1, 0, -cy], [0, 0, 0, f], [0, 0, 1/B, 0]],  (X Y Z W)ᵀ = Q (u v d 1)ᵀ
//! ```
//!
//! The principal point is chosen so that the original image centres land, on average, at the
//! rectified image centre. These are the matrices ROS `camera_info` calls the rectification
//! (`R`) and projection (`P`) matrices, and OpenCV `stereoRectify`'s `R1, R2, P1, P2, Q`.
//!
//! Rigs with (almost) zero baseline, cameras looking in opposite directions, or a baseline
//! within 45° of the optical axis are refused: their epipoles lie inside the image.

use crate::{camera::CameraModel, error::CoreError, pose::Pose};
use nalgebra::{Matrix3, Matrix3x4, Matrix4, Point2, Vector3};

/// The rectifying rotations, rectified camera and projection matrices of a stereo pair (see
/// the module documentation for the formulas and frames).
#[derive(Clone, Debug, PartialEq)]
pub struct PairRectification {
    /// Rotation from the original left camera frame into the rectified frame (`R1`).
    pub r_left: Matrix3<f64>,
    /// Rotation from the original right camera frame into the rectified frame (`R2`).
    pub r_right: Matrix3<f64>,
    /// Rectified camera shared by both images (no distortion, size of the left image), pixels.
    pub rectified: CameraModel,
    /// Baseline, metres.
    pub baseline: f64,
    /// Left projection matrix `P1 = K' [I | 0]` (pixels).
    pub p1: Matrix3x4<f64>,
    /// Right projection matrix `P2 = K' [I | (-B, 0, 0)]`: `P2[0][3] = -f B` (pixels · metres).
    pub p2: Matrix3x4<f64>,
    /// Disparity-to-depth matrix `Q`.
    pub q: Matrix4<f64>,
}

impl PairRectification {
    /// Rectifies the pair `left`, `right` with `t_left_right` (maps right-camera points into the
    /// left camera frame, metres). Errors ([`CoreError::Invalid`] with `what` = "stereo pair")
    /// on zero baseline, opposite viewing directions and baselines within 45° of the optical
    /// axis. The cameras are assumed valid ([`CameraModel::validate`]).
    pub fn new(left: &CameraModel, right: &CameraModel, t_left_right: &Pose) -> Result<Self, CoreError> {
        let refuse = |m: String| CoreError::invalid("stereo pair", m);
        let r = t_left_right.rotation();
        let t = t_left_right.translation();
        let baseline = t.norm();
        if baseline.is_nan() || baseline <= 1e-9 {
            return Err(refuse(format!("zero baseline ({baseline:.3e} m) between the optical centres")));
        }
        let e1 = t / baseline;
        let z_mean = Vector3::z() + r * Vector3::z();
        if z_mean.norm() < 1e-6 {
            return Err(refuse("the cameras look in opposite directions".into()));
        }
        let z_mean = z_mean.normalize();
        let along = e1.dot(&z_mean);
        if along.abs() > std::f64::consts::FRAC_1_SQRT_2 {
            return Err(refuse(format!("the baseline is {:.1}° from the optical axis (must be more than 45°): the epipoles lie inside the images", along.abs().acos().to_degrees())));
        }
        let e3 = (z_mean - e1 * along).normalize();
        let e2 = e3.cross(&e1);
        let r1 = Matrix3::from_rows(&[e1.transpose(), e2.transpose(), e3.transpose()]);
        let r2 = r1 * r;

        let f = left.fx.min(left.fy).min(right.fx).min(right.fy);
        let (w, h) = (left.width as f64, left.height as f64);
        let mut off = Vector3::zeros();
        for (cam, rot) in [(left, &r1), (right, &r2)] {
            let (x, y) = cam.normalize(&Point2::new((w - 1.0) / 2.0, (h - 1.0) / 2.0));
            let ray = rot * Vector3::new(x, y, 1.0);
            off += Vector3::new(f * ray.x / ray.z, f * ray.y / ray.z, 0.0) / 2.0;
        }
        let (cx, cy) = ((w - 1.0) / 2.0 - off.x, (h - 1.0) / 2.0 - off.y);
        let rectified = CameraModel { width: left.width, height: left.height, fx: f, fy: f, cx, cy, distortion: Default::default() };
        let p1 = Matrix3x4::new(f, 0.0, cx, 0.0, 0.0, f, cy, 0.0, 0.0, 0.0, 1.0, 0.0);
        let mut p2 = p1;
        p2[(0, 3)] = -f * baseline;
        let q = Matrix4::new(1.0, 0.0, 0.0, -cx, 0.0, 1.0, 0.0, -cy, 0.0, 0.0, 0.0, f, 0.0, 0.0, 1.0 / baseline, 0.0);
        Ok(PairRectification { r_left: r1, r_right: r2, rectified, baseline, p1, p2, q })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Point3, Rotation3};

    #[test]
    fn rectified_rows_align_and_right_projection_carries_the_baseline() {
        let l = CameraModel::from_hfov(640, 480, 70.0);
        let r = CameraModel { fx: l.fx * 1.02, ..l.clone() };
        let t_lr = Pose::from_parts(Rotation3::from_euler_angles(0.01, -0.03, 0.02), Vector3::new(0.25, 0.01, -0.004));
        let rect = PairRectification::new(&l, &r, &t_lr).unwrap();
        assert!((rect.baseline - t_lr.translation().norm()).abs() < 1e-15);
        assert_eq!(rect.rectified.fx, l.fx);
        // A point seen by both cameras: P1, P2 project it from the stereo frame (R1 p_left) to
        // the same rectified row, disparity f·B/Z, and P2 agrees with the right camera's own
        // rectified ray R2 p_right.
        let p_left = Point3::new(0.3, -0.2, 3.0);
        let p_right = t_lr.inverse().transform_point(&p_left);
        let stereo = (rect.r_left * p_left.coords).push(1.0);
        let (a, b) = (rect.p1 * stereo, rect.p2 * stereo);
        let (ua, va, ub, vb) = (a.x / a.z, a.y / a.z, b.x / b.z, b.y / b.z);
        assert!((va - vb).abs() < 1e-9, "{va} {vb}");
        assert!(((ua - ub) - rect.rectified.fx * rect.baseline / stereo.z).abs() < 1e-9);
        let own = rect.rectified.project(&Point3::from(rect.r_right * p_right.coords)).unwrap();
        assert!((own.x - ub).abs() < 1e-9 && (own.y - vb).abs() < 1e-9, "{own:?} vs ({ub}, {vb})");
        let e = PairRectification::new(&l, &r, &Pose::identity()).unwrap_err().to_string();
        assert!(e.contains("zero baseline"), "{e}");
    }
}
