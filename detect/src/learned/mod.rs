//! The learned tube segmenter: a small CNN trained from scratch on CPU (candle).
//!
//! See `README.md` beside this file (maintainer guide) and
//! `docs/design/0003-candle-with-own-convolution.md` for the choice of candle.
//! Pipeline: [`preprocess`] (gray + box filter by default) →
//! [`net::TubeNet`] (stride-4 foreground, centre heatmap, axis angle, half-length) →
//! [`decode`](mod@decode) (instances with mask, score and [`tubeloc_core::AxisSeed`]). Training:
//! [`augment`] crops, [`targets`], [`train::Trainer`]; weights: [`model::LearnedModel`]
//! (safetensors with format version and checksum); [`soup`] averages fine-tuned models;
//! [`shipped`] is the shipped model, embedded in the library.

pub mod augment;
pub mod dataset;
pub mod decode;
pub mod error;
pub mod hard_negatives;
pub mod layers;
pub mod model;
pub mod net;
pub mod optim;
pub mod preprocess;
pub mod rectangle;
pub mod shipped;
pub mod soup;
pub mod targets;
pub mod train;
pub mod widen;

pub use augment::{AugmentConfig, TrainImage};
pub use decode::{decode, predict_for, DecodeConfig, LearnedInstance};
pub use error::LearnedError;
pub use model::{LearnedModel, ModelMeta, Prediction, FORMAT_VERSION};
pub use net::{NetConfig, NetOutput};
pub use preprocess::Preprocess;
use rayon::prelude::*;
pub use shipped::shipped_model;
pub use soup::weight_average;
pub use train::{TrainConfig, Trainer};

/// Detects tubes in an interleaved RGB8 image (`width * height * 3` bytes).
pub fn detect_rgb(model: &LearnedModel, rgb: &[u8], width: usize, height: usize, cfg: &DecodeConfig) -> Result<Vec<LearnedInstance>, LearnedError> {
    if rgb.len() != width * height * 3 {
        return Err(LearnedError::Invalid(format!("RGB buffer has {} bytes, expected {}", rgb.len(), width * height * 3)));
    }
    let input = model.meta.preprocess.apply(rgb, width, height);
    Ok(shaped(decode(&predict_for(model, &input, width, height, cfg)?, cfg), cfg))
}

/// The instances, the masks of those narrower than [`DecodeConfig::rectangle_below_px`]
/// (axis seed width, image pixels) replaced by [`rectangle::rectangle_mask`] (an instance whose
/// rectangle is empty keeps its mask).
pub(super) fn shaped(mut instances: Vec<LearnedInstance>, cfg: &DecodeConfig) -> Vec<LearnedInstance> {
    let below = cfg.rectangle_below_px as f64;
    instances.par_iter_mut().filter(|i| i.axis.width_px < below).for_each(|i| {
        if let Some((mask, bbox)) = rectangle::rectangle_mask(&i.mask, i.axis.direction_px) {
            (i.mask, i.bbox) = (mask, bbox);
        }
    });
    instances
}

/// Detects tubes in an interleaved RGB8 image at working scale `s` ([`crate::scale`]): the
/// image is preprocessed at its own size, its planes resampled by `s`, the network run and
/// decoded there, and every instance mapped back to the original pixels (mask by nearest
/// sampling, box from the mapped mask, axis centre by `p = (p' + ½) / s - ½`, lengths by
/// `1 / s`). `s = 1` is [`detect_rgb`]. Instances whose mask vanishes on the way back are
/// dropped.
///
/// With [`DecodeConfig::second_scale`] `k > 0` and `s > 1`, the image is also detected at
/// `k s` (clamped to `[1/4, 4]`) and the two lists are merged in score order: an instance whose
/// mask overlaps a kept one at IoU > [`SCALE_MERGE_IOU`] is dropped.
pub fn detect_rgb_at_scale(model: &LearnedModel, rgb: &[u8], width: usize, height: usize, s: f64, cfg: &DecodeConfig) -> Result<Vec<LearnedInstance>, LearnedError> {
    let k = cfg.second_scale as f64;
    if k > 0.0 && s.is_finite() && s > 1.0 {
        let second = (k * s).clamp(0.25, 4.0);
        let one = DecodeConfig { second_scale: 0.0, ..*cfg };
        let mut all = detect_rgb_at_scale(model, rgb, width, height, s, &one)?;
        all.extend(detect_rgb_at_scale(model, rgb, width, height, second, &one)?);
        return Ok(merge_scales(all));
    }
    if rgb.len() != width * height * 3 {
        return Err(LearnedError::Invalid(format!("RGB buffer has {} bytes, expected {}", rgb.len(), width * height * 3)));
    }
    if !(s.is_finite() && s > 0.0) || s == 1.0 {
        return detect_planes_at_scale(model, model.meta.preprocess.apply(rgb, width, height), width, height, s, cfg);
    }
    let (nw, nh) = crate::scale::scaled_size(width, height, s);
    detect_scaled(model, &model.meta.preprocess.apply_resampled(rgb, width, height, nw, nh), (nw, nh), (width, height), cfg)
}

