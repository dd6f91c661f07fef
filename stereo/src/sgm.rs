//! Semi-global matching (Hirschmüller 2008) with a census matching cost.
//!
//! Pipeline: census transform of both images ([`census`](crate::census)) → matching costs
//! `C(x, y, d)` (Hamming distance, optional gradient term; computed row by row inside the
//! aggregation, never stored as a volume) → aggregation along 8 or 4 paths
//! with edge-adapted `P2` → winner-takes-all with parabola sub-pixel refinement
//! `d* = d + (S(d-1) - S(d+1)) / (2 (S(d-1) - 2 S(d) + S(d+1)))` → uniqueness and left-right
//! consistency checks → optional 3x3 median → speckle removal.
//!
//! Output: a [`Plane<f32>`] of left-image disparities in pixels, `x_left - x_right`, where
//! **invalid pixels are `f32::NAN`** (occluded, inconsistent, ambiguous or speckle).

use crate::aggregate::{aggregate_select, AggBuffers, AggParams};
use crate::census::census_into;
use crate::cost::{cost_row, reverse_rows, sobel_x, CostWeights};
use crate::error::{param, Result, StereoError};
use crate::post::{median3, remove_speckles};
use serde::{Deserialize, Serialize};
use tubeloc_core::Plane;

/// Number of aggregation directions.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Paths {
    /// Horizontal, vertical and the two diagonals, both ways (Hirschmüller's recommendation).
    Eight,
    /// Horizontal and vertical only: about half the aggregation work.
    Four,
}

/// Parameters of semi-global matching. Costs are in census bits (Hamming distance units).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SgmParams {
    /// Smallest disparity searched, pixels.
    pub min_disparity: i32,
    /// Number of disparities searched (multiple of 16): `d ∈ [min, min + num)`.
    pub num_disparities: usize,
    /// Census window width (odd).
    pub census_width: usize,
    /// Census window height (odd); `width * height - 1 <= 64`.
    pub census_height: usize,
    /// Weight of the census Hamming distance in the pixel cost.
    pub census_weight: u8,
    /// Weight of the truncated horizontal-gradient difference (0 disables the term).
    pub gradient_weight: u8,
    /// Truncation of the gradient difference (grey levels / 4).
    pub gradient_trunc: u8,
    /// Penalty for a disparity change of one pixel between neighbours.
    pub p1: u16,
    /// Penalty for larger disparity changes (before edge adaptation); `p1 <= p2 <= 3800`.
    pub p2: u16,
    /// Edge adaptation `P2' = max(P1, P2 / (1 + |ΔI| / k))` with `ΔI` the grey-level step
    /// along the path; `0` keeps `P2` constant.
    pub p2_edge_k: f32,
    /// Aggregation directions.
    pub paths: Paths,
    /// Uniqueness margin in percent: the best cost must beat every non-adjacent disparity by
    /// this much (0 disables).
    pub uniqueness: u32,
    /// Maximum left-right disparity disagreement in pixels; negative disables the check.
    pub lr_max_diff: i32,
    /// Parabola sub-pixel refinement.
    pub subpixel: bool,
    /// 3x3 median filter of the disparity map.
    pub median: bool,
    /// Speckle removal: regions smaller than this many pixels are invalidated (0 disables).
    pub speckle_size: usize,
    /// Largest disparity step (pixels) inside one speckle region.
    pub speckle_range: f32,
}

impl Default for SgmParams {
    fn default() -> Self {
        SgmParams {
            min_disparity: 0,
            num_disparities: 128,
            census_width: 9,
            census_height: 7,
            census_weight: 1,
            gradient_weight: 0,
            gradient_trunc: 16,
            p1: 10,
            p2: 120,
            p2_edge_k: 0.0,
            paths: Paths::Eight,
            uniqueness: 0,
            lr_max_diff: 1,
            subpixel: true,
            median: true,
            speckle_size: 100,
            speckle_range: 2.0,
        }
    }
}

impl SgmParams {
    /// Checks ranges; errors name the parameter.
    pub fn validate(&self) -> Result<()> {
        if self.num_disparities == 0 || self.num_disparities % 16 != 0 || self.num_disparities > 1024 {
            return Err(param("num_disparities", format!("{} must be a positive multiple of 16, at most 1024", self.num_disparities)));
        }
        let (cw, ch) = (self.census_width, self.census_height);
        if cw % 2 == 0 || ch % 2 == 0 || cw * ch < 9 || cw * ch > 65 {
            return Err(param("census window", format!("{cw}x{ch}: sizes must be odd with 9 <= w*h <= 65")));
        }
        let cmax = self.census_weight as u32 * (cw * ch - 1) as u32 + self.gradient_weight as u32 * self.gradient_trunc as u32;
        if cmax > 255 {
            return Err(param("census_weight", format!("largest pixel cost {cmax} exceeds 255; lower census_weight or gradient_weight")));
        }
        if self.census_weight == 0 && self.gradient_weight == 0 {
            return Err(param("census_weight", "census and gradient weights are both zero"));
        }
        if self.p1 == 0 || self.p1 > self.p2 || self.p2 > 3800 {
            return Err(param("p1/p2", format!("need 0 < p1 <= p2 <= 3800, got p1={} p2={}", self.p1, self.p2)));
        }
        if !self.p2_edge_k.is_finite() || self.p2_edge_k < 0.0 {
            return Err(param("p2_edge_k", format!("{} must be finite and >= 0", self.p2_edge_k)));
        }
        if self.uniqueness >= 100 {
            return Err(param("uniqueness", format!("{} must be below 100 (percent)", self.uniqueness)));
        }
        if self.speckle_range.is_nan() || self.speckle_range < 0.0 {
            return Err(param("speckle_range", "must be >= 0"));
        }
        Ok(())
    }

