//! Pose verification: a detection is kept when the pose refined from it explains the image as a
//! tube does (record 0068).
//!
//! Each candidate is refined in mono on the frame's ground ([`crate::frame::refine_frame`]; the ground's
//! orientation is a prior, its height is not a constraint), its mask is snapped to the pose's
//! silhouette ([`snapped_detection`]), and it is scored by a [`PoseEvidence`]: the probability
//! `P = σ(b + Σ w_i (f_i − μ_i) / s_i)` that the pose is a tube, from the detector's score and
//! the fit's evidence. Candidates are taken most probable first; one whose snapped mask overlaps
//! a kept one at IoU above [`PoseVerifier::nms_iou`] is dropped, and those at or above the cut
//! of the image's kind (grey: three equal channels; colour) are kept. A verifier with
//! [`PoseVerifier::max_limb_continuation`] first sets aside the candidates whose limbs go on
//! past their ends (record 0080; the shipped Line2D verifier has none).
//!
//! [`PoseVerification`] runs it on the Line2D matcher's candidates: the matcher runs with its
//! clutter verifier's cut lowered to a floor, and without a ground plane (or a camera of the
//! image's size) the clutter verifier's own cut applies instead.

use crate::error::{PipelineError, Result};
use crate::frame::{refine_pixels, Frame, FrameOptions, FramePixels, SeedItem};
use crate::settings::LocatorSettings;
use crate::stages::snapped_detection;
use image::DynamicImage;
use serde::{Deserialize, Serialize};
use tubeloc_core::{keep_by_iou, CameraModel, GroundPlane, PoseEvidence, TubeAxisPose, TubeDetection};
use tubeloc_detect::line2d::{Line2dDetection, Line2dDetector, Verifier};
use tubeloc_refine::Refiner;

/// The evidence model of a detector's refined poses and the cuts that keep a candidate.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseVerifier {
    /// The probability that a refined pose is a tube, fitted on the detector's candidates
    /// (`tubeloc eval --fit-pose-evidence`).
    pub evidence: PoseEvidence,
    /// Cut on the probability for colour images.
    pub threshold: f64,
    /// Cut on the probability for grey images (all three channels equal, e.g. Navcam).
    pub threshold_grey: f64,
    /// Snapped-mask IoU above which the less probable of two candidates is dropped.
    pub nms_iou: f64,
    /// The largest limb continuation of a kept candidate ([`tubeloc_refine::limb_continuation`]:
    /// how strongly the edges along its pose's limbs go on past its ends, against along its
    /// body); `None` (absent from the file): no such check.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_limb_continuation: Option<f64>,
    /// How the cuts were chosen (command, data, bound).
    #[serde(default)]
    pub fitted_on: String,
}

/// What became of one candidate.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// At or above the cut, overlapping no more probable kept candidate.
    Kept,
    /// Its snapped mask overlaps a more probable kept candidate's.
    Overlapping,
    /// Its probability is below the cut of the image's kind.
    BelowCut,
    /// The edges along its limbs go on past its ends beyond
    /// [`PoseVerifier::max_limb_continuation`]: a rim or a layer of rock, not a tube.
    LimbsContinue,
}

/// One verified candidate.
#[derive(Clone, Debug)]
pub struct PoseVerdict {
    /// Its index in the candidates given.
    pub index: usize,
    /// The candidate with its mask snapped to the pose (where they agree) and the probability
    /// as its score.
    pub detection: TubeDetection,
    /// The pose refined from it (camera frame, metres; its `score` is the detector's).
    pub pose: TubeAxisPose,
    /// The probability that the pose is a tube.
    pub probability: f64,
    /// Kept, or why not.
    pub verdict: Verdict,
}

impl PoseVerifier {
    /// Parses and checks a pose verifier's JSON; `name` names it in errors.
    pub fn from_json(text: &str, name: &str) -> Result<Self> {
        let bad = |m: String| PipelineError::Input(format!("pose verifier {name}: {m}"));
        let v: PoseVerifier = serde_json::from_str(text).map_err(|e| bad(e.to_string()))?;
        v.validate().map_err(bad)?;
        Ok(v)
    }

    /// Checks the evidence model, cuts in `[0, 1]` and an IoU in `(0, 1]`.
    pub fn validate(&self) -> std::result::Result<(), String> {
        self.evidence.validate()?;
        for (name, t) in [("threshold", self.threshold), ("threshold_grey", self.threshold_grey)] {
            if !(0.0..=1.0).contains(&t) {
                return Err(format!("{name} {t} is not a probability"));
            }
        }
        if !(self.nms_iou > 0.0 && self.nms_iou <= 1.0) {
            return Err(format!("nms_iou {} is not in (0, 1]", self.nms_iou));
        }
        if let Some(c) = self.max_limb_continuation.filter(|c| !(c.is_finite() && *c > 0.0)) {
            return Err(format!("max_limb_continuation {c} is not a positive number"));
        }
        Ok(())
    }