/// Mask IoU above which an instance found at the second scale is the same tube as a stronger
/// one ([`DecodeConfig::second_scale`]).
pub const SCALE_MERGE_IOU: f64 = 0.5;

/// Instances of several scales, strongest first, without those whose mask overlaps a stronger
/// kept one at IoU > [`SCALE_MERGE_IOU`] (ties in score keep the earlier instance).
fn merge_scales(mut all: Vec<LearnedInstance>) -> Vec<LearnedInstance> {
    all.sort_by(|a, b| b.score.total_cmp(&a.score));
    let mut kept: Vec<LearnedInstance> = Vec::with_capacity(all.len());
    for inst in all {
        // Masks are compared only where their boxes overlap.
        let same = kept.iter().filter(|k| boxes_overlap(&inst.bbox, &k.bbox)).any(|k| tubeloc_core::Rle::iou(std::slice::from_ref(&inst.mask), std::slice::from_ref(&k.mask), &[false])[0] > SCALE_MERGE_IOU);
        if !same {
            kept.push(inst);
        }
    }
    kept
}

/// Whether two COCO boxes `[x, y, w, h]` overlap with a positive area.
pub(crate) fn boxes_overlap(a: &[f64; 4], b: &[f64; 4]) -> bool {
    a[0] < b[0] + b[2] && b[0] < a[0] + a[2] && a[1] < b[1] + b[3] && b[1] < a[1] + a[3]
}

/// [`detect_rgb_at_scale`] on preprocessed input planes (`channels * width * height`).
pub fn detect_planes_at_scale(model: &LearnedModel, input: Vec<f32>, width: usize, height: usize, s: f64, cfg: &DecodeConfig) -> Result<Vec<LearnedInstance>, LearnedError> {
    if !(s.is_finite() && s > 0.0) {
        return Err(LearnedError::Invalid(format!("working scale {s} must be finite and > 0")));
    }
    if s == 1.0 {
        return Ok(shaped(decode(&predict_for(model, &input, width, height, cfg)?, cfg), cfg));
    }
    let (nw, nh) = crate::scale::scaled_size(width, height, s);
    let c = model.meta.preprocess.channels();
    let scaled = crate::scale::resample_planes(&input, c, width, height, nw, nh);
    drop(input);
    detect_scaled(model, &scaled, (nw, nh), (width, height), cfg)
}

