//! The shipped learned model, its score calibration and the learned detector's working-scale
//! band, found and loaded the way `tubeloc locate` does it, so that every front end (the CLI,
//! the Python package) builds the same [`crate::Locator`] from the same options.
//!
//! Error messages are those the CLI prints (they name the option, e.g. `--range-m`, and the
//! file at fault).

use crate::detector::LearnedDetector;
use crate::error::{PipelineError, Result};
use std::path::{Path, PathBuf};
use tubeloc_core::ScoreCalibration;
use tubeloc_detect::scale::RangeBand;

/// The shipped model's path relative to the repository root.
pub const SHIPPED_MODEL: &str = "data/models/tubenet.safetensors";

/// The shipped model (`data/models/tubenet.safetensors`), looked up under the current
/// directory, then in the workspace the executable sits in (`<ws>/target/<profile>/tubeloc`),
/// then in the source tree the program was built from (`CARGO_MANIFEST_DIR/..`).
pub fn default_model() -> PathBuf {
    let rel = Path::new(SHIPPED_MODEL);
    let mut candidates = vec![rel.to_path_buf()];
    if let Some(ws) = std::env::current_exe().ok().and_then(|e| e.parent()?.parent()?.parent().map(Path::to_path_buf)) {
        candidates.push(ws.join(rel));
    }
    let built = Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(rel);
    candidates.into_iter().find(|p| p.exists()).unwrap_or(built)
}

/// The score calibration of a model: `path` when given, else `<model>.calibration.json` beside
/// the model (`data/models/tubenet.calibration.json` for the shipped one), else the identity
/// (probability = score, threshold 0.5) with a warning on stderr.
pub fn load_calibration(path: Option<&Path>, model: &Path) -> Result<ScoreCalibration> {
    let p = match path {
        Some(p) => p.to_path_buf(),
        None => {
            let beside = model.with_extension("calibration.json");
            if !beside.exists() {
                eprintln!("warning: no score calibration beside {} ({}): probabilities are the raw scores", model.display(), beside.display());
                return Ok(ScoreCalibration::identity());
            }
            beside
        }
    };
    let c: ScoreCalibration = tubeloc_core::files::read_json(&p).map_err(|e| PipelineError::Input(format!("reading score calibration {}: {}", p.display(), error_chain(&e))))?;
    c.validate().map_err(|e| PipelineError::Input(format!("score calibration {}: {e}", p.display())))?;
    Ok(c)
}

/// An error and its sources, each after ": " (as the CLI prints errors).
pub fn error_chain(e: &(dyn std::error::Error + 'static)) -> String {
    let mut text = e.to_string();
    let mut source = e.source();
    while let Some(s) = source {
        text.push_str(": ");
        text.push_str(&s.to_string());
        source = s.source();
    }
    text
}

/// Parses a tube-range band "NEAR:FAR" (metres, 0 < NEAR < FAR) or "off" (no working scale:
/// the learned detector sees the image as it is).
pub fn parse_range_band(s: &str) -> Result<Option<RangeBand>> {
    if s == "off" {
        return Ok(None);
    }
    let bad = |m: String| PipelineError::Input(format!("--range-m {s:?}: {m}"));
    let (a, b) = s.split_once(':').ok_or_else(|| bad("expected NEAR:FAR in metres, or off".into()))?;
    let near_m = a.trim().parse().map_err(|e| bad(format!("NEAR is not a number: {e}")))?;
    let far_m = b.trim().parse().map_err(|e| bad(format!("FAR is not a number: {e}")))?;
    let band = RangeBand { near_m, far_m };
    band.validate().map_err(bad)?;
    Ok(Some(band))
}

/// The learned detector of `tubeloc locate`: the weights at `model` (default: [`default_model`])
/// with the default decoder, run at the working scale of the band `range_m` ("NEAR:FAR" metres,
/// or "off"; see [`parse_range_band`]).
pub fn learned_detector(model: Option<&Path>, range_m: &str) -> Result<LearnedDetector> {
    let model = model.map(Path::to_path_buf).unwrap_or_else(default_model);
    if !model.exists() {
        return Err(PipelineError::Input(format!("learned model {} not found: pass --model FILE, or restore the shipped data/models/tubenet.safetensors (data/models/README.md has the command that trains it)", model.display())));
    }
    let mut d = LearnedDetector::load(&model, Default::default())?;
    d.range = parse_range_band(range_m)?;
    Ok(d)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn range_band_errors_name_the_option_and_the_problem() {
        assert_eq!(parse_range_band("off").unwrap(), None);
        let b = parse_range_band("1:4").unwrap().unwrap();
        assert_eq!((b.near_m, b.far_m), (1.0, 4.0));
        assert_eq!(parse_range_band("14").unwrap_err().to_string(), "--range-m \"14\": expected NEAR:FAR in metres, or off");
        assert_eq!(parse_range_band("x:4").unwrap_err().to_string(), "--range-m \"x:4\": NEAR is not a number: invalid float literal");
        assert_eq!(parse_range_band("4:1").unwrap_err().to_string(), "--range-m \"4:1\": range band 4..1 m: need 0 < near < far, finite");
    }

    #[test]
    fn a_missing_model_is_named_with_the_way_out() {
        let err = learned_detector(Some(Path::new("/nonexistent/m.safetensors")), "1:4").err().unwrap().to_string();
        assert!(err.starts_with("learned model /nonexistent/m.safetensors not found: pass --model FILE"), "{err}");
    }
}
