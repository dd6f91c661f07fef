//! Rectangle masks: a tube's silhouette as the rectangle along its image axis that its network
//! mask fills.
//!
//! A tube lying on the ground is seen as a near-rectangle (a cylinder's outline: two straight
//! sides and slightly rounded ends). The network's masks are stride-4 logits upsampled and
//! thresholded, so they taper towards the tube's ends and fray along its sides. With `d` the
//! axis direction, `n = (-d_y, d_x)`, and each mask pixel's offsets from the pixels' mean
//! `t = (p - p̄)·d`, `a = (p - p̄)·n`, the rectangle is
//!
//! - along the axis: `t_min - ½ ≤ t ≤ t_max + ½` (the mask's whole extent),
//! - across: `q_0.05(a) - ½ ≤ a ≤ q_0.95(a) + ½` (`q_p` the `p`-quantile of the offsets: the
//!   sides at the mask's full width, stray pixels ignored),
//!
//! a pixel belonging to it when its centre lies inside ([`tubeloc_core::Rle::from_polygon`]).
//! Record 0077 chose it on the real validation composites (AR 0.257 → 0.315 grey, 0.449 →
//! 0.477 colour, AP50 +0.02). The decoder applies it to tubes narrower than the working width
//! only ([`super::DecodeConfig::rectangle_below_px`]): wider tubes, as on our renders, keep
//! their sharper network masks.

use tubeloc_core::Rle;

/// The quantiles `1 - q` and `q` of the across-axis offsets are the rectangle's sides.
pub const SIDE_QUANTILE: f64 = 0.95;

/// The rectangle mask of `mask` along the unit image direction `direction` (pixels, x right, y
/// down), with the same image size, and its COCO box; `None` for an empty mask or a degenerate
/// direction.
pub fn rectangle_mask(mask: &Rle, direction: [f64; 2]) -> Option<(Rle, [f64; 4])> {
    let norm = direction[0].hypot(direction[1]);
    if !norm.is_finite() || norm <= 1e-9 {
        return None;
    }
    let d = [direction[0] / norm, direction[1] / norm];
    let n = [-d[1], d[0]];
    let pixels = set_pixels(mask);
    if pixels.is_empty() {
        return None;
    }
    let k = pixels.len() as f64;
    let (mx, my) = pixels.iter().fold((0.0, 0.0), |(sx, sy), &(x, y)| (sx + x, sy + y));
    let (mx, my) = (mx / k, my / k);
    let (mut t_min, mut t_max) = (f64::MAX, f64::MIN);
    let mut across: Vec<f64> = Vec::with_capacity(pixels.len());
    for &(x, y) in &pixels {
        let (rx, ry) = (x - mx, y - my);
        let t = rx * d[0] + ry * d[1];
        (t_min, t_max) = (t_min.min(t), t_max.max(t));
        across.push(rx * n[0] + ry * n[1]);
    }
    let (a_lo, a_hi) = (quantile(&mut across, 1.0 - SIDE_QUANTILE), quantile(&mut across, SIDE_QUANTILE));
    let (a_mid, half_w) = ((a_lo + a_hi) / 2.0, (a_hi - a_lo) / 2.0 + 0.5);
    let (t0, t1) = (t_min - 0.5, t_max + 0.5);
    // Corners in pixel-centre coordinates; the polygon rasterizer's pixel (x, y) has its centre
    // at (x + ½, y + ½).
    let corner = |t: f64, a: f64| [mx + t * d[0] + (a_mid + a) * n[0] + 0.5, my + t * d[1] + (a_mid + a) * n[1] + 0.5];
    let xy: Vec<f64> = [corner(t0, -half_w), corner(t1, -half_w), corner(t1, half_w), corner(t0, half_w)].concat();
    let rle = Rle::from_polygon(&xy, mask.height(), mask.width());
    let bbox = rle.to_bbox();
    (rle.area() > 0).then_some((rle, bbox))
}

