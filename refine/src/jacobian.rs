//! Cheap Jacobians of the fit residuals with respect to θ = (c, δ1, δ2).
//!
//! Image residuals `r = n · π(X(θ)) / σ` are differentiated by the chain rule
//! `∂r/∂θ = nᵀ (∂π/∂X) (∂X/∂θ) / σ`:
//! - `∂π/∂X` is analytic (pinhole with OpenCV distortion):
//!   `∂u/∂X = diag(fx, fy) · D(x, y) · [[1/Z, 0, -x/Z], [0, 1/Z, -y/Z]]`, `x = X/Z`, `y = Y/Z`,
//!   `D` the 2x2 Jacobian of the distortion ([`tubeloc_core::camera::Distortion::jacobian`]).
//! - `∂X/∂θ` from the derivatives of the axis frame (central differences over the ten
//!   perturbed states, once per iteration), in which each contour point is linear
//!   ([`ContourSample::point_derivative`]; no projection, no allocation per sample).
//!
//! Stereo residuals `s = (ρ - R(z)) / σ_s` (see [`crate::fit`]) are analytic:
//! `∂ρ/∂c = -p̂ᵀ`, `∂ρ/∂δk = -z (p̂ · u_k)` with `p̂` the unit radial vector of the point;
//! the ground priors are linear: `∂g1/∂c = nᵀ/σ_g`, `∂g2/∂δk = (n · u_k)/σ_t`.

use crate::contour::{AxisFrame, AxisState, ContourSample, FrameDerivative};
use crate::model::CylinderModel;
use nalgebra::{Matrix2x3, Matrix2x5, Point3, Vector3};
use tubeloc_core::CameraModel;

/// Step of the central differences of `∂X/∂θ` (metres for `c`, radians for `δ`).
const STEP: f64 = 1e-6;

/// Analytic `∂u/∂X` (pixels per metre) at a camera-frame point; `None` at or behind the camera.
#[inline]
pub fn projection_jacobian(cam: &CameraModel, p: &Point3<f64>) -> Option<Matrix2x3<f64>> {
    if p.z <= 1e-9 {
        return None;
    }
    let iz = 1.0 / p.z;
    let (x, y) = (p.x * iz, p.y * iz);
    let d = cam.distortion.jacobian(x, y);
    let (a00, a01, a10, a11) = (cam.fx * d[0], cam.fx * d[1], cam.fy * d[2], cam.fy * d[3]);
    Some(Matrix2x3::new(a00 * iz, a01 * iz, -(a00 * x + a01 * y) * iz, a10 * iz, a11 * iz, -(a10 * x + a11 * y) * iz))
}

/// The derivatives of the axis frame at `st` along the five parameters θ in the basis
/// `(u1, u2)`, by central differences of the frames of the ten states `θ ± STEP e_k`,
/// computed once per iteration; each sample's `∂X/∂θ` follows from them
/// ([`ContourSample::point_derivative`]) without evaluating it at the ten states.
pub struct FrameDerivatives {
    /// The frame at θ.
    base: AxisFrame,
    /// `∂frame/∂θ_k`.
    deriv: [FrameDerivative; 5],
}

impl FrameDerivatives {
    /// `None` when the state or a perturbed state has no frame (camera on the axis line).
    pub fn new(st: &AxisState, u1: &Vector3<f64>, u2: &Vector3<f64>) -> Option<Self> {
        let base = st.frame()?;
        let mut deriv = [base; 5];
        for (k, dk) in deriv.iter_mut().enumerate() {
            let mut d = [0.0; 5];
            d[k] = STEP;
            let plus = st.updated(&d, u1, u2).frame()?;
            d[k] = -STEP;
            let minus = st.updated(&d, u1, u2).frame()?;
            let h = 0.5 / STEP;
            *dk = FrameDerivative { c: (plus.c - minus.c) * h, a: (plus.a - minus.a) * h, e1: (plus.e1 - minus.e1) * h, e2: (plus.e2 - minus.e2) * h, d: (plus.d - minus.d) * h };
        }
        Some(FrameDerivatives { base, deriv })
    }

    /// The frame at θ.
    pub fn base(&self) -> &AxisFrame {
        &self.base
    }

