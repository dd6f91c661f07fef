//! The shipped learned detector and its score calibration, embedded in the library, so that a
//! program built on it (an installed or copied `tubeloc`) runs with its defaults and no data
//! folder.
//!
//! The model is [`tubeloc_detect::learned::shipped`] (`data/models/tubenet.safetensors`); its
//! calibration is the text of `data/models/tubenet.calibration.json` (fitted by `tubeloc eval
//! --calibrate` on real validation composites: probability of a tube, and the threshold for
//! precision >= 0.95).
//!
//! The learned detector, its calibration and the working-scale band are built here the way
//! `tubeloc locate` builds them, so that every front end (the CLI, the Python package) makes
//! the same [`crate::Locator`] from the same options; error messages are the CLI's (they name
//! the option, e.g. `--range-m`, and the file at fault).

use crate::detector::{FusedTubeDetector, LearnedDetector, Line2dTubeDetector};
use crate::error::{PipelineError, Result};
use crate::pose_verifier::PoseVerifier;
use std::path::Path;
use tubeloc_core::{PoseEvidence, ScoreCalibration};
use tubeloc_detect::learned::shipped::{shipped_model, SHIPPED_MODEL_NAME};
use tubeloc_detect::learned::DecodeConfig;
use tubeloc_detect::line2d::TemplateLibrary;
use tubeloc_detect::scale::RangeBand;

/// The file the embedded calibration comes from, relative to the workspace root.
pub const SHIPPED_CALIBRATION_NAME: &str = "data/models/tubenet.calibration.json";

/// The shipped model's score calibration (JSON text of [`ScoreCalibration`]).
pub const SHIPPED_CALIBRATION_JSON: &str = include_str!("../../data/models/tubenet.calibration.json");

/// The shipped model's score calibration, parsed and validated.
pub fn shipped_calibration() -> Result<ScoreCalibration> {
    embedded_calibration(SHIPPED_CALIBRATION_NAME, SHIPPED_CALIBRATION_JSON)
}

/// The file the embedded pose evidence comes from, relative to the workspace root.
pub const SHIPPED_POSE_EVIDENCE_NAME: &str = "data/models/tubenet.pose_evidence.json";

/// The shipped model's pose evidence (JSON text of [`PoseEvidence`]): the probability that a
/// refined pose is a tube from the shipped model's score and the fit's evidence, fitted by
/// `tubeloc eval --fit-pose-evidence` on the snapped detections of real validation composites
/// (record 0066).
pub const SHIPPED_POSE_EVIDENCE_JSON: &str = include_str!("../../data/models/tubenet.pose_evidence.json");

/// The pose evidence `spec` names: `shipped` (the embedded one, [`SHIPPED_POSE_EVIDENCE_JSON`])
/// or the path of a file written by `tubeloc eval --fit-pose-evidence`; parsed and validated.
pub fn pose_evidence(spec: &str) -> Result<PoseEvidence> {
    let (name, text) = if spec == "shipped" {
        (SHIPPED_POSE_EVIDENCE_NAME.to_string(), SHIPPED_POSE_EVIDENCE_JSON.to_string())
    } else {
        (spec.to_string(), std::fs::read_to_string(spec).map_err(|e| PipelineError::Input(format!("reading pose evidence {spec}: {e}")))?)
    };
    let bad = |m: String| PipelineError::Input(format!("pose evidence {name}: {m}"));
    let m: PoseEvidence = serde_json::from_str(&text).map_err(|e| bad(e.to_string()))?;
    m.validate().map_err(bad)?;
    Ok(m)
}

/// The settings `tubeloc locate --detector DETECTOR` runs with: the defaults, the score
/// calibration ([`locator_calibration`]: `calibration` when given, else the detector's
/// model's) and, with a floor `min_pose_evidence` > 0, the pose evidence
/// ([`locator_pose_evidence`]) of the learned model (`model` `None`: the shipped one); with 0
/// none is looked for. The floor must be a probability.
pub fn locate_settings(detector: &str, calibration: Option<&Path>, model: Option<&Path>, min_pose_evidence: f64) -> Result<crate::LocatorSettings> {
    if !(0.0..=1.0).contains(&min_pose_evidence) {
        return Err(PipelineError::Input(format!("min_pose_evidence {min_pose_evidence}: expected a probability in [0, 1]")));
    }
    let pose_evidence = match min_pose_evidence > 0.0 {
        true => locator_pose_evidence(detector, model)?,
        false => None,
    };
    Ok(crate::LocatorSettings { calibration: locator_calibration(detector, calibration, model)?, pose_evidence, min_pose_evidence, ..Default::default() })
}

