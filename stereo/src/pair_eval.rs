//! Accuracy on synthetic pairs with exact disparity (e.g. `tubeloc synth stereo` sets):
//! disparity errors over valid pixels and over tube pixels, and the 3D accuracy of triangulated
//! tube points (distance to the true tube surface).
//!
//! *Valid* pixels have a finite exact disparity `d`, a right-image match `x - d >= 0`, and are
//! not occluded in the right view. Occlusion follows the ordering constraint: pixel `x` is
//! hidden when some pixel `x' > x` of the same row maps to `x' - d(x') < x - d(x) + 0.5`
//! (a nearer surface covers its right-image position). A pixel is *bad-t* when the estimate is
//! invalid (`NaN`) or `|d_est - d| > t`; MAE is over pixels with an estimate.
//!
//! 3D: a tube pixel with estimate `d_est` is triangulated in the left camera,
//! `P = (Z (u - cx) / f, Z (v - cy) / f, Z)` with `Z = f B / d_est`, moved into the tube frame with
//! `T_cam_tube⁻¹`, and scored by its distance to the tube's surface of revolution
//! ([`tube_surface_distance`]).

use crate::triangulate::RectifiedGeometry;
use nalgebra::Point3;
use serde::Serialize;
use tubeloc_core::{BinaryMask, Plane, Pose, TubeModel};

/// Mask of valid pixels of an exact disparity map (see the module doc): 1 = valid.
pub fn valid_mask(gt: &Plane<f32>) -> Plane<u8> {
    let (w, h) = (gt.width, gt.height);
    let mut mask = Plane::<u8>::new(w, h);
    for y in 0..h {
        let row = gt.row(y);
        let mut min_right = f32::INFINITY;
        for x in (0..w).rev() {
            let d = row[x];
            if !(d.is_finite() && d > 0.0) {
                continue;
            }
            let xr = x as f32 - d;
            if xr >= 0.0 && xr <= min_right - 0.5 {
                *mask.get_mut(x, y) = 1;
            }
            min_right = min_right.min(xr);
        }
    }
    mask
}

/// Disparity errors over a set of pixels.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct ExactScore {
    /// Pixels evaluated.
    pub pixels: usize,
    /// Fraction of them with an estimate.
    pub density: f64,
    /// Fraction with no estimate or error above 1 px.
    pub bad1: f64,
    /// Fraction with no estimate or error above 2 px.
    pub bad2: f64,
    /// Mean absolute error over pixels with an estimate, pixels.
    pub mae: f64,
}

/// Running sums for [`ExactScore`] (pooled over several images).
#[derive(Clone, Copy, Debug, Default)]
pub struct ExactAccumulator {
    n: usize,
    est: usize,
    bad1: usize,
    bad2: usize,
    abs_sum: f64,
}

impl ExactAccumulator {
    /// Adds pixels where `mask(i)` holds (`i` = row-major index).
    pub fn add(&mut self, est: &Plane<f32>, gt: &Plane<f32>, mask: impl Fn(usize) -> bool) {
        for (i, (&e, &g)) in est.data.iter().zip(&gt.data).enumerate() {
            if !mask(i) {
                continue;
            }
            self.n += 1;
            if e.is_nan() {
                self.bad1 += 1;
                self.bad2 += 1;
                continue;
            }
            let err = (e - g).abs() as f64;
            self.est += 1;
            self.abs_sum += err;
            self.bad1 += usize::from(err > 1.0);
            self.bad2 += usize::from(err > 2.0);
        }
    }

    /// The scores so far.
    pub fn score(&self) -> ExactScore {
        let n = self.n.max(1) as f64;
        ExactScore { pixels: self.n, density: self.est as f64 / n, bad1: self.bad1 as f64 / n, bad2: self.bad2 as f64 / n, mae: if self.est > 0 { self.abs_sum / self.est as f64 } else { f64::NAN } }
    }
}

/// Distance (metres) of a point in the tube frame to the surface of revolution of `model`
/// (radius `R(z)` along the axis, flat ends at `z = ±L/2`):
/// `|r - R(z)|` beside the tube, the distance to the end disc beyond an end.
pub fn tube_surface_distance(model: &TubeModel, p: &Point3<f64>) -> f64 {
    let r = (p.x * p.x + p.y * p.y).sqrt();
    let half = model.length / 2.0;
    if p.z.abs() <= half {
        let side = (r - model.radius_at(p.z)).abs();
        // Inside near an end, the end face may be closer than the side.
        let end = if r < model.radius_at(p.z) { half - p.z.abs() } else { f64::INFINITY };
        side.min(end)
    } else {
        let rz = model.radius_at(half.copysign(p.z) * (1.0 - 1e-9));
        let dz = p.z.abs() - half;
        let dr = (r - rz).max(0.0);
        (dz * dz + dr * dr).sqrt()
    }
}

