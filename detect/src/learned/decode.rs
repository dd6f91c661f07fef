//! From network outputs to tube instances.
//!
//! 1. Foreground cells: `σ(fg) > fg_threshold`; centre peaks: 3x3 local maxima of `σ(heat)`
//!    above `peak_threshold`.
//! 2. Connected foreground components (8-connectivity). Within a component, a peak on a
//!    stronger peak's axis line (across-axis distance below [`DecodeConfig::same_axis_cells`])
//!    and within [`DecodeConfig::same_tube_fraction`] of its predicted half-length is dropped
//!    (one tube, two maxima). A component still holding several peaks is split: each cell goes to the peak nearest in the peak's axis frame, with the across-axis
//!    distance weighted [`DecodeConfig::across_weight`] times the along-axis one (tubes are
//!    long and thin, so a cell belongs to the peak whose axis line passes near it).
//! 3. Full-resolution mask: the foreground logit bilinearly upsampled (stride 4) and
//!    thresholded at [`DecodeConfig::mask_logit`] inside the instance's cells, pixel `(x, y)`
//!    reading cell coordinate `((x - 1.5) / 4, (y - 1.5) / 4)`; then pixels not above
//!    [`DecodeConfig::mask_logit_rel`] × the instance's mean logit are dropped. With the fine
//!    mask branch the full-resolution logit is thresholded instead, inside the instance's cells
//!    grown by one cell (a background cell joins the neighbouring instance cell of highest
//!    foreground), since a tube's outline runs through cells that are mostly background.
//! 4. Score = `σ(mean logit over the mask)^k × (min(Lm, Lp) / max(Lm, Lp))^a × fill^b`, with
//!    `Lm` the mask's extent along the axis, `Lp` the predicted length and fill = area /
//!    (`Lm` × width) (with `k = 0`: `max σ(heat)` of the peak, or 0.5 × mean σ(fg) without one,
//!    × mean σ(fg) over the cells). Axis seed: centre at the peak (sub-cell by a 3x3 weighted
//!    mean), direction from the fg-weighted mean of `(cos 2θ, sin 2θ)`, length from the mean
//!    predicted half-length, width from the mask's extent across the axis.

use super::error::LearnedError;
use super::model::{LearnedModel, Prediction};
use super::net::{bilinear4_at, HEADS, LENGTH_SCALE, STRIDE};
use rayon::prelude::*;
use tubeloc_core::{AxisSeed, Plane};

