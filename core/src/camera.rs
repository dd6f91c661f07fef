//! Pinhole camera with OpenCV's radial-tangential ("plumb bob") distortion.
//!
//! A point `p = (X, Y, Z)` in the camera frame (OpenCV: x right, y down, z forward) projects to
//! normalized coordinates `x = X/Z, y = Y/Z`, is distorted with
//!
//! ```text
//! r² = x² + y²,  radial = 1 + k1 r² + k2 r⁴ + k3 r⁶
//! x_d = x·radial + 2 p1 x y + p2 (r² + 2x²)
//! y_d = y·radial + p1 (r² + 2y²) + 2 p2 x y
//! ```
//!
//! and maps to pixels `u = fx x_d + cx, v = fy y_d + cy`, pixel centres at integer coordinates.

use crate::error::CoreError;
use nalgebra::{Point2, Point3, Vector3};
use serde::{Deserialize, Serialize};

/// OpenCV radial-tangential distortion coefficients `(k1, k2, p1, p2, k3)`, dimensionless.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Distortion {
    /// First radial coefficient.
    #[serde(default)]
    pub k1: f64,
    /// Second radial coefficient.
    #[serde(default)]
    pub k2: f64,
    /// First tangential coefficient.
    #[serde(default)]
    pub p1: f64,
    /// Second tangential coefficient.
    #[serde(default)]
    pub p2: f64,
    /// Third radial coefficient.
    #[serde(default)]
    pub k3: f64,
}

impl Distortion {
    /// True when all coefficients are zero (an ideal pinhole).
    pub fn is_zero(&self) -> bool {
        self.k1 == 0.0 && self.k2 == 0.0 && self.p1 == 0.0 && self.p2 == 0.0 && self.k3 == 0.0
    }

    /// Applies the distortion to normalized coordinates `(x, y)`.
    #[inline]
    pub fn distort(&self, x: f64, y: f64) -> (f64, f64) {
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        let xd = x * radial + 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x);
        let yd = y * radial + self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y;
        (xd, yd)
    }

    /// Inverts [`Distortion::distort`] by Gauss-Newton iterations on the 2x2 Jacobian,
    /// converging to machine precision for the moderate distortions of real lenses.
    pub fn undistort(&self, xd: f64, yd: f64) -> (f64, f64) {
        if self.is_zero() {
            return (xd, yd);
        }
        let (mut x, mut y) = (xd, yd);
        for _ in 0..30 {
            let (fx, fy) = self.distort(x, y);
            let (ex, ey) = (fx - xd, fy - yd);
            if ex.abs() < 1e-15 && ey.abs() < 1e-15 {
                break;
            }
            let j = self.jacobian(x, y);
            let det = j[0] * j[3] - j[1] * j[2];
            if det.abs() < 1e-12 {
                break;
            }
            x -= (j[3] * ex - j[1] * ey) / det;
            y -= (-j[2] * ex + j[0] * ey) / det;
        }
        (x, y)
    }

    /// Jacobian of `distort` at `(x, y)`, row-major `[dxd/dx, dxd/dy, dyd/dx, dyd/dy]`.
    pub fn jacobian(&self, x: f64, y: f64) -> [f64; 4] {
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        let drad = self.k1 + 2.0 * self.k2 * r2 + 3.0 * self.k3 * r2 * r2; // d radial / d r2
        let dxdx = radial + x * drad * 2.0 * x + 2.0 * self.p1 * y + self.p2 * 6.0 * x;
        let dxdy = x * drad * 2.0 * y + 2.0 * self.p1 * x + self.p2 * 2.0 * y;
        let dydx = y * drad * 2.0 * x + self.p1 * 2.0 * x + 2.0 * self.p2 * y;
        let dydy = radial + y * drad * 2.0 * y + self.p1 * 6.0 * y + 2.0 * self.p2 * x;
        [dxdx, dxdy, dydx, dydy]
    }
}

/// Intrinsics of one camera: image size (pixels), focal lengths and principal point (pixels),
/// and distortion. Serialized as JSON with these field names.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CameraModel {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Focal length along x, pixels.
    pub fx: f64,
    /// Focal length along y, pixels.
    pub fy: f64,
    /// Principal point x, pixels (pixel centres at integers).
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
    /// Lens distortion; zero when absent from the JSON.
    #[serde(default)]
    pub distortion: Distortion,
}

