//! Input preprocessing: the paper's grayscale + box filter (default) or plain RGB.
//!
//! The network sees `C` planes of `f32` values normalized as `(v - 0.5) / 0.25` where `v` is the
//! intensity in `[0, 1]`. Gray: `v = (0.299 R + 0.587 G + 0.114 B) / 255`; gray-box then
//! applies a `(2r+1) x (2r+1)` box filter (mean, clamped border) computed with running sums,
//! O(1) per pixel.

use serde::{Deserialize, Serialize};

/// How an RGB image becomes network input planes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Preprocess {
    /// Grayscale then a box filter of radius `radius` pixels (the paper's choice; 1 channel).
    GrayBox {
        /// Box half-size in pixels (the box is `2r+1` wide).
        radius: usize,
    },
    /// The three RGB channels unchanged (3 channels).
    Rgb,
    /// Grayscale normalized by the image's own robust statistics (1 channel): with `v` the
    /// luminance in `[0, 1]` and `p_k` its `k`-th percentile over the whole image,
    /// `(v - p_50) / (0.5 max(p_98 - p_2, 0.02))`, clamped to `[-6, 6]`. Grey and colour
    /// cameras, dark 12-bit frames and bright ones give the network the same kind of input.
    GrayNorm,
}

impl Default for Preprocess {
    fn default() -> Self {
        Preprocess::GrayBox { radius: 1 }
    }
}

impl Preprocess {
    /// Parses `gray-box` (radius 1), `gray-box:R`, or `rgb`.
    pub fn parse(s: &str) -> Option<Preprocess> {
        match s {
            "rgb" => Some(Preprocess::Rgb),
            "gray-norm" => Some(Preprocess::GrayNorm),
            "gray-box" => Some(Preprocess::GrayBox { radius: 1 }),
            _ => s.strip_prefix("gray-box:").and_then(|r| r.parse().ok()).map(|radius| Preprocess::GrayBox { radius }),
        }
    }

    /// Number of input channels the network gets.
    pub fn channels(&self) -> usize {
        match self {
            Preprocess::GrayBox { .. } | Preprocess::GrayNorm => 1,
            Preprocess::Rgb => 3,
        }
    }

    /// Converts interleaved RGB8 (`width * height * 3` bytes) into channel-major planes
    /// (`channels * width * height` values), normalized as described in the module doc.
    pub fn apply(&self, rgb: &[u8], width: usize, height: usize) -> Vec<f32> {
        let n = width * height;
        match *self {
            Preprocess::Rgb => {
                let mut out = vec![0f32; 3 * n];
                for (i, px) in rgb.chunks_exact(3).enumerate().take(n) {
                    for c in 0..3 {
                        out[c * n + i] = (px[c] as f32 / 255.0 - 0.5) / 0.25;
                    }
                }
                out
            }
            Preprocess::GrayBox { radius } => {
                let gray: Vec<f32> = rgb.chunks_exact(3).take(n).map(luminance).collect();
                let mut out = box_filter(&gray, width, height, radius);
                out.iter_mut().for_each(|v| *v = (*v - 0.5) / 0.25);
                out
            }
            Preprocess::GrayNorm => gray_norm(rgb, n),
        }
    }