/// Thresholds of the decoder (JSON: missing fields keep their defaults).
#[derive(Clone, Copy, Debug, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DecodeConfig {
    /// Foreground probability threshold for cells.
    pub fg_threshold: f32,
    /// Heatmap probability threshold for centre peaks.
    pub peak_threshold: f32,
    /// Weight of the across-axis distance when splitting components.
    pub across_weight: f32,
    /// Minimum mask area in pixels.
    pub min_area: usize,
    /// Minimum score.
    pub min_score: f32,
    /// Peaks closer than this (cells) to a stronger peak's axis line may be merged into it...
    pub same_axis_cells: f32,
    /// ...when they are within this fraction of its predicted half-length along the axis.
    pub same_tube_fraction: f32,
    /// Threshold on the upsampled foreground logit for mask pixels (0 = probability 0.5). With
    /// [`DecodeConfig::mask_logit_rel`] 0.3 the default 0 was chosen on generated validation
    /// scenes (val9 and val21: AP50 +0.010 over a fixed threshold of 0.5).
    pub mask_logit: f32,
    /// Relative mask threshold: after thresholding at `mask_logit`, pixels whose logit is not
    /// above `mask_logit_rel × (their mean logit)` are dropped (0 = off). It trims the fringe of
    /// confident masks without cutting weak ones.
    pub mask_logit_rel: f32,
    /// Use the full-resolution mask logits when the model has them (`false`: the bilinear
    /// stride-4 masks, for comparison).
    pub fine_mask: bool,
    /// Inference, not decoding: average the network's outputs over the image and its
    /// left-right mirror ([`super::LearnedModel::predict_mirror_averaged`], twice the network
    /// time). Chosen on generated validation scenes: val9 AP50 0.712 -> 0.726, AP 0.245 ->
    /// 0.272; val21 0.791 -> 0.810, 0.277 -> 0.300.
    pub mirror_average: bool,
    /// Mirror averaging only for images of at most this many pixels (the working image the
    /// network sees); larger ones get the plain prediction, half the network time. Large frames
    /// already run in bands ([`super::model::WHOLE_MAX_PIXELS`]), and the mirror's gain there
    /// does not pay for its time (docs/design/0040).
    pub mirror_max_pixels: usize,
    /// Exponent `a` of the length agreement in the score, `score *= (min(Lm, Lp) / max(Lm, Lp))^a`
    /// with `Lm` the mask's extent along the axis and `Lp` the predicted length (0 = off).
    pub length_weight: f32,
    /// Exponent `k` of the mask confidence `σ(mean logit over the mask's pixels)`. When > 0 it
    /// replaces `peak × mean σ(fg)` as the base of the score (it ranks masks by how sure the
    /// network is of their pixels, which predicts mask IoU better than the centre peak).
    pub mask_logit_weight: f32,
    /// Exponent `b` of the fill `area / (Lm × Wm)` (mask pixels over its extent along × across
    /// the axis) in the score (0 = off): ragged or bent masks fill their box poorly.
    pub fill_weight: f32,
    /// Weight `w` of the mask's principal axis `p` in the axis seed's image direction,
    /// `normalize(u + w p)` with `u` the direction head's (sign-aligned; 0 = the head alone).
    /// The two err apart, so their sum is the better seed (and the better prior of
    /// refinement's `mask.axis_sigma_px`). The score keeps the head's direction. `w = 2` chosen
    /// on the generated validation sets (val9, val21; both cross-split RGB models, mono
    /// refinement with `--ground auto`) among 0, 0.5, 1, 2, 4 and 100 (the principal axis
    /// alone) by the mean axis p90: 1.98 (0) -> 1.70 deg (2); head alone vs principal axis vs
    /// their sum against the truth's image direction (val21, matched masks): median 0.59 / 0.57 /
    /// 0.49 deg.
    pub mask_direction_weight: f32,
    /// Inference, not decoding: when the working scale `s` enlarges the image (`s > 1`: a
    /// camera whose tubes are narrower than the working width, e.g. a Navcam frame), also run
    /// the network at `k s` and merge the two ([`super::detect_rgb_at_scale`]); 0 = one scale.
    /// The expected range behind `s` is one number for the whole frame, while a frame's tubes
    /// lie at many ranges. Off by default (`docs/design/0049-second-working-scale.md`): with
    /// `k = 0.6` the grey validation composites gain AP50 (0.559 -> 0.617 and 0.677 -> 0.700),
    /// the colour ones and the calibration set do not, and the refitted threshold keeps fewer
    /// tubes.
    pub second_scale: f32,
    /// Replace the mask of each instance narrower than this (its axis seed's width in the
    /// image's own pixels, after the working scale) by the rectangle along the seed's direction
    /// that the mask fills ([`super::rectangle`]); 0 = never. The score and the axis seed stay
    /// the network mask's. Default: the working width, 16 px
    /// (`docs/design/0077-rectangle-masks.md`: real validation composites, AR 0.257 → 0.315
    /// grey, 0.449 → 0.477 colour; wider tubes, as on our renders, keep their sharper network
    /// masks).
    pub rectangle_below_px: f32,
}

impl Default for DecodeConfig {
    fn default() -> Self {
        DecodeConfig {
            fg_threshold: 0.5,
            peak_threshold: 0.2,
            across_weight: 4.0,
            min_area: 40,
            min_score: 0.05,
            same_axis_cells: 2.5,
            same_tube_fraction: 100.0,
            mask_logit: 0.0,
            mask_logit_rel: 0.3,
            fine_mask: true,
            mirror_average: true,
            mirror_max_pixels: super::model::WHOLE_MAX_PIXELS,
            length_weight: 0.5,
            mask_logit_weight: 4.0,
            fill_weight: 1.0,
            mask_direction_weight: 2.0,
            second_scale: 0.0,
            rectangle_below_px: crate::scale::WORKING_TUBE_WIDTH_PX as f32,
        }
    }
}

