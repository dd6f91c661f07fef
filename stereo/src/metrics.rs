//! Disparity accuracy against ground truth (Middlebury-style).
//!
//! Evaluated pixels: ground truth known **and non-occluded**. Non-occluded is decided by a
//! left-right check of the two ground-truth maps: pixel `x` with left disparity `dL` is
//! non-occluded when the right map at `x_r = round(x - dL)` is known and `|dL - dR(x_r)| <= 1`.
//! A pixel is *bad* when the estimate is invalid (`NaN`) or `|d - d_gt| > threshold`
//! (invalid estimates count as bad, so sparse maps are not rewarded). The mean absolute error
//! is over evaluated pixels that have an estimate; `density` is that fraction.

use tubeloc_core::Plane;

/// Ground-truth disparity (`NaN` = unknown) and the mask of pixels to evaluate.
#[derive(Clone, Debug)]
pub struct GroundTruth {
    /// Left-image disparity, pixels, `NaN` where unknown.
    pub disparity: Plane<f32>,
    /// 1 where the pixel is evaluated (known and non-occluded).
    pub mask: Plane<u8>,
}

impl GroundTruth {
    /// From Middlebury maps stored as `value = scale · d` (0 = unknown), left and right views.
    pub fn from_middlebury(left: &Plane<u8>, right: &Plane<u8>, scale: f32) -> GroundTruth {
        let (w, h) = (left.width, left.height);
        let to_d = |v: u8| if v == 0 { f32::NAN } else { v as f32 / scale };
        let disparity = Plane::from_vec(w, h, left.data.iter().map(|&v| to_d(v)).collect());
        let mut mask = Plane::<u8>::new(w, h);
        for y in 0..h {
            for x in 0..w {
                let dl = disparity.get(x, y);
                if dl.is_nan() {
                    continue;
                }
                let xr = (x as f32 - dl + 0.5).floor(); // round half up, as the Python peer
                if xr < 0.0 || xr >= w as f32 || right.width != w || right.height != h {
                    continue;
                }
                let dr = to_d(right.get(xr as usize, y));
                if !dr.is_nan() && (dl - dr).abs() <= 1.0 {
                    *mask.get_mut(x, y) = 1;
                }
            }
        }
        GroundTruth { disparity, mask }
    }

    /// Fraction of all pixels that are evaluated.
    pub fn evaluated_fraction(&self) -> f64 {
        self.mask.data.iter().filter(|&&m| m != 0).count() as f64 / self.mask.data.len().max(1) as f64
    }
}

/// Scores of a disparity map.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct DisparityScore {
    /// Number of evaluated pixels.
    pub evaluated: usize,
    /// Fraction of evaluated pixels that are bad (invalid or error above the threshold).
    pub bad: f64,
    /// Mean absolute error (pixels) over evaluated pixels with an estimate.
    pub mae: f64,
    /// Fraction of evaluated pixels with an estimate.
    pub density: f64,
}

/// Scores `estimate` (`NaN` = invalid) against `gt` at `threshold` pixels.
pub fn score(estimate: &Plane<f32>, gt: &GroundTruth, threshold: f32) -> DisparityScore {
    let (mut n, mut bad, mut valid, mut abs_sum) = (0usize, 0usize, 0usize, 0f64);
    for ((&e, &g), &m) in estimate.data.iter().zip(&gt.disparity.data).zip(&gt.mask.data) {
        if m == 0 {
            continue;
        }
        n += 1;
        if e.is_nan() {
            bad += 1;
            continue;
        }
        let err = (e - g).abs();
        valid += 1;
        abs_sum += err as f64;
        if err > threshold {
            bad += 1;
        }
    }
    let nf = n.max(1) as f64;
    DisparityScore { evaluated: n, bad: bad as f64 / nf, mae: abs_sum / valid.max(1) as f64, density: valid as f64 / nf }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn occluded_and_invalid_pixels_are_handled() {
        // 4x1: left GT d = 1 everywhere (x4 = 4); right GT says x_r = 0 is occluded (0).
        let l = Plane::from_vec(4, 1, vec![4u8, 4, 4, 4]);
        let r = Plane::from_vec(4, 1, vec![4u8, 0, 4, 4]);
        let gt = GroundTruth::from_middlebury(&l, &r, 4.0);
        // x=0 -> xr=-1 (outside), x=2 -> xr=1 (unknown in right view): not evaluated.
        assert_eq!(gt.mask.data, vec![0, 1, 0, 1]);
        let est = Plane::from_vec(4, 1, vec![0.0, 1.5, 9.0, f32::NAN]);
        let s = score(&est, &gt, 1.0);
        assert_eq!(s.evaluated, 2);
        assert_eq!(s.bad, 0.5);
        assert_eq!(s.mae, 0.5);
        assert_eq!(s.density, 0.5);
    }
}