/// The pose evidence `tubeloc locate` checks the tubes of `detector` against
/// ([`crate::LocatorSettings::pose_evidence`]): for the learned detector with the shipped model
/// (`model` = `None`) the shipped one; with a model file, `<model>.pose_evidence.json` beside it
/// when there is one (else none, with a warning on stderr, as the evidence's score feature is
/// that model's); none for the other detectors (Line2D's and the fused detector's scores are
/// already pose-based, an external detector's scores are its own).
pub fn locator_pose_evidence(detector: &str, model: Option<&Path>) -> Result<Option<PoseEvidence>> {
    match (detector, model) {
        ("learned", None) => pose_evidence("shipped").map(Some),
        ("learned", Some(m)) => {
            let beside = m.with_extension("pose_evidence.json");
            if beside.exists() {
                return pose_evidence(&beside.to_string_lossy()).map(Some);
            }
            eprintln!("warning: no pose evidence for {} ({} is missing): tubes are handed over on the score calibration alone; fit one with `tubeloc eval --fit-pose-evidence`", m.display(), beside.display());
            Ok(None)
        }
        _ => Ok(None),
    }
}

/// The file the fused detector's embedded calibration comes from, relative to the workspace
/// root.
pub const FUSED_CALIBRATION_NAME: &str = "data/models/fused.calibration.json";

/// The fused detector's score calibration (JSON text of [`ScoreCalibration`]): fitted on the
/// fused detections ([`crate::FusedTubeDetector`]: the shipped model's and the default template
/// library's, by their pose evidence) on real validation composites, as the shipped model's
/// own (record 0069).
pub const FUSED_CALIBRATION_JSON: &str = include_str!("../../data/models/fused.calibration.json");

/// The fused detector's score calibration: with the shipped model (`model` = `None`) the
/// embedded one; with another model the identity (probability = fused score, threshold 0.5)
/// with a warning on stderr, since the embedded one was fitted on the shipped model's scores.
pub fn fused_calibration(model: Option<&Path>) -> Result<ScoreCalibration> {
    if let Some(m) = model {
        eprintln!("warning: the fused detector's calibration was fitted with the shipped model, not {}: probabilities are the raw fused scores (pass --calibration to set one)", m.display());
        return Ok(ScoreCalibration::identity());
    }
    embedded_calibration(FUSED_CALIBRATION_NAME, FUSED_CALIBRATION_JSON)
}

/// The score calibration `tubeloc locate --detector DETECTOR` hands tubes over with:
/// `calibration` (`--calibration`) when given; else the learned model's ([`load_calibration`]),
/// the fused detector's ([`fused_calibration`]), or for other detectors none (probability =
/// score, threshold 0: every converged tube).
pub fn locator_calibration(detector: &str, calibration: Option<&Path>, model: Option<&Path>) -> Result<ScoreCalibration> {
    match (calibration, detector) {
        (Some(p), _) => load_calibration(Some(p), None),
        (None, "learned") => load_calibration(None, model),
        (None, "fused") => fused_calibration(model),
        (None, _) => Ok(crate::LocatorSettings::default().calibration),
    }
}

/// An embedded calibration `json` (from the file `name`), parsed and validated.
fn embedded_calibration(name: &str, json: &str) -> Result<ScoreCalibration> {
    let bad = |m: String| PipelineError::Input(format!("embedded score calibration {name}: {m}"));
    let c: ScoreCalibration = serde_json::from_str(json).map_err(|e| bad(e.to_string()))?;
    c.validate().map_err(|e| bad(e.to_string()))?;
    Ok(c)
}

impl LearnedDetector {
    /// The learned detector with the shipped model (embedded), named
    /// `data/models/tubenet.safetensors (embedded)` in error messages.
    pub fn shipped(decode: DecodeConfig) -> Result<Self> {
        let (model, origin) = learned_model(None)?;
        Ok(Self::new(model, decode, origin))
    }
}