impl DecodeConfig {
    /// Checks the ranges: probabilities in `[0, 1]`, weights, distances and exponents `>= 0`,
    /// thresholds finite. The error names the first field out of range.
    pub fn validate(&self) -> Result<(), String> {
        use tubeloc_core::field_range::{
            check_all, check_real,
            Bound::{Closed, Open},
        };
        check_all(&[("fg_threshold", self.fg_threshold), ("peak_threshold", self.peak_threshold), ("mask_logit_rel", self.mask_logit_rel)], Closed(0.0), Closed(1.0))?;
        let non_negative = [
            ("across_weight", self.across_weight),
            ("min_score", self.min_score),
            ("same_axis_cells", self.same_axis_cells),
            ("same_tube_fraction", self.same_tube_fraction),
            ("length_weight", self.length_weight),
            ("mask_logit_weight", self.mask_logit_weight),
            ("fill_weight", self.fill_weight),
            ("mask_direction_weight", self.mask_direction_weight),
            ("second_scale", self.second_scale),
            ("rectangle_below_px", self.rectangle_below_px),
        ];
        check_all(&non_negative, Closed(0.0), Open(f64::INFINITY))?;
        check_real("mask_logit", self.mask_logit, Closed(f64::NEG_INFINITY), Closed(f64::INFINITY))?;
        Ok(())
    }
}

/// One detected tube.
#[derive(Clone, Debug)]
pub struct LearnedInstance {
    /// Confidence in `[0, 1]`.
    pub score: f64,
    /// Binary mask (1 = tube) of the image's size as COCO RLE (column-major runs).
    pub mask: tubeloc_core::Rle,
    /// COCO bbox `[x, y, w, h]` of the mask, pixels.
    pub bbox: [f64; 4],
    /// Image axis of the tube (seed for `refine`).
    pub axis: AxisSeed,
}

fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

/// The prediction that `cfg` asks for from preprocessed input planes (`channels * width *
/// height`): [`LearnedModel::predict_mirror_averaged`] with [`DecodeConfig::mirror_average`]
/// for images of at most [`DecodeConfig::mirror_max_pixels`], else [`LearnedModel::predict`].
pub fn predict_for(model: &LearnedModel, input: &[f32], width: usize, height: usize, cfg: &DecodeConfig) -> Result<Prediction, LearnedError> {
    if cfg.mirror_average && width * height <= cfg.mirror_max_pixels {
        model.predict_mirror_averaged(input, width, height)
    } else {
        model.predict(input, width, height)
    }
}