/// Distances (metres) of the triangulated estimates at the pixels of `mask` (row-major
/// indices) to the tube surface; pixels without an estimate are skipped.
pub fn tube_point_distances(est: &Plane<f32>, geom: &RectifiedGeometry, t_cam_tube: &Pose, model: &TubeModel, mask: impl Fn(usize) -> bool) -> Vec<f64> {
    let t_tube_cam = t_cam_tube.inverse();
    let mut out = Vec::new();
    for (i, &d) in est.data.iter().enumerate() {
        if !mask(i) {
            continue;
        }
        let (u, v) = ((i % est.width) as f64, (i / est.width) as f64);
        if let Some(sp) = geom.triangulate_pixel(u, v, d as f64, 0.0) {
            out.push(tube_surface_distance(model, &t_tube_cam.transform_point(&sp.point)));
        }
    }
    out
}

/// Quantile `q` in `[0, 1]` (nearest rank on a sorted copy); `NaN` for no values.
pub fn quantile(values: &[f64], q: f64) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let k = ((q.clamp(0.0, 1.0) * (v.len() - 1) as f64).round()) as usize;
    v[k]
}

/// Pooled accuracy over several synthetic pairs: disparity scores over valid pixels and over
/// valid tube pixels, and tube point distances.
#[derive(Clone, Debug, Default)]
pub struct PairEval {
    /// Scores over valid pixels.
    pub valid: ExactAccumulator,
    /// Scores over valid pixels inside the tube masks.
    pub tube: ExactAccumulator,
    /// Distances of triangulated tube points to the true surface, metres.
    pub tube_distances_m: Vec<f64>,
}

/// Summary of a [`PairEval`] (distances in millimetres).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct PairEvalSummary {
    /// Scores over valid pixels.
    pub valid: ExactScore,
    /// Scores over valid tube pixels.
    pub tube: ExactScore,
    /// Number of triangulated tube points.
    pub tube_points: usize,
    /// Median distance of tube points to the tube surface, mm.
    pub tube_median_mm: f64,
    /// 90th percentile of that distance, mm.
    pub tube_p90_mm: f64,
}

impl PairEval {
    /// Adds one pair: estimate `est` and exact `gt` left disparity, the pair's geometry, and per
    /// tube its visible mask in the left image and `T_cam_tube` (left camera).
    pub fn add(&mut self, est: &Plane<f32>, gt: &Plane<f32>, geom: &RectifiedGeometry, tubes: &[(&BinaryMask, Pose)], model: &TubeModel) {
        let valid = valid_mask(gt);
        let w = gt.width;
        self.valid.add(est, gt, |i| valid.data[i] != 0);
        for (mask, t_cam_tube) in tubes {
            if mask.width != w || mask.height != gt.height {
                continue;
            }
            let inside = |i: usize| valid.data[i] != 0 && mask.get(i % w, i / w);
            self.tube.add(est, gt, inside);
            self.tube_distances_m.extend(tube_point_distances(est, geom, t_cam_tube, model, inside));
        }
    }

    /// The pooled scores.
    pub fn summary(&self) -> PairEvalSummary {
        PairEvalSummary { valid: self.valid.score(), tube: self.tube.score(), tube_points: self.tube_distances_m.len(), tube_median_mm: 1e3 * quantile(&self.tube_distances_m, 0.5), tube_p90_mm: 1e3 * quantile(&self.tube_distances_m, 0.9) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn occluded_and_out_of_view_pixels_are_not_valid() {
        // Background d = 2 with a near box (d = 6) at x = 8..11: background pixels whose right
        // position falls under the box's right-image footprint (2..5) are occluded.
        let w = 14;
        let row: Vec<f32> = (0..w).map(|x| if (8..12).contains(&x) { 6.0 } else { 2.0 }).collect();
        let gt = Plane::from_vec(w, 1, row);
        let m = valid_mask(&gt);
        let valid: Vec<usize> = (0..w).filter(|&x| m.get(x, 0) == 1).collect();
        // x = 0, 1: right position < 0; x = 4..7 map to 2..5, covered by the box (maps to 2..5).
        assert_eq!(valid, vec![2, 3, 8, 9, 10, 11, 12, 13]);
    }

    #[test]
    fn surface_distance_is_zero_on_the_tube_and_metric_off_it() {
        let m = TubeModel::default();
        let r = m.radius_at(0.0);
        assert!(tube_surface_distance(&m, &Point3::new(r, 0.0, 0.0)) < 1e-12);
        assert!((tube_surface_distance(&m, &Point3::new(0.0, r + 0.003, 0.01)) - 0.003).abs() < 1e-12);
        let half = m.length / 2.0;
        assert!((tube_surface_distance(&m, &Point3::new(0.0, 0.0, half + 0.002)) - 0.002).abs() < 1e-12);
        assert_eq!(quantile(&[3.0, 1.0, 2.0], 0.5), 2.0);
    }
}
