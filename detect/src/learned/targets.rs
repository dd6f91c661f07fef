//! Training targets at stride 4 from an instance label map (see [`super::net`] for channels).
//!
//! Output cell `(i, j)` covers pixels `4i..4i+3` x `4j..4j+3`; its centre is pixel
//! `(4i + 1.5, 4j + 1.5)`, so pixel `x` maps to cell coordinate `(x - 1.5) / 4`.
//! - foreground: fraction of labelled pixels in the cell;
//! - centre heatmap: `max_k exp(-|u - c_k|² / 2σ²)`, σ = [`HEAT_SIGMA`] cells, `c_k` the
//!   centre of instance `k`'s axis segment ([`AxisSeed::from_pixels`]);
//! - `cos 2θ_k`, `sin 2θ_k`, `L_k / 2 / LENGTH_SCALE` on cells whose centre pixel belongs to `k`,
//!   where a per-cell weight of 1 marks them (0 elsewhere).

use super::net::{HEADS, LENGTH_SCALE, STRIDE};
use tubeloc_core::AxisSeed;

/// Heatmap Gaussian sigma in output cells.
pub const HEAT_SIGMA: f32 = 1.5;

/// Targets for one crop: `HEADS` planes and the instance-cell weight plane, at stride 4.
pub struct Targets {
    /// `HEADS * ow * oh` values, channel-major.
    pub values: Vec<f32>,
    /// `ow * oh` weights: 1 on cells inside an instance.
    pub weight: Vec<f32>,
}

/// Computes the targets of an `s x s` label map (`s` a multiple of 4).
pub fn make_targets(labels: &[u16], s: usize) -> Targets {
    let o = s / STRIDE;
    let n = o * o;
    let mut values = vec![0f32; HEADS * n];
    let mut weight = vec![0f32; n];
    let max_label = labels.iter().copied().max().unwrap_or(0) as usize;
    let mut pix: Vec<Vec<(f64, f64)>> = vec![Vec::new(); max_label + 1];
    for (i, &l) in labels.iter().enumerate() {
        if l != 0 {
            pix[l as usize].push(((i % s) as f64, (i / s) as f64));
        }
    }
    let seeds: Vec<Option<AxisSeed>> = pix.iter().map(|p| if p.len() >= 8 { AxisSeed::from_pixels(p.iter().copied()) } else { None }).collect();
    for (i, &l) in labels.iter().enumerate() {
        if l != 0 {
            let (x, y) = (i % s, i / s);
            values[(y / STRIDE) * o + x / STRIDE] += 1.0 / (STRIDE * STRIDE) as f32;
        }
    }
    let r = (3.0 * HEAT_SIGMA).ceil() as isize;
    for seed in seeds.iter().flatten() {
        let cu = (seed.centre_px[0] as f32 - 1.5) / STRIDE as f32;
        let cv = (seed.centre_px[1] as f32 - 1.5) / STRIDE as f32;
        let (iu, iv) = (cu.round() as isize, cv.round() as isize);
        for v in (iv - r).max(0)..=(iv + r).min(o as isize - 1) {
            for u in (iu - r).max(0)..=(iu + r).min(o as isize - 1) {
                let d2 = (u as f32 - cu).powi(2) + (v as f32 - cv).powi(2);
                let g = (-d2 / (2.0 * HEAT_SIGMA * HEAT_SIGMA)).exp();
                let t = &mut values[n + v as usize * o + u as usize];
                *t = t.max(g);
            }
        }
    }
    for j in 0..o {
        for i in 0..o {
            let l = labels[(j * STRIDE + STRIDE / 2) * s + i * STRIDE + STRIDE / 2] as usize;
            if let Some(Some(seed)) = (l != 0).then(|| seeds[l]) {
                let th = seed.direction_px[1].atan2(seed.direction_px[0]);
                let c = j * o + i;
                values[2 * n + c] = (2.0 * th).cos() as f32;
                values[3 * n + c] = (2.0 * th).sin() as f32;
                values[4 * n + c] = (seed.length_px as f32 / 2.0) / LENGTH_SCALE;
                weight[c] = 1.0;
            }
        }
    }
    Targets { values, weight }
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn bar_targets_have_centre_peak_and_axis() {
        // A horizontal 80x12 bar centred at pixel (63.5, 61.5) in a 128 crop.
        let s = 128;
        let mut labels = vec![0u16; s * s];
        for y in 56..68 {
            for x in 24..104 {
                labels[y * s + x] = 1;
            }
        }
        let t = make_targets(&labels, s);
        let o = s / 4;
        let n = o * o;
        let (mut best, mut bi) = (0.0, 0);
        for i in 0..n {
            if t.values[n + i] > best {
                best = t.values[n + i];
                bi = i;
            }
        }
        // Centre pixel (63.5, 61.5) -> cell (15.5, 15.0): peak at column 15 or 16, row 15.
        assert_eq!(bi / o, 15);
        assert!(bi % o == 15 || bi % o == 16);
        let c = 15 * o + 15;
        assert_eq!(t.weight[c], 1.0);
        assert!((t.values[2 * n + c] - 1.0).abs() < 1e-5 && t.values[3 * n + c].abs() < 1e-5);
        assert!((t.values[4 * n + c] * LENGTH_SCALE - 40.0).abs() < 1.0);
        assert_eq!(t.values[c], 1.0);
        assert_eq!(t.values[0], 0.0);
    }
}
