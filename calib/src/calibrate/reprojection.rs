//! The reprojection residual of one target corner seen by one rig camera, with its analytic
//! Jacobian for the bundle adjustment.
//!
//! Parameter blocks, in order: intrinsics `[fx, fy, cx, cy, k1, k2, p1, p2]` (pixels,
//! dimensionless), `[k3]`, `T_cam_ref` and `T_ref_board` as pose vectors `[ω (rad), t (m)]`
//! with left updates (`R ← exp(δω)·R`, `t ← t + δt`). Residual: projected minus observed
//! pixel (OpenCV model, [`crate::geometry::project_cam`]).

use nalgebra::{Matrix2x3, Matrix3, Point2, Rotation3, Vector3};

/// Number of Jacobian columns: 8 intrinsics, k3, 6 extrinsic, 6 board pose.
pub(crate) const COLUMNS: usize = 21;

fn rotation(v: &[f64]) -> Rotation3<f64> {
    Rotation3::new(Vector3::new(v[0], v[1], v[2]))
}

fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

fn intrinsics(b: &[&[f64]]) -> [f64; 9] {
    let mut k = [0.0; 9];
    k[..8].copy_from_slice(&b[0][..8]);
    k[8] = b[1][0];
    k
}

/// Residual of board point `x` (board frame, m) observed at pixel `u`; `false` behind the camera.
pub(crate) fn residual(b: &[&[f64]], x: &Vector3<f64>, u: &Point2<f64>, r: &mut [f64]) -> bool {
    let pr = rotation(b[3]) * x + Vector3::new(b[3][3], b[3][4], b[3][5]);
    let pc = rotation(b[2]) * pr + Vector3::new(b[2][3], b[2][4], b[2][5]);
    match crate::geometry::project_cam(&intrinsics(b), &pc) {
        Some(q) => {
            r[0] = q.x - u.x;
            r[1] = q.y - u.y;
            true
        }
        None => false,
    }
}