    /// [`Preprocess::apply`] resampled to `nw x nh` ([`crate::scale::resample_planes`]), with
    /// the same values. When the resampling starts with a box step and the preprocessing is
    /// per pixel (`rgb`, `gray-norm`), the box averages are taken of input rows computed on the
    /// fly, without the full-resolution planes (80 MB a plane for a 20-megapixel frame).
    pub fn apply_resampled(&self, rgb: &[u8], width: usize, height: usize, nw: usize, nh: usize) -> Vec<f32> {
        use crate::scale::{box_average, box_factors, resample_planes};
        let (kx, ky) = box_factors(width, height, nw, nh);
        let c = self.channels();
        let boxed = match (*self, kx > 1 || ky > 1) {
            (Preprocess::GrayNorm, true) => {
                let map = GrayNormMap::fit(rgb, width * height);
                box_average(1, width, height, kx, ky, |_, y, row| {
                    for (o, p) in row.iter_mut().zip(rgb[3 * y * width..3 * (y + 1) * width].chunks_exact(3)) {
                        *o = map.apply(p);
                    }
                })
            }
            (Preprocess::Rgb, true) => box_average(3, width, height, kx, ky, |c, y, row| {
                for (o, p) in row.iter_mut().zip(rgb[3 * y * width..3 * (y + 1) * width].chunks_exact(3)) {
                    *o = (p[c] as f32 / 255.0 - 0.5) / 0.25;
                }
            }),
            _ => return resample_planes(&self.apply(rgb, width, height), c, width, height, nw, nh),
        };
        resample_planes(&boxed, c, width / kx, height / ky, nw, nh)
    }
}

/// Luminance of an RGB8 pixel in `[0, 1]`: `(0.299 R + 0.587 G + 0.114 B) / 255`.
#[inline]
fn luminance(p: &[u8]) -> f32 {
    (0.299 * p[0] as f32 + 0.587 * p[1] as f32 + 0.114 * p[2] as f32) / 255.0
}

/// [`Preprocess::GrayNorm`]'s map from luminance to network input, fitted on one image:
/// `clamp((v - p_50) · inv, -6, 6)` with `inv = 1 / (0.5 max(p_98 - p_2, 0.02))`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GrayNormMap {
    p50: f32,
    inv: f32,
}

impl GrayNormMap {
    /// The map of the first `n` pixels of interleaved RGB8 `rgb`: percentiles of their
    /// luminance from a 1024-bin histogram.
    pub fn fit(rgb: &[u8], n: usize) -> Self {
        use rayon::prelude::*;
        let px = &rgb[..3 * n.min(rgb.len() / 3)];
        let count = px.len() / 3;
        // Per-chunk histograms summed (counts are integers: the same whatever the split).
        let hist = px
            .par_chunks(3 << 16)
            .map(|chunk| {
                let mut h = [0u32; 1024];
                for p in chunk.chunks_exact(3) {
                    h[((luminance(p) * 1023.0).round() as usize).min(1023)] += 1;
                }
                h
            })
            .reduce(
                || [0u32; 1024],
                |mut a, b| {
                    a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
                    a
                },
            );
        let pct = |q: f64| -> f32 {
            let target = (q * count as f64).ceil().max(1.0) as u64;
            let mut acc = 0u64;
            for (i, &c) in hist.iter().enumerate() {
                acc += c as u64;
                if acc >= target {
                    return i as f32 / 1023.0;
                }
            }
            1.0
        };
        let (p2, p50, p98) = (pct(0.02), pct(0.5), pct(0.98));
        GrayNormMap { p50, inv: 1.0 / (0.5 * (p98 - p2).max(0.02)) }
    }

    /// The map with median `p50` (luminance in `[0, 1]`) and gain `inv` (> 0, finite), e.g.
    /// one fitted on a whole frame and stored beside a crop of it ([`GrayNormMap::parts`]);
    /// `None` when out of range.
    pub fn from_parts(p50: f32, inv: f32) -> Option<Self> {
        ((0.0..=1.0).contains(&p50) && inv.is_finite() && inv > 0.0).then_some(GrayNormMap { p50, inv })
    }

    /// `(p50, inv)`: the median luminance and the gain of the map.
    pub fn parts(&self) -> (f32, f32) {
        (self.p50, self.inv)
    }

    /// The input planes (one) of the first `n` pixels of interleaved RGB8 `rgb` under this map.
    pub fn apply_all(&self, rgb: &[u8], n: usize) -> Vec<f32> {
        use rayon::prelude::*;
        rgb[..3 * n.min(rgb.len() / 3)].par_chunks_exact(3).map(|p| self.apply(p)).collect()
    }

