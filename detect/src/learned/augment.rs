//! Training images and augmentation: random crops with flips, rotations by 90° (unless
//! [`AugmentConfig::upright`]) plus a small angle, brightness/contrast and Gaussian noise, and
//! optional occluders ([`AugmentConfig::occluders`]: random erasing, Zhong et al. 2017) and
//! an optional resolution drop ([`AugmentConfig::resolution_drop`]).
//!
//! A crop of size `S` around centre `c` with angle `θ` and optional mirror samples the source
//! at `c + R(θ) · (±(x - S/2 + ½), y - S/2 + ½)` for output pixel `(x, y)`: bilinear for the
//! image (clamped border), nearest for the instance labels (0 outside).

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// One training image: preprocessed input planes and a per-pixel instance label map.
#[derive(Clone, Debug)]
pub struct TrainImage {
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
    /// Channel-major normalized input (`channels * width * height`).
    pub input: Vec<f32>,
    /// Instance label per pixel, row-major: 0 = background, `k` = instance `k`.
    pub labels: Vec<u16>,
    /// Indices of labelled pixels (crop centres are drawn near them).
    pub fg: Vec<u32>,
    /// Working scale of the image ([`crate::scale`]): crops sample the source every
    /// `1 / scale` pixels, as inference resamples the image by `scale`.
    pub scale: f32,
}

impl TrainImage {
    /// Builds an image from input planes and instance masks (`width * height` bytes each,
    /// non-zero = tube). Later masks win where masks overlap.
    pub fn new(width: usize, height: usize, input: Vec<f32>, masks: &[Vec<u8>]) -> Self {
        let mut labels = vec![0u16; width * height];
        for (k, m) in masks.iter().enumerate() {
            for (l, &v) in labels.iter_mut().zip(m) {
                if v != 0 {
                    *l = (k + 1) as u16;
                }
            }
        }
        let fg = labels.iter().enumerate().filter(|(_, &l)| l != 0).map(|(i, _)| i as u32).collect();
        TrainImage { width, height, input, labels, fg, scale: 1.0 }
    }

    /// Number of input channels.
    pub fn channels(&self) -> usize {
        self.input.len() / (self.width * self.height).max(1)
    }
}

/// Augmentation ranges.
#[derive(Clone, Copy, Debug)]
pub struct AugmentConfig {
    /// Crop side in pixels (multiple of 32).
    pub crop: usize,
    /// Probability that the crop is centred near a tube pixel rather than anywhere.
    pub p_object: f64,
    /// Maximum extra rotation on top of a multiple of 90°, degrees.
    pub max_angle_deg: f64,
    /// Contrast gain range `[1 - g, 1 + g]`.
    pub gain: f32,
    /// Brightness offset range `[-b, b]` in normalized units (1 unit = 0.25 intensity).
    pub offset: f32,
    /// Maximum Gaussian noise sigma, normalized units.
    pub noise: f32,
    /// Keep crops upright: no turns by multiples of 90° (the mirror stays left-right). In
    /// rover images the image's up is the scene's far side, where a tube's contact shadow
    /// shows; turned crops hide that cue from the network.
    pub upright: bool,
    /// Probability that a crop gets 1 to 3 occluders: axis-aligned rectangles, sides 8 px to
    /// `crop / 6`, filled with a flat level or a random two-level block pattern, whose pixels
    /// become background in the labels (random erasing; 0 = off). They stand for things the
    /// training scenes do not show: other objects beside and over the tubes.
    pub occluders: f64,
    /// Camera-like appearance changes on every crop: a tone curve (gamma 0.6-1.6 on the
    /// normalized range), Gaussian blur (σ up to 1.3 px, half the crops), vignetting (up to
    /// 1 normalized unit darker in the corners) and sensor noise. Off by default.
    pub photometric: bool,
    /// Probability that a crop is seen as by a camera with `k` times coarser pixels, `k` in
    /// [`RESOLUTION_DROP_FACTORS`]: the crop is averaged over `k x k` footprints, sensor noise
    /// (σ up to 0.2 normalized units) is added at that resolution, and it is resampled back
    /// bilinearly. This is what a coarse camera's frame looks like once inference brings it to
    /// the working scale (a Navcam frame is enlarged about 2.5 times); 0 = off.
    pub resolution_drop: f64,
}

