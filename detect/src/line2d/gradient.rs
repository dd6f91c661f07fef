//! Quantized gradient orientations of a colour image.
//!
//! Per pixel: the image is smoothed with a separable 5-tap binomial filter `[1 4 6 4 1] / 16`,
//! Sobel gradients are taken in each of R, G, B and the channel with the largest squared
//! magnitude `gx² + gy²` is kept. Its orientation, modulo 180 degrees, is quantized into 8 bins
//! of 22.5 degrees: bin `k` holds `[22.5 k, 22.5 (k + 1))`. Pixels whose magnitude is below
//! `mag_threshold` get no orientation. A 3x3 majority vote then replaces each labelled pixel's
//! bin by the most frequent bin among its 9 neighbours, kept only when it occurs at least
//! `min_votes` times. The output is a one-hot bitmask per pixel (`1 << bin`, or 0).

use rayon::prelude::*;
use tubeloc_core::Plane;

/// Knobs of gradient quantization.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GradientParams {
    /// Minimum Sobel magnitude (of the smoothed 0..255 channel) for a pixel to get an orientation.
    pub mag_threshold: f32,
    /// Minimum count of the majority bin among the 3x3 neighbours (1..=9).
    pub min_votes: u8,
}

impl Default for GradientParams {
    fn default() -> Self {
        GradientParams { mag_threshold: 30.0, min_votes: 5 }
    }
}

const NONE: u8 = 255;

/// `(cos, sin)` of the 7 inner bin boundaries `22.5 k` degrees, `k = 1..=7`.
const BOUNDS: [(f32, f32); 7] = [(0.923_879_5, 0.382_683_43), (0.707_106_77, 0.707_106_77), (0.382_683_43, 0.923_879_5), (0.0, 1.0), (-0.382_683_43, 0.923_879_5), (-0.707_106_77, 0.707_106_77), (-0.923_879_5, 0.382_683_43)];

/// Orientation bin (0..8) of gradient `(gx, gy)` modulo 180 degrees, without `atan2`: after
/// folding to `gy >= 0`, the bin is the number of boundaries `b` with `sin(θ - b) >= 0`, i.e.
/// `gy cos b - gx sin b >= 0`.
#[inline]
pub fn orientation_bin(gx: f32, gy: f32) -> u8 {
    let flip = gy < 0.0 || (gy == 0.0 && gx < 0.0);
    let (gx, gy) = if flip { (-gx, -gy) } else { (gx, gy) };
    let mut k = 0u8;
    for (c, s) in BOUNDS {
        k += (gy * c - gx * s >= 0.0) as u8;
    }
    k
}

/// Splits interleaved RGB8 into three smoothed `f32` planes.
fn smooth_channels(rgb: &[u8], w: usize, h: usize) -> [Vec<f32>; 3] {
    let mut out = [vec![0f32; w * h], vec![0f32; w * h], vec![0f32; w * h]];
    let mut tmp = vec![0f32; w * h];
    for (c, dst) in out.iter_mut().enumerate() {
        // Horizontal pass (clamped borders).
        tmp.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            let src = &rgb[y * w * 3..(y + 1) * w * 3];
            let px = |x: isize| src[(x.clamp(0, w as isize - 1) as usize) * 3 + c] as f32;
            for (x, o) in row.iter_mut().enumerate() {
                let x = x as isize;
                *o = px(x - 2) + 4.0 * px(x - 1) + 6.0 * px(x) + 4.0 * px(x + 1) + px(x + 2);
            }
        });
        // Vertical pass.
        let tmp = &tmp;
        dst.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            let r = |dy: isize| {
                let yy = (y as isize + dy).clamp(0, h as isize - 1) as usize;
                &tmp[yy * w..(yy + 1) * w]
            };
            let (a, b, c0, d, e) = (r(-2), r(-1), r(0), r(1), r(2));
            for x in 0..w {
                row[x] = (a[x] + 4.0 * b[x] + 6.0 * c0[x] + 4.0 * d[x] + e[x]) * (1.0 / 256.0);
            }
        });
    }
    out
}

