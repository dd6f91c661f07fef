//! JPL's CAHV and CAHVOR camera models, and the pinhole camera a CAHV model is.
//!
//! CAHV (Yakimovsky and Cunningham, 1978) holds the camera centre `C` (metres), the unit
//! optical axis `A`, and the horizontal and vertical vectors `H`, `V` (pixels) in a reference
//! frame. A point `P` images at
//!
//! ```text
//! x = (P - C)·H / (P - C)·A      (column)
//! y = (P - C)·V / (P - C)·A      (row; the centre of the first pixel is (0, 0))
//! ```
//!
//! CAHVOR (Gennery) first moves `p = P - C` radially about the axis `O`:
//! `ω = p·O`, `λ = p - ω O`, `τ = λ·λ / ω²`, `μ = R0 + R1 τ + R2 τ²`, `p' = p + μ λ`.
//!
//! A CAHV model is a pinhole camera (`x ~ K R (P - C)`): with `hc = A·H`, `vc = A·V`,
//! `hs = |A × H|`, `vs = |A × V|`, `H' = (H - hc A) / hs`, `V' = (V - vc A) / vs`, the rows
//! `[H'; V'; A] = T R` (RQ: `T` upper triangular, `R` a rotation) give
//! `K = [[hs, 0, hc], [0, vs, vc], [0, 0, 1]] T` (scaled to `K33 = 1`).

use nalgebra::{Matrix3, Vector3};

/// A CAHV camera model in its reference frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cahv {
    /// Camera centre (m).
    pub c: Vector3<f64>,
    /// Optical axis (unit).
    pub a: Vector3<f64>,
    /// Horizontal vector (px).
    pub h: Vector3<f64>,
    /// Vertical vector (px).
    pub v: Vector3<f64>,
}

/// A CAHVOR camera model: CAHV and a radial distortion about the axis `o`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cahvor {
    /// The linear part.
    pub cahv: Cahv,
    /// The distortion's axis (unit).
    pub o: Vector3<f64>,
    /// The radial coefficients `R0, R1, R2`.
    pub r: [f64; 3],
}

/// The pinhole camera of a CAHV model: `x ~ K R (P - C)`, camera frame x right, y down,
/// z along the optical axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinearCamera {
    /// Focal lengths (px).
    pub fx: f64,
    /// See `fx`.
    pub fy: f64,
    /// Principal point (px, the centre of the first pixel at (0, 0)).
    pub cx: f64,
    /// See `cx`.
    pub cy: f64,
    /// `K12` (px): how far from perpendicular `H'` and `V'` are.
    pub skew: f64,
    /// Rotation taking reference-frame vectors into the camera frame.
    pub r_cam_from_ref: Matrix3<f64>,
    /// Camera centre in the reference frame (m).
    pub centre: Vector3<f64>,
}

impl Cahv {
    /// The image of the reference-frame point `p` (column, row), `None` behind the camera.
    pub fn project(&self, p: &Vector3<f64>) -> Option<(f64, f64)> {
        project_offset(&(p - self.c), self)
    }

    /// The pinhole camera this model is; `Err` when the vectors are degenerate or describe a
    /// mirrored image.
    pub fn linearize(&self) -> Result<LinearCamera, String> {
        let na = self.a.norm();
        if !na.is_finite() || na <= 0.0 {
            return Err("the axis A is zero or not finite".into());
        }
        // x = p·H / p·A does not change when A, H and V are scaled together.
        let (a, h, v) = (self.a / na, self.h / na, self.v / na);
        let (hc, vc) = (a.dot(&h), a.dot(&v));
        let (hs, vs) = (a.cross(&h).norm(), a.cross(&v).norm());
        // Parallel to the axis, to rounding: no horizontal or vertical scale.
        if hs.is_nan() || vs.is_nan() || hs <= 1e-9 * h.norm() || vs <= 1e-9 * v.norm() {
            return Err("H or V is parallel to the axis A".into());
        }
        let rows = [(h - hc * a) / hs, (v - vc * a) / vs, a];
        // RQ by Gram-Schmidt from the last row: r3 = A, r2 = V' without its A part, r1 = H'
        // without its A and r2 parts; T = M R^T is then upper triangular, its diagonal > 0.
        let r3 = rows[2];
        let r2 = rows[1] - rows[1].dot(&r3) * r3;
        let r2 = r2.try_normalize(1e-12).ok_or("V is parallel to the axis A")?;
        let r1 = rows[0] - rows[0].dot(&r3) * r3 - rows[0].dot(&r2) * r2;
        let r1 = r1.try_normalize(1e-12).ok_or("H lies in the plane of A and V")?;
        if r1.cross(&r2).dot(&r3) < 0.0 {
            return Err("H, V and A make a mirrored (left-handed) camera".into());
        }
        let r = Matrix3::from_rows(&[r1.transpose(), r2.transpose(), r3.transpose()]);
        let m = Matrix3::from_rows(&[rows[0].transpose(), rows[1].transpose(), rows[2].transpose()]);
        let t = m * r.transpose();
        let k = Matrix3::new(hs, 0.0, hc, 0.0, vs, vc, 0.0, 0.0, 1.0) * t;
        let k = k / k[(2, 2)];
        Ok(LinearCamera { fx: k[(0, 0)], fy: k[(1, 1)], cx: k[(0, 2)], cy: k[(1, 2)], skew: k[(0, 1)], r_cam_from_ref: r, centre: self.c })
    }
}

