//! Post-processing of disparity maps (`NaN` = invalid): 3x3 median and speckle removal.

use rayon::prelude::*;
use tubeloc_core::Plane;

/// 3x3 median over the valid pixels of each valid pixel's neighbourhood (invalid stay invalid).
pub fn median3(disp: &Plane<f32>) -> Plane<f32> {
    let (w, h) = (disp.width, disp.height);
    let mut out = disp.clone();
    out.data.par_chunks_mut(w).enumerate().for_each(|(y, orow)| {
        let mut buf = [0f32; 9];
        // Interior pixels whose whole 3x3 is valid: vectorized network over the row.
        let mut fast = vec![0f32; w.saturating_sub(2)];
        let mut has_nan = vec![0u8; w.saturating_sub(2)];
        let interior = y > 0 && y + 1 < h && w > 2;
        if interior {
            median_row(disp.row(y - 1), disp.row(y), disp.row(y + 1), &mut fast, &mut has_nan);
        }
        for (x, o) in orow.iter_mut().enumerate() {
            if disp.get(x, y).is_nan() {
                continue;
            }
            if interior && x > 0 && x + 1 < w && has_nan[x - 1] == 0 {
                *o = fast[x - 1];
                continue;
            }
            let mut n = 0;
            for yy in y.saturating_sub(1)..(y + 2).min(h) {
                for xx in x.saturating_sub(1)..(x + 2).min(w) {
                    let v = disp.get(xx, yy);
                    if !v.is_nan() {
                        buf[n] = v;
                        n += 1;
                    }
                }
            }
            let s = &mut buf[..n];
            s.sort_unstable_by(f32::total_cmp);
            *o = s[n / 2];
        }
    });
    out
}

crate::multiversion! {
    /// Median of each 3x3 window of three rows (`out[i]` centred on column `i + 1`) and
    /// whether the window holds a `NaN` (then `out[i]` is meaningless).
    fn median_row(r0: &[f32], r1: &[f32], r2: &[f32], out: &mut [f32], has_nan: &mut [u8]) {
        let n = out.len();
        let (a0, a1, a2) = (&r0[..n], &r0[1..n + 1], &r0[2..n + 2]);
        let (b0, b1, b2) = (&r1[..n], &r1[1..n + 1], &r1[2..n + 2]);
        let (c0, c1, c2) = (&r2[..n], &r2[1..n + 1], &r2[2..n + 2]);
        let has_nan = &mut has_nan[..n];
        for i in 0..n {
            let p = [a0[i], a1[i], a2[i], b0[i], b1[i], b2[i], c0[i], c1[i], c2[i]];
            has_nan[i] = p.iter().fold(0u8, |acc, v| acc | u8::from(v.is_nan()));
            out[i] = median9(p);
        }
    }
}

/// Median of 9 finite values with the 19-exchange network of Paeth (Graphics Gems).
#[inline(always)]
fn median9(mut p: [f32; 9]) -> f32 {
    let mut s = |a: usize, b: usize| {
        let (x, y) = (p[a], p[b]);
        // Plain compare-selects (minps/maxps); inputs are finite.
        p[a] = if x < y { x } else { y };
        p[b] = if x < y { y } else { x };
    };
    s(1, 2);
    s(4, 5);
    s(7, 8);
    s(0, 1);
    s(3, 4);
    s(6, 7);
    s(1, 2);
    s(4, 5);
    s(7, 8);
    s(0, 3);
    s(5, 8);
    s(4, 7);
    s(3, 6);
    s(1, 4);
    s(2, 5);
    s(4, 7);
    s(4, 2);
    s(6, 4);
    s(4, 2);
    p[4]
}

/// Removes speckles: 4-connected regions of valid pixels whose neighbours differ by at most
/// `max_diff` pixels of disparity, and that hold fewer than `min_size` pixels, become `NaN`.
pub fn remove_speckles(disp: &mut Plane<f32>, min_size: usize, max_diff: f32) {
    if min_size <= 1 {
        return;
    }
    let (w, h) = (disp.width, disp.height);
    let mut seen = vec![false; w * h];
    let mut stack: Vec<usize> = Vec::new();
    let mut region: Vec<usize> = Vec::new();
    for start in 0..w * h {
        if seen[start] || disp.data[start].is_nan() {
            continue;
        }
        seen[start] = true;
        stack.clear();
        region.clear();
        stack.push(start);
        while let Some(i) = stack.pop() {
            region.push(i);
            let v = disp.data[i];
            let (x, y) = (i % w, i / w);
            let mut visit = |j: usize| {
                if !seen[j] {
                    let u = disp.data[j];
                    if !u.is_nan() && (u - v).abs() <= max_diff {
                        seen[j] = true;
                        stack.push(j);
                    }
                }
            };
            if x > 0 {
                visit(i - 1);
            }
            if x + 1 < w {
                visit(i + 1);
            }
            if y > 0 {
                visit(i - w);
            }
            if y + 1 < h {
                visit(i + w);
            }
        }
        if region.len() < min_size {
            for &i in &region {
                disp.data[i] = f32::NAN;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_islands_removed_large_kept() {
        let mut d = Plane::filled(10, 10, 5.0f32);
        d.data[33] = 20.0; // 1-pixel speckle
        *d.get_mut(0, 0) = f32::NAN;
        remove_speckles(&mut d, 4, 1.0);
        assert!(d.data[33].is_nan());
        assert_eq!(d.data.iter().filter(|v| v.is_nan()).count(), 2);
        assert_eq!(d.get(5, 5), 5.0);
    }

    #[test]
    fn median9_matches_sorting() {
        let v = [5.0f32, 1.0, 9.0, 3.0, 7.0, 2.0, 8.0, 6.0, 4.0];
        for k in 0..9 {
            let mut r = v;
            r.rotate_left(k);
            assert_eq!(median9(r), 5.0);
        }
    }

    #[test]
    fn median_removes_outlier() {
        let mut d = Plane::filled(5, 5, 2.0f32);
        *d.get_mut(2, 2) = 9.0;
        *d.get_mut(0, 0) = f32::NAN;
        let m = median3(&d);
        assert_eq!(m.get(2, 2), 2.0);
        assert!(m.get(0, 0).is_nan());
    }
}
