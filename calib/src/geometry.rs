//! Projective geometry used by calibration and tag poses: projection with a 9-vector of
//! intrinsics, homography DLT, pose from a plane homography, Zhang's closed form, averaging.
//!
//! Intrinsics vector `k = [fx, fy, cx, cy, k1, k2, p1, p2, k3]` (pixels, dimensionless);
//! pose vector `[ω, t]`: rotation vector (rad) and translation (m) of `T_cam_obj`.

use crate::error::CalibError;
use nalgebra::{DMatrix, Matrix3, Point2, Point3, Rotation3, Vector3};
use tubeloc_core::{CameraModel, Distortion, Pose};

/// Intrinsics of a camera model as `[fx, fy, cx, cy, k1, k2, p1, p2, k3]`.
pub fn intrinsics_vec(m: &CameraModel) -> [f64; 9] {
    let d = &m.distortion;
    [m.fx, m.fy, m.cx, m.cy, d.k1, d.k2, d.p1, d.p2, d.k3]
}

/// A camera model of size `width x height` from an intrinsics vector.
pub fn model_from_vec(width: u32, height: u32, k: &[f64]) -> CameraModel {
    CameraModel { width, height, fx: k[0], fy: k[1], cx: k[2], cy: k[3], distortion: Distortion { k1: k[4], k2: k[5], p1: k[6], p2: k[7], k3: k[8] } }
}

/// The pose vector `[ω, t]` of a pose.
pub fn pose_vec(p: &Pose) -> [f64; 6] {
    let w = p.0.rotation.scaled_axis();
    let t = p.translation();
    [w.x, w.y, w.z, t.x, t.y, t.z]
}

/// The pose of a pose vector `[ω, t]`.
pub fn pose_from_vec(v: &[f64]) -> Pose {
    Pose::from_parts(Rotation3::new(Vector3::new(v[0], v[1], v[2])), Vector3::new(v[3], v[4], v[5]))
}

/// Projects object point `x` through pose vector `pose` (`T_cam_obj`) and intrinsics `k`;
/// `None` behind the camera.
#[inline]
pub fn project(k: &[f64], pose: &[f64], x: &Point3<f64>) -> Option<Point2<f64>> {
    let r = Rotation3::new(Vector3::new(pose[0], pose[1], pose[2]));
    let p = r * x.coords + Vector3::new(pose[3], pose[4], pose[5]);
    project_cam(k, &p)
}

/// Projects a camera-frame point with intrinsics `k`; `None` behind the camera.
#[inline]
pub fn project_cam(k: &[f64], p: &Vector3<f64>) -> Option<Point2<f64>> {
    if p.z <= 1e-9 {
        return None;
    }
    let (x, y) = (p.x / p.z, p.y / p.z);
    let r2 = x * x + y * y;
    let radial = 1.0 + r2 * (k[4] + r2 * (k[5] + r2 * k[8]));
    let xd = x * radial + 2.0 * k[6] * x * y + k[7] * (r2 + 2.0 * x * x);
    let yd = y * radial + k[6] * (r2 + 2.0 * y * y) + 2.0 * k[7] * x * y;
    Some(Point2::new(k[0] * xd + k[2], k[1] * yd + k[3]))
}

fn normalizer(pts: &[Point2<f64>]) -> Matrix3<f64> {
    let n = pts.len() as f64;
    let (mx, my) = pts.iter().fold((0.0, 0.0), |(a, b), p| (a + p.x / n, b + p.y / n));
    let d = pts.iter().map(|p| ((p.x - mx).powi(2) + (p.y - my).powi(2)).sqrt()).sum::<f64>() / n;
    let s = if d > 0.0 { std::f64::consts::SQRT_2 / d } else { 1.0 };
    Matrix3::new(s, 0.0, -s * mx, 0.0, s, -s * my, 0.0, 0.0, 1.0)
}