impl Cahvor {
    /// The image of the reference-frame point `p` (column, row), `None` behind the camera.
    pub fn project(&self, p: &Vector3<f64>) -> Option<(f64, f64)> {
        let d = p - self.cahv.c;
        let omega = d.dot(&self.o);
        if omega <= 0.0 {
            return None;
        }
        let lambda = d - omega * self.o;
        let tau = lambda.norm_squared() / (omega * omega);
        let mu = self.r[0] + self.r[1] * tau + self.r[2] * tau * tau;
        project_offset(&(d + mu * lambda), &self.cahv)
    }
}

impl LinearCamera {
    /// The image of the reference-frame point `p` (column, row), skew included; `None` behind
    /// the camera.
    pub fn project(&self, p: &Vector3<f64>) -> Option<(f64, f64)> {
        let q = self.r_cam_from_ref * (p - self.centre);
        (q.z > 0.0).then(|| (self.fx * q.x / q.z + self.skew * q.y / q.z + self.cx, self.fy * q.y / q.z + self.cy))
    }
}

fn project_offset(d: &Vector3<f64>, m: &Cahv) -> Option<(f64, f64)> {
    let z = d.dot(&m.a);
    (z > 0.0).then(|| (d.dot(&m.h) / z, d.dot(&m.v) / z))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The CAHV model of a Navcam-like camera: 1024 px, f 1220 px, looking forward and down,
    /// with a little skew, and A scaled away from unit length.
    fn navcam() -> Cahv {
        let a = Vector3::new(0.82, -0.5, 0.26).normalize();
        let right = Vector3::new(0.0, 0.0, 1.0).cross(&a).normalize();
        let down = a.cross(&right);
        let (f, cx, cy) = (1221.0, 512.3, 509.8);
        let h = f * right + 0.002 * f * down + cx * a;
        let v = 1218.0 * down + cy * a;
        Cahv { c: Vector3::new(0.8, 0.3, -1.95), a: 2.0 * a, h: 2.0 * h, v: 2.0 * v }
    }

    #[test]
    fn the_linearized_pinhole_projects_like_the_cahv_model() {
        let m = navcam();
        let lin = m.linearize().unwrap();
        assert!((lin.fx - 1221.0).abs() < 0.01 && (lin.fy - 1218.0).abs() < 0.01, "{lin:?}");
        assert!((lin.cx - 512.3).abs() < 1e-9 && (lin.cy - 509.8).abs() < 1e-9, "{lin:?}");
        assert!((lin.r_cam_from_ref.determinant() - 1.0).abs() < 1e-12);
        assert!((lin.r_cam_from_ref * lin.r_cam_from_ref.transpose() - Matrix3::identity()).norm() < 1e-12);
        let mut worst: f64 = 0.0;
        for i in 0..50 {
            let s = i as f64;
            let p = m.c + 3.0 * m.a.normalize() + Vector3::new((s * 0.37).sin(), (s * 0.91).cos(), (s * 0.13).sin());
            let (x0, y0) = m.project(&p).unwrap();
            let (x1, y1) = lin.project(&p).unwrap();
            worst = worst.max((x0 - x1).abs()).max((y0 - y1).abs());
        }
        assert!(worst < 1e-8, "largest difference {worst} px");
        assert!(lin.project(&(m.c - m.a)).is_none() && m.project(&(m.c - m.a)).is_none());
    }

    #[test]
    fn cahvor_with_zero_coefficients_is_its_cahv_and_bends_outward_points_by_r() {
        let cahv = navcam();
        let a = cahv.a.normalize();
        let p = cahv.c + 3.0 * a + Vector3::new(0.4, 0.9, -0.2);
        let flat = Cahvor { cahv, o: a, r: [0.0; 3] };
        assert_eq!(flat.project(&p), cahv.project(&p));
        // R0 = 0.01 scales every ray's off-axis part by 1.01 about O = A: the image point moves
        // 1 % farther from the principal point.
        let bent = Cahvor { r: [0.01, 0.0, 0.0], ..flat };
        let lin = cahv.linearize().unwrap();
        let (x0, y0) = cahv.project(&p).unwrap();
        let (x1, y1) = bent.project(&p).unwrap();
        let (dx0, dy0) = (x0 - lin.cx, y0 - lin.cy);
        assert!((x1 - lin.cx - 1.01 * dx0).abs() < 1e-6 && (y1 - lin.cy - 1.01 * dy0).abs() < 1e-6);
    }

    #[test]
    fn degenerate_and_mirrored_models_are_refused() {
        let m = navcam();
        assert!(Cahv { a: Vector3::zeros(), ..m }.linearize().unwrap_err().contains("axis A is zero"));
        assert!(Cahv { h: m.a * 500.0, ..m }.linearize().unwrap_err().contains("parallel"));
        assert!(Cahv { h: -m.h + 2.0 * m.a.dot(&m.h) / m.a.norm_squared() * m.a, ..m }.linearize().unwrap_err().contains("mirrored"));
    }
}
