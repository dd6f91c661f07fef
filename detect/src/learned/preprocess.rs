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
                let gray: Vec<f32> = rgb.chunks_exact(3).take(n).map(|p| (0.299 * p[0] as f32 + 0.587 * p[1] as f32 + 0.114 * p[2] as f32) / 255.0).collect();
                let mut out = box_filter(&gray, width, height, radius);
                out.iter_mut().for_each(|v| *v = (*v - 0.5) / 0.25);
                out
            }
            Preprocess::GrayNorm => gray_norm(rgb, n),
        }
    }
}

/// [`Preprocess::GrayNorm`] of interleaved RGB8: luminance `0.299 R + 0.587 G + 0.114 B`,
/// percentiles from a 1024-bin histogram.
pub fn gray_norm(rgb: &[u8], n: usize) -> Vec<f32> {
    use rayon::prelude::*;
    let lum: Vec<f32> = rgb[..3 * n.min(rgb.len() / 3)].par_chunks_exact(3).map(|p| (0.299 * p[0] as f32 + 0.587 * p[1] as f32 + 0.114 * p[2] as f32) / 255.0).collect();
    // Per-chunk histograms summed (counts are integers: the same whatever the split).
    let hist = lum
        .par_chunks(1 << 16)
        .map(|chunk| {
            let mut h = [0u32; 1024];
            for &v in chunk {
                h[((v * 1023.0).round() as usize).min(1023)] += 1;
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
        let target = (q * lum.len() as f64).ceil().max(1.0) as u64;
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
    let inv = 1.0 / (0.5 * (p98 - p2).max(0.02));
    let mut lum = lum;
    lum.par_iter_mut().for_each(|v| *v = ((*v - p50) * inv).clamp(-6.0, 6.0));
    lum
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
}
