//! Region mode: disparity only inside regions of interest (e.g. detected tubes plus a margin),
//! for speed on full-resolution images.
//!
//! Each region is grown by `margin` pixels, overlapping grown regions are merged, and SGM runs on
//! a crop of both images that also covers the columns the right image needs
//! (`x - min_disparity - (num_disparities - 1)`). Paths are cut at the crop border, which is why
//! the margin exists. Pixels outside every grown region are `NaN`.

use crate::error::{Result, StereoError};
use crate::sgm::{SgmMatcher, SgmParams};
use serde::{Deserialize, Serialize};
use tubeloc_core::Plane;

/// An axis-aligned region of interest in pixels: top-left `(x, y)` and size `width x height`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Roi {
    /// Left column.
    pub x: i64,
    /// Top row.
    pub y: i64,
    /// Width in pixels (> 0).
    pub width: i64,
    /// Height in pixels (> 0).
    pub height: i64,
}

impl Roi {
    /// A region from `(x, y, width, height)`.
    pub fn new(x: i64, y: i64, width: i64, height: i64) -> Self {
        Roi { x, y, width, height }
    }

    fn err(&self, message: &str) -> StereoError {
        StereoError::InvalidRegion { roi: (self.x, self.y, self.width, self.height), message: message.into() }
    }
}

/// Half-open pixel rectangle `[x0, x1) x [y0, y1)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Rect {
    x0: usize,
    y0: usize,
    x1: usize,
    y1: usize,
}

impl Rect {
    fn overlaps(&self, o: &Rect) -> bool {
        self.x0 < o.x1 && o.x0 < self.x1 && self.y0 < o.y1 && o.y0 < self.y1
    }
    fn union(&self, o: &Rect) -> Rect {
        Rect { x0: self.x0.min(o.x0), y0: self.y0.min(o.y0), x1: self.x1.max(o.x1), y1: self.y1.max(o.y1) }
    }
}

/// Grows, clips and merges regions; errors on an empty list, empty regions or regions
/// entirely outside the `w x h` image.
fn grown_regions(rois: &[Roi], margin: usize, w: usize, h: usize) -> Result<Vec<Rect>> {
    if rois.is_empty() {
        return Err(StereoError::InvalidRegion { roi: (0, 0, 0, 0), message: "no regions of interest given".into() });
    }
    let mut rects = Vec::with_capacity(rois.len());
    for r in rois {
        if r.width <= 0 || r.height <= 0 {
            return Err(r.err("region is empty (width and height must be positive)"));
        }
        let (x0, y0, x1, y1) = (r.x, r.y, r.x + r.width, r.y + r.height);
        if x1 <= 0 || y1 <= 0 || x0 >= w as i64 || y0 >= h as i64 {
            return Err(r.err(&format!("region lies outside the {w}x{h} image")));
        }
        let m = margin as i64;
        rects.push(Rect { x0: (x0 - m).max(0) as usize, y0: (y0 - m).max(0) as usize, x1: (x1 + m).min(w as i64) as usize, y1: (y1 + m).min(h as i64) as usize });
    }
    // Merge overlapping rectangles until none overlap.
    let mut merged = true;
    while merged {
        merged = false;
        'outer: for i in 0..rects.len() {
            for j in i + 1..rects.len() {
                if rects[i].overlaps(&rects[j]) {
                    rects[i] = rects[i].union(&rects[j]);
                    rects.swap_remove(j);
                    merged = true;
                    break 'outer;
                }
            }
        }
    }
    Ok(rects)
}

fn crop(img: &Plane<u8>, x0: usize, y0: usize, x1: usize, y1: usize) -> Plane<u8> {
    let mut data = Vec::with_capacity((x1 - x0) * (y1 - y0));
    for y in y0..y1 {
        data.extend_from_slice(&img.row(y)[x0..x1]);
    }
    Plane::from_vec(x1 - x0, y1 - y0, data)
}

/// Disparity of a rectified pair only inside `rois` grown by `margin` pixels (`NaN` elsewhere).
/// Errors on size mismatch, an empty region list, empty regions and regions outside the image.
pub fn disparity_regions(left: &Plane<u8>, right: &Plane<u8>, params: &SgmParams, rois: &[Roi], margin: usize) -> Result<Plane<f32>> {
    let mut matcher = SgmMatcher::new(params.clone())?;
    if left.width != right.width || left.height != right.height {
        // Reuse the full-image check for its message.
        return matcher.compute(left, right);
    }
    let (w, h) = (left.width, left.height);
    let rects = grown_regions(rois, margin, w, h)?;
    let reach = (params.min_disparity as i64 + params.num_disparities as i64 - 1).max(0) as usize;
    let reach_right = (-(params.min_disparity as i64)).max(0) as usize;
    let mut out = Plane::filled(w, h, f32::NAN);
    for r in rects {
        let cx0 = r.x0.saturating_sub(reach);
        let cx1 = (r.x1 + reach_right).min(w);
        let cy0 = r.y0;
        let cy1 = r.y1;
        let (lc, rc) = (crop(left, cx0, cy0, cx1, cy1), crop(right, cx0, cy0, cx1, cy1));
        let d = if lc.width >= 2 && lc.height >= 2 { matcher.compute(&lc, &rc)? } else { Plane::filled(lc.width, lc.height, f32::NAN) };
        for y in r.y0..r.y1 {
            let src = &d.row(y - cy0)[r.x0 - cx0..r.x1 - cx0];
            out.data[y * w + r.x0..y * w + r.x1].copy_from_slice(src);
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regions_are_grown_clipped_and_merged() {
        let r = grown_regions(&[Roi::new(10, 10, 5, 5), Roi::new(18, 10, 5, 5), Roi::new(90, 90, 20, 20)], 2, 100, 100).unwrap();
        assert_eq!(r.len(), 2);
        assert!(r.contains(&Rect { x0: 8, y0: 8, x1: 25, y1: 17 }));
        assert!(r.contains(&Rect { x0: 88, y0: 88, x1: 100, y1: 100 }));
    }

    #[test]
    fn empty_and_outside_regions_error() {
        let e = grown_regions(&[], 0, 10, 10).unwrap_err().to_string();
        assert!(e.contains("no regions"), "{e}");
        let e = grown_regions(&[Roi::new(1, 1, 0, 4)], 0, 10, 10).unwrap_err().to_string();
        assert!(e.contains("empty"), "{e}");
        let e = grown_regions(&[Roi::new(20, 1, 3, 4)], 0, 10, 10).unwrap_err().to_string();
        assert!(e.contains("outside"), "{e}");
    }
}
