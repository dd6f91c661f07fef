//! The learned tube segmenter: a small CNN trained from scratch on CPU (candle).
//!
//! See `README.md` beside this file (maintainer guide) and
//! `docs/design/0003-candle-with-own-convolution.md` for the choice of candle.
//! Pipeline: [`preprocess`] (gray + box filter by default) →
//! [`net::TubeNet`] (stride-4 foreground, centre heatmap, axis angle, half-length) →
//! [`decode`] (instances with mask, score and [`tubeloc_core::AxisSeed`]). Training:
//! [`augment`] crops, [`targets`], [`train::Trainer`]; weights: [`model::LearnedModel`]
//! (safetensors with format version and checksum); [`soup`] averages fine-tuned models;
//! [`shipped`] is the shipped model, embedded in the library.

pub mod augment;
pub mod dataset;
pub mod decode;
pub mod error;
pub mod layers;
pub mod model;
pub mod net;
pub mod optim;
pub mod preprocess;
pub mod shipped;
pub mod soup;
pub mod targets;
pub mod train;

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
    Ok(decode(&predict_for(model, &input, width, height, cfg)?, cfg))
}

/// Detects tubes in an interleaved RGB8 image at working scale `s` ([`crate::scale`]): the
/// image is preprocessed at its own size, its planes resampled by `s`, the network run and
/// decoded there, and every instance mapped back to the original pixels (mask by nearest
/// sampling, box from the mapped mask, axis centre by `p = (p' + ½) / s - ½`, lengths by
/// `1 / s`). `s = 1` is [`detect_rgb`]. Instances whose mask vanishes on the way back are
/// dropped.
pub fn detect_rgb_at_scale(model: &LearnedModel, rgb: &[u8], width: usize, height: usize, s: f64, cfg: &DecodeConfig) -> Result<Vec<LearnedInstance>, LearnedError> {
    if rgb.len() != width * height * 3 {
        return Err(LearnedError::Invalid(format!("RGB buffer has {} bytes, expected {}", rgb.len(), width * height * 3)));
    }
    if !(s.is_finite() && s > 0.0) || s == 1.0 {
        return detect_planes_at_scale(model, model.meta.preprocess.apply(rgb, width, height), width, height, s, cfg);
    }
    let (nw, nh) = crate::scale::scaled_size(width, height, s);
    detect_scaled(model, &model.meta.preprocess.apply_resampled(rgb, width, height, nw, nh), (nw, nh), (width, height), cfg)
}

/// [`detect_rgb_at_scale`] on preprocessed input planes (`channels * width * height`).
pub fn detect_planes_at_scale(model: &LearnedModel, input: Vec<f32>, width: usize, height: usize, s: f64, cfg: &DecodeConfig) -> Result<Vec<LearnedInstance>, LearnedError> {
    if !(s.is_finite() && s > 0.0) {
        return Err(LearnedError::Invalid(format!("working scale {s} must be finite and > 0")));
    }
    if s == 1.0 {
        return Ok(decode(&predict_for(model, &input, width, height, cfg)?, cfg));
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
    Ok(found
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
        .collect())
}