/// [`residual`] and its Jacobian, row-major 2 x [`COLUMNS`].
pub(crate) fn residual_and_jacobian(b: &[&[f64]], x: &Vector3<f64>, u: &Point2<f64>, r: &mut [f64], j: &mut [f64]) -> bool {
    let k = intrinsics(b);
    let (re, rp) = (rotation(b[2]), rotation(b[3]));
    let rpx = rp * x;
    let pr = rpx + Vector3::new(b[3][3], b[3][4], b[3][5]);
    let q = re * pr;
    let pc = q + Vector3::new(b[2][3], b[2][4], b[2][5]);
    if pc.z <= 1e-9 {
        return false;
    }
    let iz = 1.0 / pc.z;
    let (xn, yn) = (pc.x * iz, pc.y * iz);
    let r2 = xn * xn + yn * yn;
    let radial = 1.0 + r2 * (k[4] + r2 * (k[5] + r2 * k[8]));
    let dradial = k[4] + r2 * (2.0 * k[5] + 3.0 * r2 * k[8]);
    let xd = xn * radial + 2.0 * k[6] * xn * yn + k[7] * (r2 + 2.0 * xn * xn);
    let yd = yn * radial + k[6] * (r2 + 2.0 * yn * yn) + 2.0 * k[7] * xn * yn;
    r[0] = k[0] * xd + k[2] - u.x;
    r[1] = k[1] * yd + k[3] - u.y;
    // d(xd, yd) / d(xn, yn).
    let dxx = radial + 2.0 * xn * xn * dradial + 2.0 * k[6] * yn + 6.0 * k[7] * xn;
    let dxy = 2.0 * xn * yn * dradial + 2.0 * k[6] * xn + 2.0 * k[7] * yn;
    let dyx = 2.0 * xn * yn * dradial + 2.0 * k[6] * xn + 2.0 * k[7] * yn;
    let dyy = radial + 2.0 * yn * yn * dradial + 6.0 * k[6] * yn + 2.0 * k[7] * xn;
    // d(u, v) / d(pc) = diag(fx, fy) · d(xd, yd)/d(xn, yn) · d(xn, yn)/d(pc).
    let dn = Matrix2x3::new(iz, 0.0, -xn * iz, 0.0, iz, -yn * iz);
    let dd = nalgebra::Matrix2::new(k[0] * dxx, k[0] * dxy, k[1] * dyx, k[1] * dyy);
    let dp = dd * dn;
    let rows = [
        // fx, fy, cx, cy, k1, k2, p1, p2, k3
        [xd, 0.0, 1.0, 0.0, k[0] * xn * r2, k[0] * xn * r2 * r2, k[0] * 2.0 * xn * yn, k[0] * (r2 + 2.0 * xn * xn), k[0] * xn * r2 * r2 * r2],
        [0.0, yd, 0.0, 1.0, k[1] * yn * r2, k[1] * yn * r2 * r2, k[1] * (r2 + 2.0 * yn * yn), k[1] * 2.0 * xn * yn, k[1] * yn * r2 * r2 * r2],
    ];
    // Extrinsic: d pc / d[δω, δt] = [−[q]×, I]; board pose: [−R_e·[R_p x]×, R_e].
    let d_ext_w = dp * -skew(&q);
    let re_m = re.matrix();
    let d_pose_w = dp * (-re_m * skew(&rpx));
    let d_pose_t = dp * re_m;
    for row in 0..2 {
        let o = row * COLUMNS;
        j[o..o + 9].copy_from_slice(&rows[row]);
        for c in 0..3 {
            j[o + 9 + c] = d_ext_w[(row, c)];
            j[o + 12 + c] = dp[(row, c)];
            j[o + 15 + c] = d_pose_w[(row, c)];
            j[o + 18 + c] = d_pose_t[(row, c)];
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lm::{plus, BlockKind};

    #[test]
    fn analytic_jacobian_matches_central_differences() {
        let intr = vec![820.0, 815.0, 322.0, 241.0, -0.21, 0.09, 0.0012, -0.0007];
        let k3 = vec![-0.015];
        let ext = vec![0.05, -0.12, 0.03, -0.12, 0.01, 0.02];
        let pose = vec![0.3, -0.2, 0.15, 0.05, -0.03, 1.2];
        let x = Vector3::new(0.07, -0.04, 0.0);
        let u = Point2::new(300.0, 250.0);
        let blocks = [intr, k3, ext, pose];
        let kinds = [BlockKind::Euclidean, BlockKind::Euclidean, BlockKind::Pose, BlockKind::Pose];
        let views: Vec<&[f64]> = blocks.iter().map(|v| v.as_slice()).collect();
        let (mut r, mut j) = ([0.0; 2], [0.0; 2 * COLUMNS]);
        assert!(residual_and_jacobian(&views, &x, &u, &mut r, &mut j));
        let mut r0 = [0.0; 2];
        assert!(residual(&views, &x, &u, &mut r0));
        assert!((r[0] - r0[0]).abs() < 1e-12 && (r[1] - r0[1]).abs() < 1e-12);
        let mut col = 0;
        for (bi, blk) in blocks.iter().enumerate() {
            for i in 0..blk.len() {
                let step = if kinds[bi] == BlockKind::Pose { 1e-7 } else { 1e-6 * blk[i].abs().max(1.0) };
                let eval = |s: f64| {
                    let mut d = vec![0.0; blk.len()];
                    d[i] = s;
                    let mut moved = blk.clone();
                    plus(kinds[bi], blk, &d, &mut moved);
                    let mut bs: Vec<&[f64]> = views.clone();
                    bs[bi] = &moved;
                    let mut rr = [0.0; 2];
                    assert!(residual(&bs, &x, &u, &mut rr));
                    rr
                };
                let (rp, rm) = (eval(step), eval(-step));
                for row in 0..2 {
                    let numeric = (rp[row] - rm[row]) / (2.0 * step);
                    let analytic = j[row * COLUMNS + col];
                    assert!((numeric - analytic).abs() < 1e-5 * numeric.abs().max(1.0), "column {col} row {row}: numeric {numeric} analytic {analytic}");
                }
                col += 1;
            }
        }
        assert_eq!(col, COLUMNS);
    }
}