    /// The cut for an image that is grey (`grey`) or colour.
    pub fn threshold_for(&self, grey: bool) -> f64 {
        if grey {
            self.threshold_grey
        } else {
            self.threshold
        }
    }

    /// The refinement settings of the verification: the defaults, with the ground's height not
    /// a constraint (a nominal ground: the terrain has relief about it) and no merging.
    pub fn refinement_settings() -> LocatorSettings {
        let mut s = LocatorSettings::default();
        s.refine.priors.ground_height_known = false;
        s.merge_duplicates = false;
        s
    }

    /// Refines every candidate of `frame` (mono; its ground), snaps and scores each, and
    /// decides which are kept ([`Verdict`]). Returns one verdict per candidate, most probable
    /// first (ties in candidate order). `grey`: the image's kind.
    pub fn verify(&self, refiner: &Refiner, settings: &LocatorSettings, frame: &Frame, candidates: &[TubeDetection], grey: bool) -> Result<Vec<PoseVerdict>> {
        let items: Vec<SeedItem> = candidates.iter().cloned().map(SeedItem::Detection).collect();
        // The frame's grey levels, converted once for the fits and the limb check.
        let px = FramePixels::of(frame.image, settings.colour_ends);
        let refined = refine_pixels(refiner, settings, frame, &px, &items, &FrameOptions::default())?;
        let snap = settings.stages.snap;
        let mut verdicts: Vec<PoseVerdict> = candidates
            .iter()
            .zip(refined.poses)
            .enumerate()
            .map(|(index, (d, pose))| {
                let mut detection = d.clone();
                snapped_detection(&mut detection, &pose, refiner, frame.camera, &snap);
                let probability = self.evidence.probability(&pose);
                detection.score = probability;
                PoseVerdict { index, detection, pose, probability, verdict: Verdict::BelowCut }
            })
            .collect();
        verdicts.sort_by(|a, b| b.probability.total_cmp(&a.probability).then(a.index.cmp(&b.index)));
        // Most probable first: those at or above the cut are the leading ones; of them, those
        // whose limbs go on past their ends are set aside before the suppression.
        let above = verdicts.partition_point(|v| v.probability >= self.threshold_for(grey));
        let going_on: Vec<bool> = verdicts[..above]
            .iter()
            .map(|v| match self.max_limb_continuation {
                Some(max) if v.pose.converged => tubeloc_refine::limb_continuation::limb_continuation(&px.gray, frame.camera, &settings.tube, &v.pose).is_some_and(|c| c > max),
                _ => false,
            })
            .collect();
        let masks: Vec<Option<&tubeloc_core::Rle>> = verdicts[..above].iter().zip(&going_on).map(|(v, &g)| if g { None } else { v.detection.mask.as_ref() }).collect();
        let keep = keep_by_iou(&masks, self.nms_iou);
        for ((v, k), g) in verdicts.iter_mut().zip(keep).zip(going_on) {
            v.verdict = match (g, k) {
                (true, _) => Verdict::LimbsContinue,
                (false, true) => Verdict::Kept,
                (false, false) => Verdict::Overlapping,
            };
        }
        Ok(verdicts)
    }
}

/// Line2D's verification by pose: the pose verifier, the refiner it runs, and the clutter
/// verifier whose own cuts apply where no pose can be refined.
pub struct PoseVerification {
    /// The pose verifier.
    pub verifier: PoseVerifier,
    /// The clutter verifier with its own cuts ([`Verifier::threshold_for_search`]).
    pub clutter: Verifier,
    refiner: Refiner,
    settings: LocatorSettings,
}

/// The clutter verifier's cut below which Line2D candidates do not reach the pose verifier:
/// every candidate it scores does.
pub const CLUTTER_FLOOR: f32 = 0.0;

impl PoseVerification {
    /// A verification with `verifier`; `clutter` is the matcher's clutter verifier with its own
    /// cuts (the matcher itself runs with a lower floor, [`PoseVerification::floor_of`]).
    pub fn new(verifier: PoseVerifier, clutter: Verifier) -> Result<Self> {
        let settings = PoseVerifier::refinement_settings();
        let refiner = Refiner::new(&settings.tube, settings.refine.clone()).map_err(|e| PipelineError::Input(format!("pose verification's refiner: {e}")))?;
        Ok(PoseVerification { verifier, clutter, refiner, settings })
    }

    /// The refiner and settings the verification refines with.
    pub(crate) fn refinement(&self) -> (&Refiner, &LocatorSettings) {
        (&self.refiner, &self.settings)
    }

    /// The verification of `matcher`'s candidates by `verifier`: `matcher`'s clutter verifier
    /// is kept with its own cuts (for images without a ground) and the matcher's is lowered to
    /// `floor` for every image, so that the candidates above it reach the pose verifier. Errors
    /// when the matcher has no clutter verifier (its probability is the evidence's score).
    pub fn for_matcher(matcher: &mut Line2dDetector, verifier: PoseVerifier, floor: f32) -> Result<Self> {
        let clutter = matcher.params.verifier.clone().ok_or_else(|| PipelineError::Input("pose verification needs the Line2D clutter verifier: its probability is the pose evidence's score".into()))?;
        let mut lowered = clutter.clone();
        lowered.set_threshold(floor);
        matcher.params.verifier = Some(lowered);
        Self::new(verifier, clutter)
    }