/// Decodes the network outputs of one image ([`super::LearnedModel::predict`]) into
/// instances, sorted by decreasing score.
pub fn decode(pred: &Prediction, cfg: &DecodeConfig) -> Vec<LearnedInstance> {
    let (out, ow, oh, width, height) = (&pred.planes[..], pred.out_w, pred.out_h, pred.width, pred.height);
    let n = ow * oh;
    assert_eq!(out.len(), HEADS * n, "output plane size");
    let fg: Vec<f32> = out[..n].par_iter().map(|&v| sigmoid(v)).collect();
    let heat: Vec<f32> = out[n..2 * n].par_iter().map(|&v| sigmoid(v)).collect();
    // Peaks.
    let mut peaks = Vec::new();
    for y in 0..oh {
        for x in 0..ow {
            let v = heat[y * ow + x];
            if v < cfg.peak_threshold {
                continue;
            }
            let mut is_max = true;
            for dy in -1isize..=1 {
                for dx in -1isize..=1 {
                    let (xx, yy) = (x as isize + dx, y as isize + dy);
                    if (dx, dy) != (0, 0) && xx >= 0 && yy >= 0 && (xx as usize) < ow && (yy as usize) < oh {
                        let w = heat[yy as usize * ow + xx as usize];
                        // Ties: the first in raster order wins.
                        if w > v || (w == v && (dy < 0 || (dy == 0 && dx < 0))) {
                            is_max = false;
                        }
                    }
                }
            }
            if is_max {
                peaks.push(y * ow + x);
            }
        }
    }
    // Components.
    let mut comp = vec![u32::MAX; n];
    let mut comps: Vec<Vec<usize>> = Vec::new();
    let mut stack = Vec::new();
    for s in 0..n {
        if fg[s] <= cfg.fg_threshold || comp[s] != u32::MAX {
            continue;
        }
        let id = comps.len() as u32;
        let mut cells = Vec::new();
        comp[s] = id;
        stack.push(s);
        while let Some(c) = stack.pop() {
            cells.push(c);
            let (x, y) = ((c % ow) as isize, (c / ow) as isize);
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let (xx, yy) = (x + dx, y + dy);
                    if xx >= 0 && yy >= 0 && (xx as usize) < ow && (yy as usize) < oh {
                        let d = yy as usize * ow + xx as usize;
                        if comp[d] == u32::MAX && fg[d] > cfg.fg_threshold {
                            comp[d] = id;
                            stack.push(d);
                        }
                    }
                }
            }
        }
        comps.push(cells);
    }
    // Mean doubled-angle direction of a set of cells.
    let direction = |cells: &[usize]| -> (f32, f32) {
        let (mut c2, mut s2) = (0.0f32, 0.0f32);
        for &c in cells {
            c2 += fg[c] * out[2 * n + c];
            s2 += fg[c] * out[3 * n + c];
        }
        let th = 0.5 * s2.atan2(c2);
        (th.cos(), th.sin())
    };
    let mut groups: Vec<(Option<usize>, Vec<usize>)> = Vec::new();
    for cells in comps {
        let id = comp[cells[0]];
        let mut cand: Vec<usize> = peaks.iter().copied().filter(|&p| comp[p] == id).collect();
        cand.sort_by(|&a, &b| heat[b].total_cmp(&heat[a]));
        // Peak suppression along the axis: a weaker peak lying on a stronger one's axis line
        // (across < `same_axis_cells`) within `same_tube_fraction` of its predicted half-length
        // is the same tube.
        let mut mine: Vec<usize> = Vec::new();
        for &p in &cand {
            let (x, y) = ((p % ow) as f32, (p / ow) as f32);
            let dup = mine.iter().any(|&q| {
                let (qx, qy) = ((q % ow) as f32, (q / ow) as f32);
                let near: Vec<usize> = cells.iter().copied().filter(|&c| ((c % ow) as f32 - qx).abs() <= 2.0 && ((c / ow) as f32 - qy).abs() <= 2.0).collect();
                let (ux, uy) = direction(&near);
                let (dx, dy) = (x - qx, y - qy);
                let along = (dx * ux + dy * uy).abs();
                let across = (-dx * uy + dy * ux).abs();
                let half_cells = out[4 * n + q].max(0.0) * LENGTH_SCALE / STRIDE as f32;
                across < cfg.same_axis_cells && along < cfg.same_tube_fraction * half_cells
            });
            if !dup {
                mine.push(p);
            }
        }
        if mine.len() <= 1 {
            groups.push((mine.first().copied(), cells));
            continue;
        }
        // Split along the axes: each peak's direction from the cells near it.
        let dirs: Vec<(f32, f32)> = mine
            .iter()
            .map(|&p| {
                let (px, py) = ((p % ow) as isize, (p / ow) as isize);
                let near: Vec<usize> = cells.iter().copied().filter(|&c| ((c % ow) as isize - px).abs() <= 2 && ((c / ow) as isize - py).abs() <= 2).collect();
                direction(&near)
            })
            .collect();
        let mut parts: Vec<Vec<usize>> = vec![Vec::new(); mine.len()];
        for &c in &cells {
            let (x, y) = ((c % ow) as f32, (c / ow) as f32);
            let best = (0..mine.len())
                .min_by(|&a, &b| {
                    let d = |k: usize| {
                        let (px, py) = ((mine[k] % ow) as f32, (mine[k] / ow) as f32);
                        let (dx, dy) = (x - px, y - py);
                        let (ux, uy) = dirs[k];
                        let along = dx * ux + dy * uy;
                        let across = -dx * uy + dy * ux;
                        along.abs() + cfg.across_weight * across.abs()
                    };
                    d(a).total_cmp(&d(b))
                })
                .unwrap_or(0);
            parts[best].push(c);
        }
        for (k, part) in parts.into_iter().enumerate() {
            if !part.is_empty() {
                groups.push((Some(mine[k]), part));
            }
        }
    }
    let mut result = Vec::new();
    let mut cell_owner = vec![u32::MAX; n];
    for (gi, (_, cells)) in groups.iter().enumerate() {
        for &c in cells {
            cell_owner[c] = gi as u32;
        }
    }
    let fine = pred.fine.as_deref().filter(|_| cfg.fine_mask);
    let grow = fine.is_some() as usize;
    if grow == 1 {
        cell_owner = grown_owner(&cell_owner, &fg, ow, oh);
    }
    for (gi, (peak, cells)) in groups.iter().enumerate() {
        let mean_fg = cells.iter().map(|&c| fg[c]).sum::<f32>() / cells.len() as f32;
        let peak_v = peak.map(|p| heat[p]).unwrap_or(0.5 * mean_fg);
        let score = peak_v * mean_fg;
        if score < cfg.min_score {
            continue;
        }
        // Full-resolution mask inside the cells' pixel box.
        let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
        for &c in cells {
            let (x, y) = (c % ow, c / ow);
            x0 = x0.min(x);
            y0 = y0.min(y);
            x1 = x1.max(x);
            y1 = y1.max(y);
        }
        let px0 = (x0 * STRIDE).saturating_sub(STRIDE * (1 + grow));
        let py0 = (y0 * STRIDE).saturating_sub(STRIDE * (1 + grow));
        let px1 = ((x1 + 2 + grow) * STRIDE).min(width);
        let py1 = ((y1 + 2 + grow) * STRIDE).min(height);
        let mut mask = Plane::<u8>::new(width, height);
        let mut pix = Vec::new();
        let mut logit_sum = 0.0f64;
        let mut vals = Vec::new();
        for y in py0..py1 {
            let v = ((y as f32 - 1.5) / STRIDE as f32).clamp(0.0, (oh - 1) as f32);
            for x in px0..px1 {
                let u = ((x as f32 - 1.5) / STRIDE as f32).clamp(0.0, (ow - 1) as f32);
                // Owner: nearest cell.
                let nc = (v.round() as usize).min(oh - 1) * ow + (u.round() as usize).min(ow - 1);
                if cell_owner[nc] != gi as u32 {
                    continue;
                }
                let val = match fine {
                    Some(f) => f[y * width + x],
                    None => bilinear4_at(&out[..n], ow, oh, x, y),
                };
                if val > cfg.mask_logit {
                    logit_sum += val as f64;
                    mask.data[y * width + x] = 1;
                    pix.push((x as f64, y as f64));
                    vals.push(val);
                }
            }
        }
        if cfg.mask_logit_rel > 0.0 && !pix.is_empty() {
            let thr = cfg.mask_logit_rel as f64 * logit_sum / pix.len() as f64;
            let mut k = 0;
            pix.retain(|&(x, y)| {
                let keep = vals[k] as f64 > thr;
                k += 1;
                if !keep {
                    mask.data[y as usize * width + x as usize] = 0;
                }
                keep
            });
        }
        if pix.len() < cfg.min_area {
            continue;
        }
        // Network direction and length; centre at the peak when there is one.
        let (dx, dy) = direction(cells);
        let dir = if dx.abs() >= dy.abs() && dx < 0.0 || dy.abs() > dx.abs() && dy < 0.0 { (-dx, -dy) } else { (dx, dy) };
        let half = cells.iter().map(|&c| fg[c] * out[4 * n + c]).sum::<f32>() / cells.iter().map(|&c| fg[c]).sum::<f32>().max(1e-6);
        let pred_len = (half > 0.0).then_some((2.0 * half * LENGTH_SCALE) as f64);
        let peak_centre = peak.map(|p| {
            let (px, py) = ((p % ow) as isize, (p / ow) as isize);
            let (mut sw, mut sx, mut sy) = (0.0f32, 0.0f32, 0.0f32);
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let (xx, yy) = (px + dx, py + dy);
                    if xx >= 0 && yy >= 0 && (xx as usize) < ow && (yy as usize) < oh {
                        let w = heat[yy as usize * ow + xx as usize];
                        sw += w;
                        sx += w * xx as f32;
                        sy += w * yy as f32;
                    }
                }
            }
            [(sx / sw * STRIDE as f32 + 1.5) as f64, (sy / sw * STRIDE as f32 + 1.5) as f64]
        });
        let u = [dir.0 as f64, dir.1 as f64];
        let Some(mut axis) = AxisSeed::from_pixels(pix.iter().copied()) else { continue };
        let principal = axis.direction_px;
        let (bx0, by0, bx1, by1) = pix.iter().fold((f64::MAX, f64::MAX, f64::MIN, f64::MIN), |a, &(x, y)| (a.0.min(x), a.1.min(y), a.2.max(x), a.3.max(y)));
        let bbox = [bx0, by0, bx1 - bx0 + 1.0, by1 - by0 + 1.0];
        axis.direction_px = u;
        if let Some(len) = pred_len {
            axis.length_px = len;
        }
        if let Some(c) = peak_centre {
            axis.centre_px = c;
        }
        let perp = (-axis.direction_px[1], axis.direction_px[0]);
        let (lo, hi, alo, ahi) = pix.iter().fold((f64::MAX, f64::MIN, f64::MAX, f64::MIN), |a, &(x, y)| {
            let (rx, ry) = (x - axis.centre_px[0], y - axis.centre_px[1]);
            let t = rx * perp.0 + ry * perp.1;
            let l = rx * u[0] + ry * u[1];
            (a.0.min(t), a.1.max(t), a.2.min(l), a.3.max(l))
        });
        axis.width_px = (hi - lo + 1.0).max(1.0);
        let lm = ahi - alo + 1.0;
        let mut score = if cfg.mask_logit_weight > 0.0 {
            let mean_logit = logit_sum / vals.len() as f64;
            (1.0 / (1.0 + (-mean_logit).exp())).powf(cfg.mask_logit_weight as f64)
        } else {
            score as f64
        };
        if let (true, Some(lp)) = (cfg.length_weight > 0.0, pred_len) {
            score *= (lm.min(lp) / lm.max(lp).max(1e-9)).powf(cfg.length_weight as f64);
        }
        if cfg.fill_weight > 0.0 {
            score *= (pix.len() as f64 / (lm * axis.width_px)).min(1.0).powf(cfg.fill_weight as f64);
        }
        if score < cfg.min_score as f64 {
            continue;
        }
        if cfg.mask_direction_weight > 0.0 {
            let w = cfg.mask_direction_weight as f64 * if principal[0] * u[0] + principal[1] * u[1] < 0.0 { -1.0 } else { 1.0 };
            let (x, y) = (u[0] + w * principal[0], u[1] + w * principal[1]);
            let n = x.hypot(y);
            if n > 1e-9 {
                axis.direction_px = [x / n, y / n];
            }
        }
        result.push(LearnedInstance { score, mask: tubeloc_core::Rle::from_mask(&tubeloc_core::BinaryMask { width: mask.width, height: mask.height, data: mask.data }), bbox, axis });
    }
    result.sort_by(|a, b| b.score.total_cmp(&a.score));
    result
}