/// Range of the pixel-size factor `k` of [`AugmentConfig::resolution_drop`].
pub const RESOLUTION_DROP_FACTORS: std::ops::RangeInclusive<f32> = 1.5..=3.0;

impl Default for AugmentConfig {
    fn default() -> Self {
        AugmentConfig { crop: 256, p_object: 0.75, max_angle_deg: 20.0, gain: 0.3, offset: 0.4, noise: 0.15, upright: false, occluders: 0.0, photometric: false, resolution_drop: 0.0 }
    }
}

/// Samples one augmented crop: returns `(input, labels)` of `channels * S * S` and `S * S`.
pub fn sample_crop(img: &TrainImage, cfg: &AugmentConfig, rng: &mut ChaCha8Rng) -> (Vec<f32>, Vec<u16>) {
    let s = cfg.crop;
    let (w, h) = (img.width, img.height);
    let (mut cx, mut cy) = if !img.fg.is_empty() && rng.random_bool(cfg.p_object) {
        let i = img.fg[rng.random_range(0..img.fg.len())] as usize;
        let j = s as f64 / 3.0;
        ((i % w) as f64 + rng.random_range(-j..=j), (i / w) as f64 + rng.random_range(-j..=j))
    } else {
        (rng.random_range(0.0..w as f64), rng.random_range(0.0..h as f64))
    };
    cx = cx.clamp(0.0, w as f64 - 1.0);
    cy = cy.clamp(0.0, h as f64 - 1.0);
    let quarter = rng.random_range(0..4);
    let quarter = if cfg.upright { 0 } else { quarter };
    let theta = quarter as f64 * std::f64::consts::FRAC_PI_2 + rng.random_range(-cfg.max_angle_deg..=cfg.max_angle_deg).to_radians();
    let mirror = if rng.random_bool(0.5) { -1.0 } else { 1.0 };
    let (c, sn) = (theta.cos() as f32, theta.sin() as f32);
    let ch = img.channels();
    let mut input = vec![0f32; ch * s * s];
    let mut labels = vec![0u16; s * s];
    let half = s as f32 / 2.0;
    for y in 0..s {
        for x in 0..s {
            let dx = mirror as f32 * (x as f32 - half + 0.5) / img.scale;
            let dy = (y as f32 - half + 0.5) / img.scale;
            let sx = cx as f32 + c * dx - sn * dy;
            let sy = cy as f32 + sn * dx + c * dy;
            let (nx, ny) = (sx.round(), sy.round());
            if nx >= 0.0 && ny >= 0.0 && (nx as usize) < w && (ny as usize) < h {
                labels[y * s + x] = img.labels[ny as usize * w + nx as usize];
            }
            let bx = sx.clamp(0.0, (w - 1) as f32);
            let by = sy.clamp(0.0, (h - 1) as f32);
            let (x0, y0) = (bx.floor() as usize, by.floor() as usize);
            let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
            let (fx, fy) = (bx - x0 as f32, by - y0 as f32);
            for k in 0..ch {
                let p = &img.input[k * w * h..(k + 1) * w * h];
                let a = p[y0 * w + x0] * (1.0 - fx) + p[y0 * w + x1] * fx;
                let b = p[y1 * w + x0] * (1.0 - fx) + p[y1 * w + x1] * fx;
                input[k * s * s + y * s + x] = a * (1.0 - fy) + b * fy;
            }
        }
    }
    if cfg.resolution_drop > 0.0 && rng.random_bool(cfg.resolution_drop) {
        let k = rng.random_range(RESOLUTION_DROP_FACTORS);
        let sigma = rng.random_range(0.0f32..0.2);
        drop_resolution(&mut input, s, ch, k, sigma, rng);
    }
    let gain = 1.0 + rng.random_range(-cfg.gain..=cfg.gain);
    let offset = rng.random_range(-cfg.offset..=cfg.offset);
    let sigma = rng.random_range(0.0..=cfg.noise);
    let normal = Normal::new(0.0f32, sigma.max(1e-6)).expect("finite sigma");
    for v in input.iter_mut() {
        *v = *v * gain + offset + if sigma > 0.0 { normal.sample(rng) } else { 0.0 };
    }
    if cfg.photometric {
        photometric(&mut input, s, ch, rng);
    }
    if cfg.occluders > 0.0 && rng.random_bool(cfg.occluders) {
        for _ in 0..rng.random_range(1..=3) {
            add_occluder(&mut input, &mut labels, s, ch, rng);
        }
    }
    (input, labels)
}