    /// Largest pixel matching cost (census bits times weight plus truncated gradient term).
    fn cost_max(&self) -> u32 {
        self.census_weight as u32 * (self.census_width * self.census_height - 1) as u32 + self.gradient_weight as u32 * self.gradient_trunc as u32
    }

    fn agg_params(&self) -> AggParams {
        let mut lut = [0i16; 256];
        for (di, v) in lut.iter_mut().enumerate() {
            let p2 = if self.p2_edge_k > 0.0 { self.p2 as f32 / (1.0 + di as f32 / self.p2_edge_k) } else { self.p2 as f32 };
            *v = (p2.round() as i16).max(self.p1 as i16);
        }
        AggParams {
            nd: self.num_disparities,
            dmin: self.min_disparity,
            p1: self.p1 as i16,
            p2_lut: lut,
            eight_paths: self.paths == Paths::Eight,
            uniqueness: self.uniqueness,
            lr_max_diff: self.lr_max_diff,
            subpixel: self.subpixel,
            narrow: self.cost_max() as i32 + lut.iter().copied().max().unwrap_or(0) as i32 <= 255,
        }
    }
}

/// A reusable matcher: holds the census planes and aggregation buffers (`2·W·H·D` bytes for
/// the partial path sums, plus row buffers) so repeated calls on same-size images do not
/// reallocate. Matching costs are computed row by row inside the aggregation, never stored
/// as a volume.
pub struct SgmMatcher {
    params: SgmParams,
    census: (Plane<u64>, Plane<u64>),
    bufs: AggBuffers,
}

impl SgmMatcher {
    /// A matcher with validated parameters.
    pub fn new(params: SgmParams) -> Result<Self> {
        params.validate()?;
        Ok(SgmMatcher { params, census: (Plane::new(0, 0), Plane::new(0, 0)), bufs: AggBuffers::default() })
    }

    /// The parameters in use.
    pub fn params(&self) -> &SgmParams {
        &self.params
    }

    /// Left-image disparity of a rectified pair (pixels, `NaN` = invalid).
    pub fn compute(&mut self, left: &Plane<u8>, right: &Plane<u8>) -> Result<Plane<f32>> {
        check_pair(left, right)?;
        // Run inside the rayon pool: the per-row joins are then cheap work-stealing forks
        // instead of hand-offs from an outside thread.
        rayon::scope(|_| self.compute_in_pool(left, right))
    }

    fn compute_in_pool(&mut self, left: &Plane<u8>, right: &Plane<u8>) -> Result<Plane<f32>> {
        let p = &self.params;
        let (w, h, nd) = (left.width, left.height, p.num_disparities);
        let (cl, cr) = &mut self.census;
        census_into(left, p.census_width, p.census_height, cl)?;
        census_into(right, p.census_width, p.census_height, cr)?;
        reverse_rows(cr);
        let (cl, cr) = (&*cl, &*cr);
        let grads = if p.gradient_weight > 0 { Some((sobel_x(left), sobel_x(right))) } else { None };
        let wt = CostWeights { census: p.census_weight, grad: p.gradient_weight, grad_trunc: p.gradient_trunc, border: (p.census_weight as u32 * (p.census_width * p.census_height - 1) as u32 / 2).min(255) as u8 };
        let grads = grads.as_ref().map(|(a, b)| (a, b));
        let dmin = p.min_disparity;
        let mut out = Plane::<f32>::new(w, h);
        aggregate_select(left, &p.agg_params(), &mut self.bufs, &mut out.data, |y, row| cost_row(y, cl, cr, grads, dmin, nd, wt, row));
        if p.median {
            out = median3(&out);
        }
        remove_speckles(&mut out, p.speckle_size, p.speckle_range);
        Ok(out)
    }
}

/// Left-image disparity of a rectified pair with semi-global matching (see the module doc).
/// Errors on size mismatch, images smaller than 2x2 and invalid parameters.
pub fn disparity(left: &Plane<u8>, right: &Plane<u8>, params: &SgmParams) -> Result<Plane<f32>> {
    SgmMatcher::new(params.clone())?.compute(left, right)
}

fn check_pair(left: &Plane<u8>, right: &Plane<u8>) -> Result<()> {
    if left.width != right.width || left.height != right.height {
        return Err(StereoError::SizeMismatch { what: "left image".into(), a_w: left.width, a_h: left.height, other: "right image".into(), b_w: right.width, b_h: right.height });
    }
    if left.width < 2 || left.height < 2 || left.data.len() != left.width * left.height || right.data.len() != left.data.len() {
        return Err(param("images", format!("{}x{} image with {} values is too small or inconsistent", left.width, left.height, left.data.len())));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::SgmParams;

    #[test]
    fn parameter_files_refuse_unknown_fields_with_file_and_field() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sgm.json");
        std::fs::write(&path, r#"{"p1": 8, "p3": 100}"#).unwrap();
        let err = tubeloc_core::files::read_json::<SgmParams>(&path).unwrap_err().to_string();
        assert!(err.contains("sgm.json") && err.contains("unknown field `p3`"), "{err}");
        std::fs::write(&path, r#"{"p1": 8}"#).unwrap();
        assert_eq!(tubeloc_core::files::read_json::<SgmParams>(&path).unwrap(), SgmParams { p1: 8, ..SgmParams::default() });
    }
}