/// Instance ownership grown by one cell: an unowned cell takes the owner of its 8-neighbour
/// of highest foreground probability among the owned ones.
fn grown_owner(owner: &[u32], fg: &[f32], ow: usize, oh: usize) -> Vec<u32> {
    let mut grown = owner.to_vec();
    for y in 0..oh {
        for x in 0..ow {
            if owner[y * ow + x] != u32::MAX {
                continue;
            }
            let mut best = (f32::MIN, u32::MAX);
            for yy in y.saturating_sub(1)..(y + 2).min(oh) {
                for xx in x.saturating_sub(1)..(x + 2).min(ow) {
                    let c = yy * ow + xx;
                    if owner[c] != u32::MAX && fg[c] > best.0 {
                        best = (fg[c], owner[c]);
                    }
                }
            }
            grown[y * ow + x] = best.1;
        }
    }
    grown
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Stride-4 outputs (64 x 64 cells, 256 x 256 pixels) with horizontal bars: each bar is
    /// `(row, x0..x1 cells, fg logit, centre peak probability, predicted half-length in cells)`.
    fn bars(spec: &[(usize, std::ops::Range<usize>, f32, f32, f32)]) -> Prediction {
        let (ow, oh) = (64, 64);
        let n = ow * oh;
        let mut planes = vec![-6.0f32; HEADS * n];
        for (row, xs, logit, peak, half) in spec {
            for y in row - 1..=row + 1 {
                for x in xs.clone() {
                    let c = y * ow + x;
                    planes[c] = *logit;
                    planes[2 * n + c] = 1.0;
                    planes[3 * n + c] = 0.0;
                    planes[4 * n + c] = half * STRIDE as f32 / LENGTH_SCALE;
                }
            }
            let p = peak / (1.0 - peak);
            planes[n + row * ow + (xs.start + xs.end) / 2] = p.ln();
        }
        Prediction { planes, out_w: ow, out_h: oh, width: 256, height: 256, fine: None }
    }

    #[test]
    fn score_ranks_a_mask_whose_length_disagrees_with_the_predicted_length_lower() {
        // Two identical 20-cell bars (80 px); the second one's length head says 240 px.
        let pred = bars(&[(10, 10..30, 4.0, 0.9, 10.0), (40, 10..30, 4.0, 0.9, 30.0)]);
        let cfg = DecodeConfig::default();
        let inst = decode(&pred, &cfg);
        assert_eq!(inst.len(), 2);
        assert!(inst[0].axis.centre_px[1] < 100.0, "the consistent bar ranks first: {:?}", inst[0].axis);
        // Length agreement of the second: about 80 / 240, so its score is about (1/3)^0.5 of the first's.
        let ratio = inst[1].score / inst[0].score;
        assert!((ratio - (1.0f64 / 3.0).sqrt()).abs() < 0.05, "ratio {ratio}");
        // Without the length term both score the same.
        let flat = decode(&pred, &DecodeConfig { length_weight: 0.0, ..cfg });
        assert!((flat[0].score - flat[1].score).abs() < 1e-9, "{} vs {}", flat[0].score, flat[1].score);
    }

    #[test]
    fn mask_confidence_outranks_a_stronger_centre_peak() {
        // Bar A: sure pixels (logit 4), weak peak 0.4; bar B: unsure pixels (logit 1), peak 0.95.
        let pred = bars(&[(10, 10..30, 4.0, 0.4, 10.0), (40, 10..30, 1.0, 0.95, 10.0)]);
        let inst = decode(&pred, &DecodeConfig::default());
        assert_eq!(inst.len(), 2);
        assert!(inst[0].axis.centre_px[1] < 100.0 && inst[0].score > inst[1].score, "{:?}", inst.iter().map(|i| (i.score, i.axis.centre_px)).collect::<Vec<_>>());
        // A peak x mean fg score ranks them the other way round.
        let old = DecodeConfig { mask_logit_weight: 0.0, length_weight: 0.0, fill_weight: 0.0, ..DecodeConfig::default() };
        let inst = decode(&pred, &old);
        assert!(inst[0].axis.centre_px[1] > 100.0, "{:?}", inst.iter().map(|i| (i.score, i.axis.centre_px)).collect::<Vec<_>>());
    }

    #[test]
    fn axis_seed_direction_blends_the_head_with_the_mask_principal_axis() {
        // A horizontal bar whose direction head says 6 degrees.
        let mut pred = bars(&[(20, 10..40, 4.0, 0.9, 15.0)]);
        let n = pred.out_w * pred.out_h;
        let t = 12f32.to_radians();
        for c in 0..n {
            if pred.planes[c] > 0.0 {
                pred.planes[2 * n + c] = t.cos();
                pred.planes[3 * n + c] = t.sin();
            }
        }
        let angle = |cfg: &DecodeConfig| {
            let inst = decode(&pred, cfg);
            assert_eq!(inst.len(), 1);
            let [dx, dy] = inst[0].axis.direction_px;
            (dy.atan2(dx).to_degrees(), inst[0].score)
        };
        let (head, s0) = angle(&DecodeConfig { mask_direction_weight: 0.0, ..DecodeConfig::default() });
        let (blend, s2) = angle(&DecodeConfig { mask_direction_weight: 2.0, ..DecodeConfig::default() });
        assert!((head.abs() - 6.0).abs() < 0.1, "head {head}");
        // normalize(u + 2 p) with u at 6 degrees and p at 0: atan(sin 6 / (cos 6 + 2)).
        let expect = (6f64.to_radians().sin()).atan2(6f64.to_radians().cos() + 2.0).to_degrees();
        assert!((blend.abs() - expect).abs() < 0.2 && blend.signum() == head.signum(), "blend {blend}, expected {expect}");
        assert_eq!(s0, s2, "the score keeps the head's direction");
    }

    #[test]
    fn default_decoder_settings_validate_and_out_of_range_ones_are_named() {
        assert_eq!(DecodeConfig::default().validate(), Ok(()));
        let e = DecodeConfig { fg_threshold: 1.5, ..DecodeConfig::default() }.validate().unwrap_err();
        assert!(e.contains("fg_threshold = 1.5"), "{e}");
        let e = DecodeConfig { fill_weight: f32::NAN, ..DecodeConfig::default() }.validate().unwrap_err();
        assert!(e.contains("fill_weight"), "{e}");
    }
}