/// The resolution drop of [`AugmentConfig::resolution_drop`] on an `s x s` crop of `channels`
/// planes: low-resolution pixel `(i, j)` (side `m = ⌈s / k⌉`) is the mean of the crop pixels
/// whose centres fall in `[i k, (i + 1) k) x [j k, (j + 1) k)`, plus Gaussian noise of `sigma`;
/// crop pixel `(x, y)` is then the bilinear sample of the low-resolution plane at
/// `((x + ½) / k - ½, (y + ½) / k - ½)` (clamped at the border).
fn drop_resolution(input: &mut [f32], s: usize, channels: usize, k: f32, sigma: f32, rng: &mut ChaCha8Rng) {
    let m = (s as f32 / k).ceil() as usize;
    let normal = Normal::new(0.0f32, sigma.max(1e-6)).expect("finite sigma");
    // Per crop coordinate (the same for rows and columns): its low-resolution cell, and the two
    // cells and weight it is sampled back from.
    let cell: Vec<usize> = (0..s).map(|x| (((x as f32 + 0.5) / k) as usize).min(m - 1)).collect();
    let last = (m - 1) as f32;
    let back: Vec<(usize, usize, f32)> = (0..s)
        .map(|x| {
            let l = ((x as f32 + 0.5) / k - 0.5).clamp(0.0, last);
            let l0 = l.floor() as usize;
            (l0, (l0 + 1).min(m - 1), l.fract())
        })
        .collect();
    let mut count = vec![0u32; m * m];
    for &cy in &cell {
        for &cx in &cell {
            count[cy * m + cx] += 1;
        }
    }
    let mut sum = vec![0f32; m * m];
    for c in 0..channels {
        let p = &mut input[c * s * s..(c + 1) * s * s];
        sum.fill(0.0);
        for (y, &cy) in cell.iter().enumerate() {
            for (x, &cx) in cell.iter().enumerate() {
                sum[cy * m + cx] += p[y * s + x];
            }
        }
        for (v, &n) in sum.iter_mut().zip(&count) {
            *v = *v / n.max(1) as f32 + if sigma > 0.0 { normal.sample(rng) } else { 0.0 };
        }
        for (y, &(y0, y1, fy)) in back.iter().enumerate() {
            for (x, &(x0, x1, fx)) in back.iter().enumerate() {
                let a = sum[y0 * m + x0] * (1.0 - fx) + sum[y0 * m + x1] * fx;
                let b = sum[y1 * m + x0] * (1.0 - fx) + sum[y1 * m + x1] * fx;
                p[y * s + x] = a * (1.0 - fy) + b * fy;
            }
        }
    }
}