/// Checks that 2D points span a plane region: at least 4 points and the smaller principal
/// spread at least `1e-3` of the larger (else they are collinear).
pub fn check_spread(pts: &[Point2<f64>], what: &str) -> Result<(), CalibError> {
    if pts.len() < 4 {
        return Err(CalibError::TooFew(format!("{what}: {} points, need at least 4", pts.len())));
    }
    let n = pts.len() as f64;
    let (mx, my) = pts.iter().fold((0.0, 0.0), |(a, b), p| (a + p.x / n, b + p.y / n));
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    for p in pts {
        let (dx, dy) = (p.x - mx, p.y - my);
        sxx += dx * dx;
        sxy += dx * dy;
        syy += dy * dy;
    }
    let tr = sxx + syy;
    let disc = ((sxx - syy).powi(2) + 4.0 * sxy * sxy).sqrt();
    let (l1, l2) = ((tr + disc) / 2.0, (tr - disc) / 2.0);
    if l1 <= 0.0 || l2 / l1 < 1e-6 {
        return Err(CalibError::Degenerate(format!("{what}: points are collinear (spread ratio {:.1e})", if l1 > 0.0 { (l2 / l1).max(0.0).sqrt() } else { 0.0 })));
    }
    Ok(())
}

/// Homography `H` with `dst ~ H·src`, by the normalized DLT over ≥ 4 correspondences.
pub fn homography(src: &[Point2<f64>], dst: &[Point2<f64>]) -> Result<Matrix3<f64>, CalibError> {
    check_spread(src, "homography source")?;
    check_spread(dst, "homography image")?;
    let (ts, td) = (normalizer(src), normalizer(dst));
    let mut a = DMatrix::<f64>::zeros(2 * src.len(), 9);
    for (i, (s, d)) in src.iter().zip(dst).enumerate() {
        let s = ts * Vector3::new(s.x, s.y, 1.0);
        let d = td * Vector3::new(d.x, d.y, 1.0);
        let (x, y, u, v) = (s.x / s.z, s.y / s.z, d.x / d.z, d.y / d.z);
        let r0 = [-x, -y, -1.0, 0.0, 0.0, 0.0, u * x, u * y, u];
        let r1 = [0.0, 0.0, 0.0, -x, -y, -1.0, v * x, v * y, v];
        for j in 0..9 {
            a[(2 * i, j)] = r0[j];
            a[(2 * i + 1, j)] = r1[j];
        }
    }
    let ata = a.transpose() * &a;
    let eig = ata.symmetric_eigen();
    let (imin, _) = eig.eigenvalues.iter().enumerate().fold((0, f64::INFINITY), |(bi, bv), (i, &v)| if v < bv { (i, v) } else { (bi, bv) });
    let h = eig.eigenvectors.column(imin);
    let hn = Matrix3::new(h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], h[8]);
    let tdi = td.try_inverse().ok_or_else(|| CalibError::Degenerate("homography normalization".into()))?;
    let hm = tdi * hn * ts;
    let s = hm[(2, 2)];
    let hm = if s.abs() > 1e-12 { hm / s } else { hm / hm.norm() };
    if !hm.iter().all(|v| v.is_finite()) {
        return Err(CalibError::Degenerate("homography is not finite".into()));
    }
    Ok(hm)
}

/// Nearest rotation (Frobenius) to a 3x3 matrix, via SVD, with det +1.
pub fn nearest_rotation(m: &Matrix3<f64>) -> Rotation3<f64> {
    let svd = m.svd(true, true);
    let (u, vt) = (svd.u.expect("u"), svd.v_t.expect("v_t"));
    let mut d = Matrix3::identity();
    if (u * vt).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    Rotation3::from_matrix_unchecked(u * d * vt)
}

/// `T_cam_plane` from a homography mapping plane `(x, y)` (metres) to normalized image
/// coordinates (`K = I`): `[r1 r2 t] ∝ H`, sign chosen so the plane is in front (t.z > 0).
pub fn pose_from_homography(h: &Matrix3<f64>) -> Result<Pose, CalibError> {
    let (h1, h2, h3) = (h.column(0).into_owned(), h.column(1).into_owned(), h.column(2).into_owned());
    let s = 2.0 / (h1.norm() + h2.norm());
    if !s.is_finite() {
        return Err(CalibError::Degenerate("homography has a zero column".into()));
    }
    let s = if h3.z * s < 0.0 { -s } else { s };
    let (r1, r2, t) = (h1 * s, h2 * s, h3 * s);
    let r = nearest_rotation(&Matrix3::from_columns(&[r1, r2, r1.cross(&r2)]));
    Ok(Pose::from_parts(r, t))
}

