//! The learned tube segmenter: a small CNN trained from scratch on CPU (candle).
//!
//! See `README.md` beside this file (maintainer guide) and
//! `docs/design/0003-candle-with-own-convolution.md` for the choice of candle.
//! Pipeline: [`preprocess`] (gray + box filter by default) →
//! [`net::TubeNet`] (stride-4 foreground, centre heatmap, axis angle, half-length) →
//! [`decode`] (instances with mask, score and [`tubeloc_core::AxisSeed`]). Training:
//! [`augment`] crops, [`targets`], [`train::Trainer`]; weights: [`model::LearnedModel`]
//! (safetensors with format version and checksum); [`soup`] averages fine-tuned models.

pub mod augment;
pub mod dataset;
pub mod decode;
pub mod error;
pub mod layers;
pub mod model;
pub mod net;
pub mod optim;
pub mod preprocess;
pub mod soup;
pub mod targets;
pub mod train;

pub use augment::{AugmentConfig, TrainImage};
pub use decode::{decode, DecodeConfig, LearnedInstance};
pub use error::LearnedError;
pub use model::{LearnedModel, ModelMeta, Prediction, FORMAT_VERSION};
pub use net::{NetConfig, NetOutput};
pub use preprocess::Preprocess;
pub use soup::weight_average;
pub use train::{TrainConfig, Trainer};

/// Detects tubes in an interleaved RGB8 image (`width * height * 3` bytes).
pub fn detect_rgb(model: &LearnedModel, rgb: &[u8], width: usize, height: usize, cfg: &DecodeConfig) -> Result<Vec<LearnedInstance>, LearnedError> {
    if rgb.len() != width * height * 3 {
        return Err(LearnedError::Invalid(format!("RGB buffer has {} bytes, expected {}", rgb.len(), width * height * 3)));
    }
    let input = model.meta.preprocess.apply(rgb, width, height);
    Ok(decode(&model.predict_with(&input, width, height, cfg)?, cfg))
}
