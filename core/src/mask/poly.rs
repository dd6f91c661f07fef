//! Polygon rasterization identical to pycocotools' `rleFrPoly`.
//!
//! Vertices are scaled by 5 and rounded (`(int)(5 x + 0.5)`), the closed boundary is walked one
//! step per unit of its major axis, the points where the walk crosses a column boundary of the
//! original grid are kept (`x` on a pixel centre after downscaling, `y = ceil` of the crossing),
//! and the sorted crossing positions (column-major index `x * h + y`) become the run lengths.

use super::Rle;

/// Rasterizes one polygon `[x0, y0, x1, y1, ...]` (pixels) into an `h x w` RLE.
pub(super) fn rle_from_polygon(xy: &[f64], h: u32, w: u32) -> Rle {
    const SCALE: f64 = 5.0;
    let k = xy.len() / 2;
    // C `(int)` casts truncate toward zero; Rust `as i32` does the same (and saturates).
    let mut x: Vec<i32> = (0..k).map(|j| (SCALE * xy[2 * j] + 0.5) as i32).collect();
    let mut y: Vec<i32> = (0..k).map(|j| (SCALE * xy[2 * j + 1] + 0.5) as i32).collect();
    if k > 0 {
        x.push(x[0]);
        y.push(y[0]);
    }
    // Dense boundary points in the upsampled grid.
    let mut u: Vec<i32> = Vec::new();
    let mut v: Vec<i32> = Vec::new();
    for j in 0..k {
        let (mut xs, mut xe, mut ys, mut ye) = (x[j], x[j + 1], y[j], y[j + 1]);
        let dx = (xe - xs).abs();
        let dy = (ys - ye).abs();
        let flip = (dx >= dy && xs > xe) || (dx < dy && ys > ye);
        if flip {
            std::mem::swap(&mut xs, &mut xe);
            std::mem::swap(&mut ys, &mut ye);
        }
        if dx >= dy {
            let s = if dx == 0 { f64::NAN } else { (ye - ys) as f64 / dx as f64 };
            for d in 0..=dx {
                let t = if flip { dx - d } else { d };
                u.push(t + xs);
                // dx == 0 implies dy == 0: a single point at (xs, ys); C computes ys + NaN*0 there,
                // which casts to an unspecified int, but the point is never used (no column change).
                let yy = if dx == 0 { ys } else { (ys as f64 + s * t as f64 + 0.5) as i32 };
                v.push(yy);
            }
        } else {
            let s = (xe - xs) as f64 / dy as f64;
            for d in 0..=dy {
                let t = if flip { dy - d } else { d };
                v.push(t + ys);
                u.push((xs as f64 + s * t as f64 + 0.5) as i32);
            }
        }
    }
    // Column crossings, downsampled to the pixel grid.
    let hf = h as f64;
    let mut a: Vec<u32> = Vec::new();
    for j in 1..u.len() {
        if u[j] == u[j - 1] {
            continue;
        }
        let xd = (if u[j] < u[j - 1] { u[j] } else { u[j] - 1 }) as f64;
        let xd = (xd + 0.5) / SCALE - 0.5;
        if xd.floor() != xd || xd < 0.0 || xd > w as f64 - 1.0 {
            continue;
        }
        let yd = (if v[j] < v[j - 1] { v[j] } else { v[j - 1] }) as f64;
        let mut yd = (yd + 0.5) / SCALE - 0.5;
        if yd < 0.0 {
            yd = 0.0;
        } else if yd > hf {
            yd = hf;
        }
        let yd = yd.ceil();
        a.push(((xd as i32).wrapping_mul(h as i32)).wrapping_add(yd as i32) as u32);
    }
    a.push(h.wrapping_mul(w));
    a.sort_unstable();
    let mut p = 0u32;
    for t in a.iter_mut() {
        let cur = *t;
        *t = t.wrapping_sub(p);
        p = cur;
    }
    // Drop zero-length runs by merging the following run into the previous one.
    let mut b: Vec<u32> = Vec::with_capacity(a.len());
    let mut j = 0usize;
    b.push(a[j]);
    j += 1;
    while j < a.len() {
        if a[j] > 0 {
            b.push(a[j]);
            j += 1;
        } else {
            j += 1;
            if j < a.len() {
                if let Some(last) = b.last_mut() {
                    *last = last.wrapping_add(a[j]);
                }
                j += 1;
            }
        }
    }
    Rle { size: [h, w], counts: b }
}