    /// Line2D on `image` (of `camera`, on `ground`) verified by pose: the matcher's candidates
    /// (`matcher`, its clutter cut at the floor) refined, scored and kept as
    /// [`PoseVerifier::verify`] decides, most probable first, each with its mask and box
    /// snapped, its score and `pose_probability` the probability. Without a ground plane, or
    /// without a camera of the image's size, the candidates at the clutter verifier's own cut
    /// ([`Verifier::threshold_for_search`]) instead; the flag says whether poses verified them.
    pub fn detect(&self, matcher: &Line2dDetector, image: &DynamicImage, camera: Option<&CameraModel>, ground: Option<&GroundPlane>, image_id: u64) -> Result<(Vec<Line2dDetection>, bool)> {
        let rgb = tubeloc_detect::input::rgb8_pixels(image);
        let (w, h) = (image.width() as usize, image.height() as usize);
        let candidates = matcher.detect_on_ground(&rgb, w, h, camera, ground).map_err(|e| PipelineError::Detect(e.to_string()))?;
        let grey = tubeloc_detect::input::is_grey_rgb8(&rgb);
        let own = camera.filter(|c| (c.width as usize, c.height as usize) == (w, h));
        let (Some(own), Some(ground)) = (own, ground) else {
            // The cut the matcher would have applied: the search it ran used `camera`.
            let cut = self.clutter.threshold_for_search(grey, matcher.searched_twice(grey, camera));
            return Ok((candidates.into_iter().filter(|d| d.probability.is_none_or(|p| p >= cut)).collect(), false));
        };
        let dets: Vec<TubeDetection> = candidates.iter().map(|d| d.to_tube_detection(image_id)).collect();
        let frame = Frame { image, camera: own, image_id, ground: Some(*ground), stereo: None };
        let verdicts = self.verifier.verify(&self.refiner, &self.settings, &frame, &dets, grey)?;
        let kept = verdicts
            .into_iter()
            .filter(|v| v.verdict == Verdict::Kept)
            .map(|v| {
                let mut d = candidates[v.index].clone();
                d.score = v.probability as f32;
                d.pose_probability = Some(v.probability as f32);
                d.bbox = v.detection.bbox;
                if let Some(m) = v.detection.mask {
                    d.mask = m;
                }
                d
            })
            .collect();
        Ok((kept, true))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn verifier() -> PoseVerifier {
        let evidence = PoseEvidence { features: tubeloc_core::pose_evidence::EVIDENCE_FEATURE_NAMES.map(String::from).to_vec(), mean: [0.0; 5], scale: [1.0; 5], weights: [1.0, 0.0, 0.0, 0.0, 0.0], bias: 0.0, fitted_on: String::new() };
        PoseVerifier { evidence, threshold: 0.1, threshold_grey: 0.05, nms_iou: 0.5, max_limb_continuation: None, fitted_on: String::new() }
    }

    #[test]
    fn cuts_follow_the_kind_and_bad_files_are_refused_with_the_reason() {
        let v = verifier();
        assert_eq!((v.threshold_for(false), v.threshold_for(true)), (0.1, 0.05));
        let text = serde_json::to_string(&v).unwrap();
        assert_eq!(PoseVerifier::from_json(&text, "v.json").unwrap(), v);
        let bad = text.replace("\"threshold_grey\":0.05", "\"threshold_grey\":1.5");
        assert_eq!(PoseVerifier::from_json(&bad, "v.json").unwrap_err().to_string(), "pose verifier v.json: threshold_grey 1.5 is not a probability");
        let bad = text.replace("\"nms_iou\":0.5", "\"nms_iou\":0.0");
        assert!(PoseVerifier::from_json(&bad, "v.json").unwrap_err().to_string().contains("nms_iou 0 is not in (0, 1]"));
        let e = PoseVerifier::from_json("{}", "v.json").unwrap_err().to_string();
        assert!(e.starts_with("pose verifier v.json: missing field"), "{e}");
        // The limb check: absent, none; present, a positive number.
        assert!(!text.contains("max_limb_continuation"));
        let with = PoseVerifier { max_limb_continuation: Some(0.6), ..verifier() };
        assert_eq!(PoseVerifier::from_json(&serde_json::to_string(&with).unwrap(), "v.json").unwrap(), with);
        let bad = serde_json::to_string(&PoseVerifier { max_limb_continuation: Some(-1.0), ..verifier() }).unwrap();
        assert!(PoseVerifier::from_json(&bad, "v.json").unwrap_err().to_string().contains("max_limb_continuation -1 is not a positive number"));
    }
}