/// The `q`-quantile of `v` (nearest rank, `v` reordered); `v` not empty.
fn quantile(v: &mut [f64], q: f64) -> f64 {
    let i = ((v.len() - 1) as f64 * q).round() as usize;
    *v.select_nth_unstable_by(i, f64::total_cmp).1
}

/// The set pixels `(x, y)` of a column-major RLE, without decoding the image.
fn set_pixels(mask: &Rle) -> Vec<(f64, f64)> {
    let h = mask.height() as usize;
    let mut out = Vec::new();
    let mut pos = 0usize;
    for (i, &c) in mask.counts.iter().enumerate() {
        if i % 2 == 1 {
            out.extend((pos..pos + c as usize).map(|p| ((p / h) as f64, (p % h) as f64)));
        }
        pos += c as usize;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use tubeloc_core::BinaryMask;

    fn iou(a: &Rle, b: &Rle) -> f64 {
        Rle::iou(std::slice::from_ref(a), std::slice::from_ref(b), &[false])[0]
    }

    /// The rectangle of a mask that is already a rectangle along the given axis is that mask.
    #[test]
    fn a_rectangular_mask_is_its_own_rectangle() {
        let m = BinaryMask::from_fn(60, 40, |x, y| (10..50).contains(&x) && (15..23).contains(&y));
        let rle = Rle::from_mask(&m);
        let (r, bbox) = rectangle_mask(&rle, [1.0, 0.0]).unwrap();
        assert_eq!(r, rle);
        assert_eq!(bbox, [10.0, 15.0, 40.0, 8.0]);
    }

    /// A lens-shaped mask (tapered ends, as stride-4 logits give) of a tilted bar becomes
    /// nearly the bar: the rectangle is closer to the true outline than the lens.
    #[test]
    fn a_tapered_mask_of_a_tilted_bar_becomes_the_bar() {
        let (w, h) = (120, 100);
        let ang: f64 = 0.5;
        let (d, n) = ([ang.cos(), ang.sin()], [-ang.sin(), ang.cos()]);
        let c = [60.0, 50.0];
        let (half_l, half_w) = (35.0, 5.0);
        let local = |x: usize, y: usize| {
            let (rx, ry) = (x as f64 - c[0], y as f64 - c[1]);
            (rx * d[0] + ry * d[1], rx * n[0] + ry * n[1])
        };
        let truth = Rle::from_mask(&BinaryMask::from_fn(w, h, |x, y| {
            let (t, a) = local(x, y);
            t.abs() <= half_l && a.abs() <= half_w
        }));
        // The lens: full width at the middle, narrowing to half at the ends, 2 px short.
        let lens = Rle::from_mask(&BinaryMask::from_fn(w, h, |x, y| {
            let (t, a) = local(x, y);
            t.abs() <= half_l - 2.0 && a.abs() <= half_w * (1.0 - 0.5 * (t / half_l).powi(2))
        }));
        let (rect, _) = rectangle_mask(&lens, d).unwrap();
        let (before, after) = (iou(&lens, &truth), iou(&rect, &truth));
        assert!(after > 0.85 && after > before + 0.05, "IoU with the bar: lens {before:.3}, rectangle {after:.3}");
    }

    /// A stray pixel beside the mask does not widen the rectangle; an empty mask or a zero
    /// direction gives none.
    #[test]
    fn stray_pixels_are_ignored_and_degenerate_input_gives_none() {
        let m = BinaryMask::from_fn(60, 40, |x, y| (10..50).contains(&x) && (15..23).contains(&y) || (x, y) == (30, 30));
        let (r, _) = rectangle_mask(&Rle::from_mask(&m), [1.0, 0.0]).unwrap();
        assert_eq!(r.to_bbox(), [10.0, 15.0, 40.0, 8.0]);
        assert!(rectangle_mask(&Rle::from_mask(&BinaryMask::new(20, 10)), [1.0, 0.0]).is_none());
        assert!(rectangle_mask(&Rle::from_mask(&m), [0.0, 0.0]).is_none());
    }
}
