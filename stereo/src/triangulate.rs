//! Triangulation of rectified disparities into 3D points with depth uncertainty.
//!
//! In the rectified left camera frame (OpenCV axes, metres), a pixel `(u, v)` with disparity
//! `d = u_left - u_right > 0` lies at
//!
//! ```text
//! Z = f B / d,   X = (u - cx) Z / f,   Y = (v - cy) Z / f
//! σ_Z = |∂Z/∂d| σ_d = Z² σ_d / (f B)
//! ```
//!
//! with `f` the rectified focal length (pixels), `(cx, cy)` the rectified principal point
//! (pixels, shared by both rectified cameras) and `B` the baseline (metres).
//! [`crate::rectify::StereoRectification::to_left_camera`] maps the points into the original
//! (unrectified) left camera frame.

use nalgebra::Point3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use tubeloc_core::Plane;

/// Geometry of a rectified pair: focal length and principal point (pixels), baseline (metres).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct RectifiedGeometry {
    /// Rectified focal length, pixels.
    pub f: f64,
    /// Rectified principal point x, pixels.
    pub cx: f64,
    /// Rectified principal point y, pixels.
    pub cy: f64,
    /// Baseline, metres (distance between the optical centres).
    pub baseline: f64,
}

/// A triangulated point.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct StereoPoint {
    /// Pixel in the rectified left image.
    pub pixel: [f32; 2],
    /// Disparity, pixels.
    pub disparity: f32,
    /// Point in the rectified left camera frame, metres.
    pub point: Point3<f64>,
    /// Standard deviation of the depth `Z`, metres: `Z² σ_d / (f B)`.
    pub sigma_z: f64,
}

impl RectifiedGeometry {
    /// Depth (metres) of disparity `d` pixels; `None` when `d <= 0` or not finite.
    #[inline]
    pub fn depth(&self, d: f64) -> Option<f64> {
        (d.is_finite() && d > 0.0).then(|| self.f * self.baseline / d)
    }

    /// Disparity (pixels) of depth `z` metres.
    #[inline]
    pub fn disparity(&self, z: f64) -> f64 {
        self.f * self.baseline / z
    }

    /// Triangulates one pixel `(u, v)` with disparity `d`, disparity noise `sigma_d` pixels.
    pub fn triangulate_pixel(&self, u: f64, v: f64, d: f64, sigma_d: f64) -> Option<StereoPoint> {
        let z = self.depth(d)?;
        Some(StereoPoint { pixel: [u as f32, v as f32], disparity: d as f32, point: Point3::new((u - self.cx) * z / self.f, (v - self.cy) * z / self.f, z), sigma_z: z * z * sigma_d / (self.f * self.baseline) })
    }
}

/// Triangulates every valid pixel (`d` finite and `> 0`) of a rectified left disparity map,
/// in raster order. `sigma_d` is the disparity standard deviation in pixels.
pub fn triangulate(disp: &Plane<f32>, geom: &RectifiedGeometry, sigma_d: f64) -> Vec<StereoPoint> {
    disp.data.par_chunks(disp.width.max(1)).enumerate().flat_map_iter(|(y, row)| row.iter().enumerate().filter_map(move |(x, &d)| geom.triangulate_pixel(x as f64, y as f64, d as f64, sigma_d))).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn depth_and_sigma_follow_formulas() {
        let g = RectifiedGeometry { f: 1000.0, cx: 500.0, cy: 400.0, baseline: 0.2 };
        let p = g.triangulate_pixel(600.0, 300.0, 50.0, 0.25).unwrap();
        assert!((p.point.z - 4.0).abs() < 1e-12);
        assert!((p.point.x - 0.4).abs() < 1e-12 && (p.point.y + 0.4).abs() < 1e-12);
        // σ_Z = Z² σ_d / (f B) = 16 * 0.25 / 200 = 0.02 m; matches the finite difference.
        assert!((p.sigma_z - 0.02).abs() < 1e-12);
        let fd = (g.depth(50.0 - 1e-4).unwrap() - g.depth(50.0 + 1e-4).unwrap()) / 2e-4 * 0.25;
        assert!((fd - p.sigma_z).abs() < 1e-6);
        assert!(g.triangulate_pixel(0.0, 0.0, 0.0, 1.0).is_none());
        let d = Plane::from_vec(2, 1, vec![f32::NAN, 100.0]);
        let pts = triangulate(&d, &g, 0.5);
        assert_eq!(pts.len(), 1);
        assert_eq!(pts[0].pixel, [1.0, 0.0]);
    }
}