/// Detects on input planes resampled to `(nw, nh)` and maps every instance back to the
/// original `(width, height)` pixels, as [`detect_rgb_at_scale`] describes.
fn detect_scaled(model: &LearnedModel, scaled: &[f32], (nw, nh): (usize, usize), (width, height): (usize, usize), cfg: &DecodeConfig) -> Result<Vec<LearnedInstance>, LearnedError> {
    let found = decode(&predict_for(model, scaled, nw, nh, cfg)?, cfg);
    let (sx, sy) = (nw as f64 / width as f64, nh as f64 / height as f64);
    let back = found
        .into_par_iter()
        .filter_map(|i| {
            let small = i.mask.to_bounded_mask().ok()?;
            let (mask, bbox) = crate::scale::mask_back_rle_in(&small.data, nw, nh, width, height, small.bbox());
            if mask.area() == 0 {
                return None;
            }
            let mut axis = i.axis;
            axis.centre_px = crate::scale::point_back(axis.centre_px, sx, sy);
            let (dx, dy) = (axis.direction_px[0] / sx, axis.direction_px[1] / sy);
            let dn = (dx * dx + dy * dy).sqrt();
            if dn > 0.0 {
                axis.direction_px = [dx / dn, dy / dn];
            }
            let sm = (sx * sy).sqrt();
            axis.length_px /= sm;
            axis.width_px /= sm;
            Some(LearnedInstance { score: i.score, mask, bbox, axis })
        })
        .collect();
    Ok(shaped(back, cfg))
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use tubeloc_core::{AxisSeed, BinaryMask, Rle};

    /// An instance whose mask is the rows 3-5 of columns `x0..x1` of a 40x10 image.
    pub(crate) fn instance(score: f64, x0: usize, x1: usize) -> LearnedInstance {
        let mask = BinaryMask::from_fn(40, 10, |x, y| (x0..x1).contains(&x) && (3..6).contains(&y));
        let axis = AxisSeed { centre_px: [(x0 + x1) as f64 / 2.0, 4.0], direction_px: [1.0, 0.0], length_px: (x1 - x0) as f64, width_px: 3.0 };
        LearnedInstance { score, bbox: mask.bbox(), mask: Rle::from_mask(&mask), axis }
    }

    /// Two scales' instances merge strongest first: the weaker copy of a tube (mask IoU > 0.5)
    /// goes, a partly overlapping or separate tube stays.
    #[test]
    fn scales_merge_by_mask_overlap_in_score_order() {
        let merged = merge_scales(vec![instance(0.4, 0, 10), instance(0.9, 1, 11), instance(0.5, 6, 16), instance(0.3, 25, 35)]);
        let kept: Vec<f64> = merged.iter().map(|i| i.score).collect();
        assert_eq!(kept, vec![0.9, 0.5, 0.3], "IoU(0-10, 1-11) = 9/11 merges; IoU(1-11, 6-16) = 5/15 does not");
    }

    /// Masks of tubes narrower than `rectangle_below_px` become rectangles; a wider tube and
    /// the setting 0 keep the network's mask.
    #[test]
    fn only_narrow_tubes_masks_become_rectangles() {
        // A ragged bar: rows 3-5 of columns 5-30, its end columns one row thin.
        let ragged = BinaryMask::from_fn(40, 10, |x, y| (5..31).contains(&x) && (3..6).contains(&y) && !((x == 5 || x == 30) && y != 4));
        let narrow = LearnedInstance { score: 0.9, bbox: ragged.bbox(), mask: Rle::from_mask(&ragged), axis: AxisSeed { centre_px: [17.5, 4.0], direction_px: [1.0, 0.0], length_px: 26.0, width_px: 3.0 } };
        let wide = LearnedInstance { axis: AxisSeed { width_px: 20.0, ..narrow.axis }, ..narrow.clone() };
        let bar = Rle::from_mask(&BinaryMask::from_fn(40, 10, |x, y| (5..31).contains(&x) && (3..6).contains(&y)));
        let out = shaped(vec![narrow.clone(), wide.clone()], &DecodeConfig::default());
        assert_eq!(out[0].mask, bar, "the narrow tube's mask is its rectangle");
        assert_eq!((out[0].score, out[0].axis), (narrow.score, narrow.axis));
        assert_eq!(out[1].mask, wide.mask, "a tube wider than the working width keeps its mask");
        let off = shaped(vec![narrow.clone()], &DecodeConfig { rectangle_below_px: 0.0, ..DecodeConfig::default() });
        assert_eq!(off[0].mask, narrow.mask);
    }

    /// The second scale runs only for enlarged images: a frame at scale 1 or shrunk gives the
    /// same instances with and without it.
    #[test]
    fn second_scale_runs_only_for_enlarged_images() {
        assert_eq!(DecodeConfig::default().second_scale, 0.0, "off by default");
        let model = shipped_model().unwrap();
        let rgb: Vec<u8> = (0..96 * 80 * 3).map(|i| ((i * 37 + i / 7) % 251) as u8).collect();
        let (on, off) = (DecodeConfig { second_scale: 0.6, ..DecodeConfig::default() }, DecodeConfig { second_scale: 0.0, ..DecodeConfig::default() });
        for s in [1.0, 0.5] {
            let a = detect_rgb_at_scale(&model, &rgb, 96, 80, s, &off).unwrap();
            let b = detect_rgb_at_scale(&model, &rgb, 96, 80, s, &on).unwrap();
            assert_eq!(a.iter().map(|i| (i.score, i.bbox)).collect::<Vec<_>>(), b.iter().map(|i| (i.score, i.bbox)).collect::<Vec<_>>(), "scale {s}");
        }
        let bad = DecodeConfig { second_scale: -1.0, ..DecodeConfig::default() };
        assert!(bad.validate().unwrap_err().contains("second_scale"));
    }
}
