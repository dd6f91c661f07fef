//! The shipped learned detector and its score calibration, embedded in the library, so that a
//! program built on it (an installed or copied `tubeloc`) runs with its defaults and no data
//! folder.
//!
//! The model is [`tubeloc_detect::learned::shipped`] (`data/models/tubenet.safetensors`); its
//! calibration is the text of `data/models/tubenet.calibration.json` (fitted by `tubeloc eval
//! --calibrate` on real validation composites: probability of a tube, and the threshold for
//! precision >= 0.95).

use crate::detector::LearnedDetector;
use crate::error::{PipelineError, Result};
use tubeloc_core::ScoreCalibration;
use tubeloc_detect::learned::shipped::{shipped_model, SHIPPED_MODEL_NAME};
use tubeloc_detect::learned::DecodeConfig;

/// The file the embedded calibration comes from, relative to the workspace root.
pub const SHIPPED_CALIBRATION_NAME: &str = "data/models/tubenet.calibration.json";

/// The shipped model's score calibration (JSON text of [`ScoreCalibration`]).
pub const SHIPPED_CALIBRATION_JSON: &str = include_str!("../../data/models/tubenet.calibration.json");

/// The shipped model's score calibration, parsed and validated.
pub fn shipped_calibration() -> Result<ScoreCalibration> {
    let bad = |m: String| PipelineError::Input(format!("embedded score calibration {SHIPPED_CALIBRATION_NAME}: {m}"));
    let c: ScoreCalibration = serde_json::from_str(SHIPPED_CALIBRATION_JSON).map_err(|e| bad(e.to_string()))?;
    c.validate().map_err(|e| bad(e.to_string()))?;
    Ok(c)
}

impl LearnedDetector {
    /// The learned detector with the shipped model (embedded), named
    /// `data/models/tubenet.safetensors (embedded)` in error messages.
    pub fn shipped(decode: DecodeConfig) -> Result<Self> {
        let model = shipped_model().map_err(|e| PipelineError::Detect(format!("loading the embedded model: {e}")))?;
        Ok(Self::new(model, decode, format!("{SHIPPED_MODEL_NAME} (embedded)")))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_embedded_calibration_is_the_shipped_file() {
        let file = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(SHIPPED_CALIBRATION_NAME);
        let from_file: ScoreCalibration = serde_json::from_slice(&std::fs::read(file).unwrap()).unwrap();
        let c = shipped_calibration().unwrap();
        assert_eq!(c, from_file);
        // The shipped threshold was chosen for precision >= 0.95.
        assert_eq!(c.target_precision, 0.95);
        assert!(c.threshold > 0.0 && c.threshold < 1.0, "{c:?}");
    }
}