/// The camera-like changes of [`AugmentConfig::photometric`] on an `s x s` crop.
fn photometric(input: &mut [f32], s: usize, channels: usize, rng: &mut ChaCha8Rng) {
    // Tone curve: gamma on u = (x + 4) / 8 in [0, 1].
    let gamma = (rng.random_range(-0.5f32..0.5)).exp2().clamp(0.6, 1.6);
    for v in input.iter_mut() {
        let u = ((*v + 4.0) / 8.0).clamp(0.0, 1.0);
        *v = u.powf(gamma) * 8.0 - 4.0;
    }
    if rng.random_bool(0.5) {
        let sigma = rng.random_range(0.3f32..1.3);
        let taps: Vec<f32> = (-3i32..=3).map(|k| (-(k * k) as f32 / (2.0 * sigma * sigma)).exp()).collect();
        let sum: f32 = taps.iter().sum();
        let taps: Vec<f32> = taps.iter().map(|t| t / sum).collect();
        let mut tmp = vec![0f32; s * s];
        for c in 0..channels {
            let p = &mut input[c * s * s..(c + 1) * s * s];
            for y in 0..s {
                for x in 0..s {
                    tmp[y * s + x] = (-3i32..=3).map(|k| p[y * s + (x as i32 + k).clamp(0, s as i32 - 1) as usize] * taps[(k + 3) as usize]).sum();
                }
            }
            for y in 0..s {
                for x in 0..s {
                    p[y * s + x] = (-3i32..=3).map(|k| tmp[(y as i32 + k).clamp(0, s as i32 - 1) as usize * s + x] * taps[(k + 3) as usize]).sum();
                }
            }
        }
    }
    let vig = rng.random_range(0.0f32..1.0);
    let (cx, cy) = (rng.random_range(0.3f32..0.7) * s as f32, rng.random_range(0.3f32..0.7) * s as f32);
    let noise = rng.random_range(0.0f32..0.25);
    let normal = Normal::new(0.0f32, noise.max(1e-6)).expect("finite sigma");
    let r2 = 2.0 * (s as f32 * 0.5) * (s as f32 * 0.5);
    for c in 0..channels {
        for y in 0..s {
            for x in 0..s {
                let d2 = ((x as f32 - cx).powi(2) + (y as f32 - cy).powi(2)) / r2;
                input[c * s * s + y * s + x] += -vig * d2 + normal.sample(rng);
            }
        }
    }
}