impl CameraModel {
    /// An ideal pinhole of the given size and horizontal field of view (degrees), principal
    /// point at the image centre, square pixels.
    pub fn from_hfov(width: u32, height: u32, hfov_deg: f64) -> Self {
        let fx = (width as f64 / 2.0) / (hfov_deg.to_radians() / 2.0).tan();
        CameraModel { width, height, fx, fy: fx, cx: (width as f64 - 1.0) / 2.0, cy: (height as f64 - 1.0) / 2.0, distortion: Distortion::default() }
    }

    /// Checks that sizes are non-zero and all numbers finite with positive focal lengths.
    pub fn validate(&self) -> Result<(), CoreError> {
        let d = &self.distortion;
        let nums = [self.fx, self.fy, self.cx, self.cy, d.k1, d.k2, d.p1, d.p2, d.k3];
        if self.width == 0 || self.height == 0 {
            return Err(CoreError::invalid("camera", "width and height must be positive"));
        }
        if nums.iter().any(|v| !v.is_finite()) {
            return Err(CoreError::invalid("camera", "all intrinsics must be finite numbers"));
        }
        if self.fx <= 0.0 || self.fy <= 0.0 {
            return Err(CoreError::invalid("camera", format!("focal lengths must be positive (fx={}, fy={})", self.fx, self.fy)));
        }
        Ok(())
    }

    /// Projects a point in the camera frame (metres) to pixel coordinates, with distortion.
    /// Returns `None` for points at or behind the camera plane (`Z <= 1e-9`).
    #[inline]
    pub fn project(&self, p: &Point3<f64>) -> Option<Point2<f64>> {
        if p.z <= 1e-9 {
            return None;
        }
        Some(self.project_normalized(p.x / p.z, p.y / p.z))
    }

    /// Maps undistorted normalized coordinates to pixels (applies distortion and intrinsics).
    #[inline]
    pub fn project_normalized(&self, x: f64, y: f64) -> Point2<f64> {
        let (xd, yd) = self.distortion.distort(x, y);
        Point2::new(self.fx * xd + self.cx, self.fy * yd + self.cy)
    }

    /// Undistorted normalized coordinates `(x, y)` of a pixel: the ray is `(x, y, 1)`.
    #[inline]
    pub fn normalize(&self, px: &Point2<f64>) -> (f64, f64) {
        let xd = (px.x - self.cx) / self.fx;
        let yd = (px.y - self.cy) / self.fy;
        self.distortion.undistort(xd, yd)
    }

    /// Unit ray direction in the camera frame through pixel `px`.
    pub fn unproject(&self, px: &Point2<f64>) -> Vector3<f64> {
        let (x, y) = self.normalize(px);
        Vector3::new(x, y, 1.0).normalize()
    }

    /// The 3D point at depth `z` (metres, along the optical axis) seen at pixel `px`.
    pub fn unproject_depth(&self, px: &Point2<f64>, z: f64) -> Point3<f64> {
        let (x, y) = self.normalize(px);
        Point3::new(x * z, y * z, z)
    }

    /// The same camera for an image resized by `scale` (e.g. 0.5 for half resolution),
    /// keeping pixel centres at integer coordinates: `c' = (c + 0.5) s - 0.5`.
    pub fn scaled(&self, scale: f64) -> Self {
        CameraModel {
            width: ((self.width as f64) * scale).round() as u32,
            height: ((self.height as f64) * scale).round() as u32,
            fx: self.fx * scale,
            fy: self.fy * scale,
            cx: (self.cx + 0.5) * scale - 0.5,
            cy: (self.cy + 0.5) * scale - 0.5,
            distortion: self.distortion,
        }
    }

    /// The same camera for a crop whose top-left pixel is `(x0, y0)` and size `width x height`.
    pub fn cropped(&self, x0: u32, y0: u32, width: u32, height: u32) -> Self {
        CameraModel { width, height, cx: self.cx - x0 as f64, cy: self.cy - y0 as f64, ..self.clone() }
    }