    /// The network input of an RGB8 pixel `p`.
    #[inline]
    pub fn apply(&self, p: &[u8]) -> f32 {
        ((luminance(p) - self.p50) * self.inv).clamp(-6.0, 6.0)
    }
}

/// [`Preprocess::GrayNorm`] of interleaved RGB8 (its first `n` pixels) ([`GrayNormMap`]).
pub fn gray_norm(rgb: &[u8], n: usize) -> Vec<f32> {
    GrayNormMap::fit(rgb, n).apply_all(rgb, n)
}

/// Mean over a `(2r+1)^2` window with clamped (replicated) borders; separable running sums.
pub fn box_filter(src: &[f32], width: usize, height: usize, r: usize) -> Vec<f32> {
    if r == 0 || width == 0 || height == 0 {
        return src.to_vec();
    }
    let k = (2 * r + 1) as f32;
    let mut tmp = vec![0f32; src.len()];
    let clampi = |i: isize, n: usize| i.clamp(0, n as isize - 1) as usize;
    for y in 0..height {
        let row = &src[y * width..(y + 1) * width];
        let mut s: f32 = (-(r as isize)..=r as isize).map(|d| row[clampi(d, width)]).sum();
        for x in 0..width {
            tmp[y * width + x] = s / k;
            s += row[clampi(x as isize + r as isize + 1, width)] - row[clampi(x as isize - r as isize, width)];
        }
    }
    let mut out = vec![0f32; src.len()];
    for x in 0..width {
        let col = |y: usize| tmp[y * width + x];
        let mut s: f32 = (-(r as isize)..=r as isize).map(|d| col(clampi(d, height))).sum();
        for y in 0..height {
            out[y * width + x] = s / k;
            s += col(clampi(y as isize + r as isize + 1, height)) - col(clampi(y as isize - r as isize, height));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn box_filter_matches_brute_force() {
        let (w, h) = (7, 5);
        let src: Vec<f32> = (0..w * h).map(|i| ((i * 37) % 11) as f32).collect();
        let out = box_filter(&src, w, h, 1);
        for y in 0..h {
            for x in 0..w {
                let mut s = 0.0;
                for dy in -1i32..=1 {
                    for dx in -1i32..=1 {
                        let xx = (x as i32 + dx).clamp(0, w as i32 - 1) as usize;
                        let yy = (y as i32 + dy).clamp(0, h as i32 - 1) as usize;
                        s += src[yy * w + xx];
                    }
                }
                assert!((out[y * w + x] - s / 9.0).abs() < 1e-4);
            }
        }
        assert_eq!(Preprocess::parse("gray-box:2"), Some(Preprocess::GrayBox { radius: 2 }));
        assert_eq!(Preprocess::parse("rgb"), Some(Preprocess::Rgb));
        assert_eq!(Preprocess::parse("hsv"), None);
    }

    #[test]
    fn resampled_input_equals_resampling_the_full_resolution_input() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        // Shrinks with and without the box step, odd sizes, an enlargement.
        for (w, h, nw, nh) in [(97, 61, 20, 13), (64, 64, 16, 16), (50, 30, 40, 24), (33, 47, 9, 30), (20, 10, 41, 21)] {
            let rgb: Vec<u8> = (0..3 * w * h).map(|_| rng.random()).collect();
            for pre in [Preprocess::GrayNorm, Preprocess::Rgb, Preprocess::GrayBox { radius: 1 }] {
                let full = crate::scale::resample_planes(&pre.apply(&rgb, w, h), pre.channels(), w, h, nw, nh);
                let fused = pre.apply_resampled(&rgb, w, h, nw, nh);
                assert_eq!(fused.len(), full.len(), "{pre:?} {w}x{h} -> {nw}x{nh}");
                // Bit for bit: the same sums in the same order.
                assert!(fused.iter().zip(&full).all(|(a, b)| a.to_bits() == b.to_bits()), "{pre:?} {w}x{h} -> {nw}x{nh}");
            }
        }
    }
}