/// Raw orientation labels (bin or none) of the strongest colour channel.
fn labels(ch: &[Vec<f32>; 3], w: usize, h: usize, thr: f32) -> Vec<u8> {
    let thr2 = thr * thr;
    let mut out = vec![NONE; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        let ym = y.saturating_sub(1);
        let yp = (y + 1).min(h - 1);
        for (x, label) in row.iter_mut().enumerate() {
            let xm = x.saturating_sub(1);
            let xp = (x + 1).min(w - 1);
            let (mut best, mut bgx, mut bgy) = (-1.0f32, 0.0f32, 0.0f32);
            for p in ch {
                let a = |yy: usize, xx: usize| p[yy * w + xx];
                let gx = (a(ym, xp) + 2.0 * a(y, xp) + a(yp, xp)) - (a(ym, xm) + 2.0 * a(y, xm) + a(yp, xm));
                let gy = (a(yp, xm) + 2.0 * a(yp, x) + a(yp, xp)) - (a(ym, xm) + 2.0 * a(ym, x) + a(ym, xp));
                let m = gx * gx + gy * gy;
                if m > best {
                    best = m;
                    bgx = gx;
                    bgy = gy;
                }
            }
            if best >= thr2 && best > 0.0 {
                *label = orientation_bin(bgx, bgy);
            }
        }
    });
    out
}

/// 3x3 majority vote over labels: one-hot bitmask output.
pub(crate) fn majority(lab: &[u8], w: usize, h: usize, min_votes: u8) -> Vec<u8> {
    let mut out = vec![0u8; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for x in 0..w {
            if lab[y * w + x] == NONE {
                continue;
            }
            let mut hist = [0u8; 8];
            for yy in y.saturating_sub(1)..=(y + 1).min(h - 1) {
                for xx in x.saturating_sub(1)..=(x + 1).min(w - 1) {
                    let l = lab[yy * w + xx];
                    if l != NONE {
                        hist[l as usize] += 1;
                    }
                }
            }
            let (mut bi, mut bc) = (0usize, 0u8);
            for (i, &c) in hist.iter().enumerate() {
                if c > bc {
                    bc = c;
                    bi = i;
                }
            }
            if bc >= min_votes {
                row[x] = 1 << bi;
            }
        }
    });
    out
}

/// One-hot quantized orientations of an interleaved RGB8 image (`rgb.len() == 3 w h`).
pub fn quantize_rgb(rgb: &[u8], width: usize, height: usize, params: &GradientParams) -> Plane<u8> {
    assert_eq!(rgb.len(), width * height * 3, "RGB buffer size");
    if width == 0 || height == 0 {
        return Plane::new(width, height);
    }
    let ch = smooth_channels(rgb, width, height);
    let lab = labels(&ch, width, height, params.mag_threshold);
    Plane::from_vec(width, height, majority(&lab, width, height, params.min_votes))
}

/// Halves an interleaved RGB8 image by 2x2 box averaging (odd last row/column dropped).
pub fn downsample_rgb(rgb: &[u8], width: usize, height: usize) -> (Vec<u8>, usize, usize) {
    let (w2, h2) = (width / 2, height / 2);
    let mut out = vec![0u8; w2 * h2 * 3];
    out.par_chunks_mut((w2 * 3).max(1)).enumerate().for_each(|(y, row)| {
        let r0 = &rgb[(2 * y) * width * 3..];
        let r1 = &rgb[(2 * y + 1) * width * 3..];
        for x in 0..w2 {
            for c in 0..3 {
                let i = 2 * x * 3 + c;
                let s = r0[i] as u16 + r0[i + 3] as u16 + r1[i] as u16 + r1[i + 3] as u16;
                row[x * 3 + c] = ((s + 2) / 4) as u8;
            }
        }
    });
    (out, w2, h2)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn orientation_bins_match_atan2() {
        for i in 0..720 {
            let a = (i as f32 + 0.25) * 0.5f32.to_radians();
            let (gx, gy) = (a.cos() * 7.0, a.sin() * 7.0);
            let deg = gy.atan2(gx).to_degrees().rem_euclid(180.0);
            let expect = ((deg / 22.5).floor() as u8).min(7);
            assert_eq!(orientation_bin(gx, gy), expect, "angle {deg}");
        }
    }

    #[test]
    fn vertical_edge_gives_horizontal_gradient_bin() {
        let (w, h) = (32, 16);
        let mut rgb = vec![0u8; w * h * 3];
        for y in 0..h {
            for x in 16..w {
                rgb[(y * w + x) * 3 + 1] = 200;
            }
        }
        let q = quantize_rgb(&rgb, w, h, &GradientParams::default());
        assert_eq!(q.get(15, 8), 1); // bin 0
        assert_eq!(q.get(4, 8), 0); // flat
    }
}