/// Paints one occluder into an `s x s` crop of `channels` planes: a rectangle (sides 8 px to
/// `s / 6`) filled with a flat level per channel or, half the time, a pattern of square blocks
/// (4 to 8 px) at two levels; its labels become 0. Levels are drawn in `[-2, 2]` normalized
/// units (the range of sand, shadow and white paint).
fn add_occluder(input: &mut [f32], labels: &mut [u16], s: usize, channels: usize, rng: &mut ChaCha8Rng) {
    let max_side = (s / 6).max(9);
    let (w, h) = (rng.random_range(8..max_side), rng.random_range(8..max_side));
    let (x0, y0) = (rng.random_range(0..s.saturating_sub(w).max(1)), rng.random_range(0..s.saturating_sub(h).max(1)));
    let levels: [Vec<f32>; 2] = [(0..channels).map(|_| rng.random_range(-2.0f32..2.0)).collect(), (0..channels).map(|_| rng.random_range(-2.0f32..2.0)).collect()];
    let block = if rng.random_bool(0.5) { rng.random_range(4..=8) } else { 0 };
    // One random bit per block, drawn up front so the pattern does not depend on the order of
    // the pixel loop.
    let (bw, bh) = if block > 0 { (w.div_ceil(block), h.div_ceil(block)) } else { (1, 1) };
    let bits: Vec<bool> = (0..bw * bh).map(|_| block > 0 && rng.random_bool(0.5)).collect();
    for y in y0..(y0 + h).min(s) {
        for x in x0..(x0 + w).min(s) {
            let bit = (y - y0).checked_div(block).zip((x - x0).checked_div(block)).is_some_and(|(by, bx)| bits[by * bw + bx]);
            let level = &levels[bit as usize];
            for (k, &v) in level.iter().enumerate() {
                input[k * s * s + y * s + x] = v;
            }
            labels[y * s + x] = 0;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    /// Fraction of 200 crops whose top row is brighter than their bottom row, on an image whose
    /// value grows downward (value = row index).
    fn upside_down_fraction(upright: bool) -> f64 {
        let (w, h) = (200, 200);
        let input: Vec<f32> = (0..w * h).map(|i| (i / w) as f32).collect();
        let img = TrainImage::new(w, h, input, &[]);
        let cfg = AugmentConfig { crop: 64, noise: 0.0, gain: 0.0, offset: 0.0, upright, ..Default::default() };
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let flipped = (0..200)
            .filter(|_| {
                let (crop, _) = sample_crop(&img, &cfg, &mut rng);
                crop[..64].iter().sum::<f32>() > crop[63 * 64..].iter().sum::<f32>()
            })
            .count();
        flipped as f64 / 200.0
    }

    #[test]
    fn upright_crops_keep_the_image_up_and_turned_crops_do_not() {
        assert_eq!(upside_down_fraction(true), 0.0);
        // Turns by 0, 90, 180, 270 degrees: all 180-degree crops and about half of the
        // quarter-turned ones (whose rows are source columns) end upside down, ~1/2 in all.
        let f = upside_down_fraction(false);
        assert!((0.35..0.65).contains(&f), "{f}");
    }

    #[test]
    fn a_resolution_drop_keeps_flat_planes_and_means_and_removes_fine_detail() {
        let s = 64;
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        // A flat plane stays flat (no noise).
        let mut flat = vec![1.5f32; s * s];
        drop_resolution(&mut flat, s, 1, 2.5, 0.0, &mut rng);
        assert!(flat.iter().all(|v| (v - 1.5).abs() < 1e-5));
        // A one-pixel checkerboard averages out at k = 2: every pixel becomes its mean.
        let mut checker: Vec<f32> = (0..s * s).map(|i| ((i % s + i / s) % 2) as f32).collect();
        drop_resolution(&mut checker, s, 1, 2.0, 0.0, &mut rng);
        assert!(checker.iter().all(|v| (v - 0.5).abs() < 1e-5), "{:?}", &checker[..8]);
        // A ramp keeps its slope and mean away from the border.
        let mut ramp: Vec<f32> = (0..s * s).map(|i| (i % s) as f32).collect();
        drop_resolution(&mut ramp, s, 1, 3.0, 0.0, &mut rng);
        let row = &ramp[32 * s..33 * s];
        assert!((row[40] - row[20] - 20.0).abs() < 1.0, "{} {}", row[20], row[40]);
    }

    #[test]
    fn occluders_erase_the_labels_they_cover_and_nothing_else() {
        let (w, h) = (120, 120);
        let input: Vec<f32> = (0..w * h).map(|i| (i % w) as f32 * 0.01).collect();
        let img = TrainImage::new(w, h, input, &[vec![1u8; w * h]]);
        let plain = AugmentConfig { crop: 64, noise: 0.0, gain: 0.0, offset: 0.0, ..Default::default() };
        let occluded = AugmentConfig { occluders: 1.0, ..plain };
        for seed in 0..20 {
            let (a, la) = sample_crop(&img, &plain, &mut ChaCha8Rng::seed_from_u64(seed));
            let (b, lb) = sample_crop(&img, &occluded, &mut ChaCha8Rng::seed_from_u64(seed));
            let changed: Vec<usize> = (0..64 * 64).filter(|&i| a[i] != b[i] || la[i] != lb[i]).collect();
            // At least one 8x8 occluder, and every changed pixel is background in the labels.
            assert!(changed.len() >= 64, "seed {seed}: {} pixels changed", changed.len());
            assert!(changed.iter().all(|&i| lb[i] == 0 && (-2.0..2.0).contains(&b[i])), "seed {seed}");
        }
    }
}