/// Zhang's closed-form intrinsics (zero skew) from plane-to-pixel homographies of ≥ 3 views:
/// `h_iᵀ B h_j` constraints on `B = K⁻ᵀK⁻¹`. Returns `[fx, fy, cx, cy]`.
pub fn zhang_intrinsics(hs: &[Matrix3<f64>]) -> Result<[f64; 4], CalibError> {
    if hs.len() < 3 {
        return Err(CalibError::TooFew(format!("{} views for Zhang's initialization, need at least 3", hs.len())));
    }
    let v = |h: &Matrix3<f64>, i: usize, j: usize| -> [f64; 6] {
        let (a, b) = (h.column(i), h.column(j));
        [a[0] * b[0], a[0] * b[1] + a[1] * b[0], a[1] * b[1], a[2] * b[0] + a[0] * b[2], a[2] * b[1] + a[1] * b[2], a[2] * b[2]]
    };
    let mut m = DMatrix::<f64>::zeros(2 * hs.len() + 1, 6);
    for (k, h) in hs.iter().enumerate() {
        let h = h / h.norm();
        let v12 = v(&h, 0, 1);
        let (v11, v22) = (v(&h, 0, 0), v(&h, 1, 1));
        for j in 0..6 {
            m[(2 * k, j)] = v12[j];
            m[(2 * k + 1, j)] = v11[j] - v22[j];
        }
    }
    // Zero skew: B12 = 0 (weighted strongly).
    m[(2 * hs.len(), 1)] = 1e3;
    let eig = (m.transpose() * &m).symmetric_eigen();
    let (imin, _) = eig.eigenvalues.iter().enumerate().fold((0, f64::INFINITY), |(bi, bv), (i, &x)| if x < bv { (i, x) } else { (bi, bv) });
    let b = eig.eigenvectors.column(imin);
    let (b11, b12, b22, b13, b23, b33) = (b[0], b[1], b[2], b[3], b[4], b[5]);
    let den = b11 * b22 - b12 * b12;
    let v0 = (b12 * b13 - b11 * b23) / den;
    let lambda = b33 - (b13 * b13 + v0 * (b12 * b13 - b11 * b23)) / b11;
    let alpha = (lambda / b11).sqrt();
    let beta = (lambda * b11 / den).sqrt();
    let u0 = -b13 * alpha * alpha / lambda;
    let k = [alpha, beta, u0, v0];
    if k.iter().all(|x| x.is_finite()) && alpha > 0.0 && beta > 0.0 {
        Ok(k)
    } else {
        Err(CalibError::Degenerate("Zhang's closed form has no positive-definite solution (views too similar or too few tilted views)".into()))
    }
}

/// Chordal L2 mean of poses: rotation = nearest rotation to the mean matrix, mean translation.
pub fn average_poses(poses: &[Pose]) -> Option<Pose> {
    if poses.is_empty() {
        return None;
    }
    let n = poses.len() as f64;
    let mut m = Matrix3::zeros();
    let mut t = Vector3::zeros();
    for p in poses {
        m += p.rotation() / n;
        t += p.translation() / n;
    }
    Some(Pose::from_parts(nearest_rotation(&m), t))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn homography_and_pose_round_trip() {
        let pose = Pose::from_parts(Rotation3::from_euler_angles(0.3, -0.2, 0.1), Vector3::new(0.1, -0.05, 1.5));
        let src: Vec<Point2<f64>> = (0..12).map(|i| Point2::new((i % 4) as f64 * 0.1, (i / 4) as f64 * 0.1)).collect();
        let dst: Vec<Point2<f64>> = src
            .iter()
            .map(|s| {
                let p = pose.transform_point(&Point3::new(s.x, s.y, 0.0));
                Point2::new(p.x / p.z, p.y / p.z)
            })
            .collect();
        let h = homography(&src, &dst).unwrap();
        let back = pose_from_homography(&h).unwrap();
        let (a, d) = back.distance(&pose);
        assert!(a < 1e-9 && d < 1e-9, "{a} {d}");
        let line: Vec<Point2<f64>> = (0..6).map(|i| Point2::new(i as f64, 2.0 * i as f64)).collect();
        let err = homography(&line, &line).unwrap_err().to_string();
        assert!(err.contains("collinear"), "{err}");
    }
}