/// The score calibration of a model: `path` when given; else for a model file
/// `<model>.calibration.json` beside it, or the identity (probability = score, threshold 0.5)
/// with a warning on stderr when there is none; for the shipped model (`model` = `None`) its
/// embedded calibration.
pub fn load_calibration(path: Option<&Path>, model: Option<&Path>) -> Result<ScoreCalibration> {
    let p = match (path, model) {
        (Some(p), _) => p.to_path_buf(),
        (None, None) => return shipped_calibration(),
        (None, Some(model)) => {
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

/// The learned detector of `tubeloc locate`: the weights at `model` (default: the shipped,
/// embedded model) with the default decoder, run at the working scale of the band `range_m`
/// ("NEAR:FAR" metres, or "off"; see [`parse_range_band`]).
pub fn learned_detector(model: Option<&Path>, range_m: &str) -> Result<LearnedDetector> {
    let (weights, origin) = learned_model(model)?;
    let mut d = LearnedDetector::new(weights, Default::default(), origin);
    d.range = parse_range_band(range_m)?;
    Ok(d)
}

/// The weights at `model` (`--model`; the shipped, embedded model when `None`) and their name
/// in error messages.
fn learned_model(model: Option<&Path>) -> Result<(tubeloc_detect::learned::LearnedModel, String)> {
    match model {
        None => Ok((shipped_model().map_err(|e| PipelineError::Detect(format!("loading the embedded model: {e}")))?, format!("{SHIPPED_MODEL_NAME} (embedded)"))),
        Some(m) if !m.exists() => Err(PipelineError::Input(format!("learned model {} not found: pass an existing --model FILE, or leave --model out to use the shipped model", m.display()))),
        Some(m) => Ok((tubeloc_detect::learned::LearnedModel::load(m).map_err(|e| PipelineError::Detect(format!("loading model {}: {e}", m.display())))?, m.display().to_string())),
    }
}

/// The template library at `templates` (`--templates LIB.tlt`), or without one the default
/// library ([`TemplateLibrary::default_library`], built in memory in about 1 s: the library
/// the real stage of `tubeloc bench` measures).
pub fn template_library(templates: Option<&Path>) -> Result<TemplateLibrary> {
    match templates {
        Some(lib) => TemplateLibrary::load(lib).map_err(|e| PipelineError::Input(format!("reading {}: {}", lib.display(), error_chain(&e)))),
        None => TemplateLibrary::default_library().map_err(|e| PipelineError::Detect(format!("building the default template library: {e}"))),
    }
}

/// Line2D with the template library `templates` names ([`template_library`]), the default
/// matching parameters and the shipped clutter verifier.
fn line2d_matcher(templates: Option<&Path>) -> Result<tubeloc_detect::line2d::Line2dDetector> {
    tubeloc_detect::line2d::Line2dDetector::new(template_library(templates)?, Default::default()).map_err(|e| PipelineError::Detect(e.to_string()))
}

/// The Line2D detector of `tubeloc locate --detector line2d [--templates LIB.tlt]`: the library
/// ([`template_library`]: the default one without a file) with the default matching parameters and the shipped clutter verifier, its candidates
/// verified by their poses with the pose verifier `pose_verifier` names
/// ([`line2d_pose_verifier`]; `None`: none, the clutter verifier's cut alone).
pub fn line2d_detector(templates: Option<&Path>, pose_verifier: Option<&str>) -> Result<Line2dTubeDetector> {
    let matcher = line2d_matcher(templates)?;
    match pose_verifier {
        Some(spec) => Line2dTubeDetector::verified(matcher, line2d_pose_verifier(spec)?),
        None => Ok(Line2dTubeDetector::new(matcher)),
    }
}

/// The file the embedded Line2D pose verifier comes from, relative to the workspace root.
pub const SHIPPED_LINE2D_POSE_VERIFIER_NAME: &str = "data/models/line2d.pose_verifier.json";

/// The shipped Line2D pose verifier (JSON text of [`PoseVerifier`]): the pose evidence of the
/// default library's candidates, fitted by `tubeloc eval --fit-pose-evidence` on real
/// validation composites, and its cuts per image kind, chosen by `tubeloc eval
/// --fit-pose-verifier` on the tube-free validation frames (record 0068).
pub const SHIPPED_LINE2D_POSE_VERIFIER_JSON: &str = include_str!("../../data/models/line2d.pose_verifier.json");

/// The Line2D pose verifier `spec` names: `shipped` (the embedded one,
/// [`SHIPPED_LINE2D_POSE_VERIFIER_JSON`]) or the path of a file written by `tubeloc eval
/// --fit-pose-verifier`; parsed and validated.
pub fn line2d_pose_verifier(spec: &str) -> Result<PoseVerifier> {
    if spec == "shipped" {
        return PoseVerifier::from_json(SHIPPED_LINE2D_POSE_VERIFIER_JSON, SHIPPED_LINE2D_POSE_VERIFIER_NAME);
    }
    let text = std::fs::read_to_string(spec).map_err(|e| PipelineError::Input(format!("reading pose verifier {spec}: {e}")))?;
    PoseVerifier::from_json(&text, spec)
}

/// The fused detector of `tubeloc locate --detector fused [--templates LIB.tlt] [--model M]
/// [--range-m R]`: the learned detector as [`learned_detector`] with the shipped model's pose
/// evidence, and Line2D as [`line2d_detector`] verified by the shipped pose verifier (record
/// 0069). With another model than the shipped one its detections are scored by the shipped
/// model's pose evidence, with a warning on stderr.
pub fn fused_detector(templates: Option<&Path>, model: Option<&Path>, range_m: &str) -> Result<FusedTubeDetector> {
    let line2d = line2d_matcher(templates)?;
    let learned = learned_detector(model, range_m)?;
    if let Some(m) = model {
        eprintln!("warning: the fused detector scores learned detections by the shipped model's pose evidence, not one fitted for {}", m.display());
    }
    FusedTubeDetector::new(learned, pose_evidence("shipped")?, line2d, line2d_pose_verifier("shipped")?)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The shipped file `name` (relative to the workspace root): its path and its parsed JSON.
    fn shipped_file<T: serde::de::DeserializeOwned>(name: &str) -> (std::path::PathBuf, T) {
        let file = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(name);
        let parsed = serde_json::from_slice(&std::fs::read(&file).unwrap()).unwrap();
        (file, parsed)
    }

    #[test]
    fn the_embedded_calibration_is_the_shipped_file() {
        let (_, from_file): (_, ScoreCalibration) = shipped_file(SHIPPED_CALIBRATION_NAME);
        let c = shipped_calibration().unwrap();
        assert_eq!(c, from_file);
        // The shipped threshold was chosen for precision >= 0.95.
        assert_eq!(c.target_precision, 0.95);
        assert!(c.threshold > 0.0 && c.threshold < 1.0, "{c:?}");
    }

    #[test]
    fn the_embedded_fused_calibration_is_its_file() {
        let (_, from_file): (_, ScoreCalibration) = shipped_file(FUSED_CALIBRATION_NAME);
        let c = fused_calibration(None).unwrap();
        assert_eq!(c, from_file);
        assert_eq!(c.target_precision, 0.95);
        assert!(c.threshold > 0.0 && c.threshold < 1.0, "{c:?}");
        assert_eq!(fused_calibration(Some(Path::new("other.safetensors"))).unwrap(), ScoreCalibration::identity());
    }

    #[test]
    fn the_embedded_pose_evidence_is_its_file_and_bad_files_are_named() {
        let (file, from_file): (_, PoseEvidence) = shipped_file(SHIPPED_POSE_EVIDENCE_NAME);
        let m = pose_evidence("shipped").unwrap();
        assert_eq!(m, from_file);
        assert_eq!(pose_evidence(file.to_str().unwrap()).unwrap(), m);
        assert!(m.fitted_on.contains("--split val"), "{}", m.fitted_on);
        // The fit's evidence counts the right way on real frames: more contour on edges, a
        // higher score, a sharper axis make a tube more likely.
        assert!(m.weights[0] > 0.0 && m.weights[1] > 0.0 && m.weights[2] > 0.0 && m.weights[4] < 0.0, "{m:?}");
        let e = pose_evidence("absent_evidence.json").unwrap_err().to_string();
        assert!(e.contains("reading pose evidence absent_evidence.json"), "{e}");
    }

    #[test]
    fn the_embedded_line2d_pose_verifier_is_its_file() {
        let (file, from_file): (_, PoseVerifier) = shipped_file(SHIPPED_LINE2D_POSE_VERIFIER_NAME);
        let v = line2d_pose_verifier("shipped").unwrap();
        assert_eq!(v, from_file);
        assert_eq!(line2d_pose_verifier(file.to_str().unwrap()).unwrap(), v);
        // Fitted and cut on the validation part; a candidate with more contour on edges and a
        // higher clutter probability is more likely a tube.
        assert!(v.evidence.fitted_on.contains("real_val_all") && v.fitted_on.contains("--split val"), "{v:?}");
        assert!(v.evidence.weights[0] > 0.0 && v.evidence.weights[2] > 0.0, "{v:?}");
        // Grey clutter under an assumed camera passes more often: its cut is the higher one.
        assert!(v.threshold_grey > v.threshold && v.threshold > 0.0 && v.threshold_grey < 1.0, "{v:?}");
        let e = line2d_pose_verifier("absent_verifier.json").unwrap_err().to_string();
        assert!(e.contains("reading pose verifier absent_verifier.json"), "{e}");
    }

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
        assert!(err.starts_with("learned model /nonexistent/m.safetensors not found: pass an existing --model FILE"), "{err}");
    }
}
