//! Sensor model: optical blur, shot and read noise, sRGB gamma, 8-bit quantization.
//!
//! On a linear image `v` (1.0 = full well): a separable Gaussian blur of `blur_sigma_px`,
//! then `e = v · full_well` electrons with noise `N(0, sqrt(e + read_e²))`, then
//! `v' = e' / full_well` encoded with the sRGB curve and rounded to 8 bits. The noise of each
//! row comes from a ChaCha8 stream seeded by `(seed, row)`, so output bytes are a pure
//! function of the input and the seed whatever the thread count.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Sensor parameters.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SensorOptions {
    /// Gaussian blur standard deviation, pixels (0 disables).
    pub blur_sigma_px: f32,
    /// Full-well capacity in electrons (sets shot noise; 0 disables all noise).
    pub full_well_e: f32,
    /// Read noise, electrons RMS.
    pub read_noise_e: f32,
}

impl Default for SensorOptions {
    fn default() -> Self {
        SensorOptions { blur_sigma_px: 0.6, full_well_e: 6000.0, read_noise_e: 6.0 }
    }
}

/// Applies blur, noise and gamma to a linear RGB buffer (`w·h·3`), returning sRGB bytes.
pub fn develop(linear: &mut [f32], w: usize, h: usize, opts: &SensorOptions, seed: u64) -> Vec<u8> {
    if opts.blur_sigma_px > 0.0 {
        blur_rgb(linear, w, h, opts.blur_sigma_px);
    }
    let lut: Vec<u8> = (0..4096).map(|i| crate::terrain::linear_to_srgb8(i as f32 / 4095.0)).collect();
    let mut out = vec![0u8; w * h * 3];
    out.par_chunks_mut(w * 3).zip(linear.par_chunks(w * 3)).enumerate().for_each(|(y, (orow, lrow))| {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ (y as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15));
        for (o, &v) in orow.iter_mut().zip(lrow) {
            let mut v = v.max(0.0);
            if opts.full_well_e > 0.0 {
                let e = v * opts.full_well_e;
                let sigma = (e + opts.read_noise_e * opts.read_noise_e).sqrt();
                let z: f32 = StandardNormal.sample(&mut rng);
                v = (e + sigma * z).max(0.0) / opts.full_well_e;
            }
            *o = lut[((v.min(1.0) * 4095.0) + 0.5) as usize];
        }
    });
    out
}

/// In-place separable Gaussian blur of an interleaved RGB buffer (kernel radius `⌈3σ⌉`).
pub fn blur_rgb(buf: &mut [f32], w: usize, h: usize, sigma: f32) {
    let rad = (3.0 * sigma).ceil() as isize;
    let mut k: Vec<f32> = (-rad..=rad).map(|i| (-(i * i) as f32 / (2.0 * sigma * sigma)).exp()).collect();
    let s: f32 = k.iter().sum();
    k.iter_mut().for_each(|v| *v /= s);
    let mut tmp = vec![0.0f32; buf.len()];
    tmp.par_chunks_mut(w * 3).zip(buf.par_chunks(w * 3)).for_each(|(orow, irow)| {
        for x in 0..w as isize {
            for c in 0..3 {
                let mut acc = 0.0;
                for (ki, &kv) in k.iter().enumerate() {
                    let xx = (x + ki as isize - rad).clamp(0, w as isize - 1) as usize;
                    acc += kv * irow[xx * 3 + c];
                }
                orow[x as usize * 3 + c] = acc;
            }
        }
    });
    let tmp_ref = &tmp;
    buf.par_chunks_mut(w * 3).enumerate().for_each(|(y, orow)| {
        for (ki, &kv) in k.iter().enumerate() {
            let yy = (y as isize + ki as isize - rad).clamp(0, h as isize - 1) as usize;
            let irow = &tmp_ref[yy * w * 3..(yy + 1) * w * 3];
            if ki == 0 {
                for (o, &i) in orow.iter_mut().zip(irow) {
                    *o = kv * i;
                }
            } else {
                for (o, &i) in orow.iter_mut().zip(irow) {
                    *o += kv * i;
                }
            }
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn develop_is_deterministic_and_noise_has_expected_spread() {
        let (w, h) = (64, 64);
        let base = vec![0.2f32; w * h * 3];
        let opts = SensorOptions { blur_sigma_px: 0.0, ..Default::default() };
        let a = develop(&mut base.clone(), w, h, &opts, 7);
        let b = develop(&mut base.clone(), w, h, &opts, 7);
        let c = develop(&mut base.clone(), w, h, &opts, 8);
        assert_eq!(a, b);
        assert_ne!(a, c);
        let mean = a.iter().map(|&v| v as f64).sum::<f64>() / a.len() as f64;
        // sRGB of 0.2 is 0.4845 → 123.5.
        assert!((mean - 123.5).abs() < 1.0, "mean {mean}");
        let none = SensorOptions { blur_sigma_px: 0.0, full_well_e: 0.0, read_noise_e: 0.0 };
        assert!(develop(&mut base.clone(), w, h, &none, 1).iter().all(|&v| v == 124 || v == 123));
    }

    #[test]
    fn blur_preserves_mean_and_spreads_an_impulse() {
        let (w, h) = (9, 9);
        let mut buf = vec![0.0f32; w * h * 3];
        buf[(4 * w + 4) * 3] = 1.0;
        blur_rgb(&mut buf, w, h, 0.8);
        let sum: f32 = buf.iter().step_by(3).sum();
        assert!((sum - 1.0).abs() < 1e-5);
        assert!(buf[(4 * w + 4) * 3] < 0.5 && buf[(4 * w + 5) * 3] > 0.05);
    }
}