    /// Image Jacobian `∂u/∂θ` (2x5, level pixels per unit of θ) of one contour sample whose
    /// current 3D point is `x`; `None` when the sample or its projection is undefined.
    #[inline]
    pub fn image_jacobian(&self, model: &CylinderModel, s: &ContourSample, cam: &CameraModel, x: &Point3<f64>) -> Option<Matrix2x5<f64>> {
        let pj = projection_jacobian(cam, x)?;
        let mut j = Matrix2x5::zeros();
        for (k, df) in self.deriv.iter().enumerate() {
            let col = pj * s.point_derivative(model, &self.base, df)?;
            j[(0, k)] = col.x;
            j[(1, k)] = col.y;
        }
        Some(j)
    }
}

/// Gradient row `∂s/∂θ` (before the `1/σ_s` normalization) of the stereo residual of point
/// `p` at state `st`: `ρ = |P - c - z a|`, `z = (P - c)·a`.
#[inline]
pub fn stereo_row(st: &AxisState, u1: &Vector3<f64>, u2: &Vector3<f64>, p: &Point3<f64>) -> [f64; 5] {
    let rel = p.coords - st.c;
    let z = rel.dot(&st.a);
    let perp = rel - st.a * z;
    let rho = perp.norm();
    if rho < 1e-12 {
        return [0.0; 5];
    }
    let ph = perp / rho;
    [-ph.x, -ph.y, -ph.z, -z * ph.dot(u1), -z * ph.dot(u2)]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contour::build_samples;
    use tubeloc_core::{Distortion, TubeModel};

    #[test]
    fn image_jacobian_matches_finite_differences_of_the_projection() {
        let model = CylinderModel::new(&TubeModel::default()).unwrap();
        let mut cam = CameraModel::from_hfov(1024, 768, 50.0);
        cam.distortion = Distortion { k1: -0.1, k2: 0.03, p1: 0.001, p2: -0.0005, k3: 0.0 };
        let st = AxisState { c: Vector3::new(0.1, 0.05, 0.8), a: Vector3::new(1.0, 0.2, 0.3).normalize() };
        let (u1, u2) = tubeloc_core::tube_pose::tangent_basis(&st.a);
        let pf = FrameDerivatives::new(&st, &u1, &u2).unwrap();
        let f = st.frame().unwrap();
        let samples = build_samples(&model, &st, &cam, 20.0);
        assert!(samples.len() > 10);
        for s in &samples {
            let x = s.eval(&model, &f).unwrap().x;
            let j = pf.image_jacobian(&model, s, &cam, &x).unwrap();
            for k in 0..5 {
                let h = 1e-5;
                let mut d = [0.0; 5];
                d[k] = h;
                let up = cam.project(&s.eval(&model, &st.updated(&d, &u1, &u2).frame().unwrap()).unwrap().x).unwrap();
                d[k] = -h;
                let um = cam.project(&s.eval(&model, &st.updated(&d, &u1, &u2).frame().unwrap()).unwrap().x).unwrap();
                let fd = (up - um) / (2.0 * h);
                let scale = fd.norm().max(1.0);
                assert!((fd.x - j[(0, k)]).abs() < 1e-4 * scale && (fd.y - j[(1, k)]).abs() < 1e-4 * scale, "k {k}: {fd:?} vs {:?}", j.column(k));
            }
        }
    }

    #[test]
    fn stereo_row_matches_finite_differences() {
        let st = AxisState { c: Vector3::new(0.1, 0.05, 0.8), a: Vector3::new(1.0, 0.2, 0.3).normalize() };
        let (u1, u2) = tubeloc_core::tube_pose::tangent_basis(&st.a);
        let p = Point3::new(0.13, 0.04, 0.79);
        let rho = |s: &AxisState| {
            let rel = p.coords - s.c;
            (rel - s.a * rel.dot(&s.a)).norm()
        };
        let row = stereo_row(&st, &u1, &u2, &p);
        for (k, rk) in row.iter().enumerate() {
            let h = 1e-6;
            let mut d = [0.0; 5];
            d[k] = h;
            let a = rho(&st.updated(&d, &u1, &u2));
            d[k] = -h;
            let b = rho(&st.updated(&d, &u1, &u2));
            assert!(((a - b) / (2.0 * h) - rk).abs() < 1e-6, "k {k}");
        }
    }
}