    /// True when the pixel lies inside the image (centres at integers, edges at -0.5).
    pub fn contains(&self, px: &Point2<f64>) -> bool {
        px.x >= -0.5 && px.y >= -0.5 && px.x < self.width as f64 - 0.5 && px.y < self.height as f64 - 0.5
    }

    /// Horizontal field of view in degrees (ignoring distortion).
    pub fn hfov_deg(&self) -> f64 {
        2.0 * ((self.width as f64 / 2.0) / self.fx).atan().to_degrees()
    }

    /// The 3x3 intrinsic matrix `K`.
    pub fn k_matrix(&self) -> nalgebra::Matrix3<f64> {
        nalgebra::Matrix3::new(self.fx, 0.0, self.cx, 0.0, self.fy, self.cy, 0.0, 0.0, 1.0)
    }

    /// Reads a camera from a JSON file and validates it.
    pub fn load_json(path: &std::path::Path) -> Result<Self, CoreError> {
        let text = std::fs::read(path).map_err(|e| CoreError::io(path, e))?;
        Self::from_json_text(&text, path)
    }

    /// Parses a camera from JSON text and validates it; `origin` names the source in errors.
    pub fn from_json_text(text: &[u8], origin: &std::path::Path) -> Result<Self, CoreError> {
        let cam: CameraModel = crate::files::parse_json(text, origin)?;
        cam.validate().map_err(|e| CoreError::parse(origin, e.to_string()))?;
        Ok(cam)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lens() -> CameraModel {
        CameraModel { distortion: Distortion { k1: -0.12, k2: 0.05, p1: 0.001, p2: -0.0007, k3: -0.01 }, ..CameraModel::from_hfov(1024, 768, 77.0) }
    }

    #[test]
    fn project_unproject_round_trip_with_distortion() {
        let cam = lens();
        for &(x, y, z) in &[(0.1, -0.2, 1.0), (-0.7, 0.5, 1.3), (0.0, 0.0, 2.0), (0.6, 0.45, 0.9)] {
            let p = Point3::new(x, y, z);
            let px = cam.project(&p).unwrap();
            let back = cam.unproject_depth(&px, z);
            assert!((back - p).norm() < 1e-9, "{p:?} -> {px:?} -> {back:?}");
        }
    }

    #[test]
    fn jacobian_matches_finite_differences() {
        let d = lens().distortion;
        let (x, y, h) = (0.3, -0.2, 1e-7);
        let j = d.jacobian(x, y);
        let (a, b) = d.distort(x + h, y);
        let (c, e) = d.distort(x - h, y);
        assert!(((a - c) / (2.0 * h) - j[0]).abs() < 1e-6);
        assert!(((b - e) / (2.0 * h) - j[2]).abs() < 1e-6);
        let (a, b) = d.distort(x, y + h);
        let (c, e) = d.distort(x, y - h);
        assert!(((a - c) / (2.0 * h) - j[1]).abs() < 1e-6);
        assert!(((b - e) / (2.0 * h) - j[3]).abs() < 1e-6);
    }

    #[test]
    fn hfov_and_scaling_keep_geometry() {
        let cam = CameraModel::from_hfov(5472, 3648, 77.0);
        assert!((cam.hfov_deg() - 77.0).abs() < 1e-9);
        let half = cam.scaled(0.5);
        assert_eq!((half.width, half.height), (2736, 1824));
        let p = Point3::new(0.3, 0.1, 2.0);
        let a = cam.project(&p).unwrap();
        let b = half.project(&p).unwrap();
        assert!(((a.x + 0.5) * 0.5 - 0.5 - b.x).abs() < 1e-9);
        assert!(cam.project(&Point3::new(0.0, 0.0, -1.0)).is_none());
    }

    #[test]
    fn json_round_trip_and_validation() {
        let cam = lens();
        let text = serde_json::to_string(&cam).unwrap();
        let back: CameraModel = serde_json::from_str(&text).unwrap();
        assert_eq!(cam, back);
        let bad = CameraModel { fx: -1.0, ..cam };
        assert!(bad.validate().unwrap_err().to_string().contains("focal"));
    }
}
