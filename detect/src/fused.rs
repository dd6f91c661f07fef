//! Fused detection: Line2D candidates scored by the learned segmenter's agreement.
//!
//! Line2D finds a tube's silhouette and coarse pose from gradient orientations, and its clutter
//! verifier ([`crate::line2d::classify`]) gives each candidate a probability `P` from
//! radiometric features. On real grey frames rock edges give contours and contrasts as good
//! as a far tube's, so `P` alone ranks far tubes below clutter. The learned segmenter sees
//! appearance instead of contour, and on real frames it rarely fires on the clutter that
//! Line2D keeps (1.3 % of the Line2D candidates on tube-free grey validation frames overlap a
//! learned instance), while its masks of far tubes are too loose to be counted.
//!
//! The **agreement** `L` of a candidate is the highest score of a learned instance whose mask
//! overlaps the candidate's silhouette at IoU ≥ `min_iou` (0 when none does). The fused score
//! is the product
//!
//! ```text
//! S = P L
//! ```
//!
//! in `[0, 1]`; candidates with `S ≥ threshold` (> 0) are kept, strongest first, with Line2D's
//! silhouette, box and coarse pose. A candidate the network does not see is dropped whatever
//! its verifier probability: on the real validation composites such candidates with P ≥ 0.84
//! were tubes 9 times in 77. `S` ranks detections; it is not a calibrated probability.

use crate::learned::{detect_rgb_at_scale, DecodeConfig, LearnedInstance, LearnedModel};
use crate::line2d::{Line2dDetection, Line2dDetector};
use crate::scale::{working_scale, RangeBand};
use tubeloc_core::{CameraModel, GroundPlane, Rle};

/// Settings of the fusion (see the module doc; JSON: missing fields keep their defaults).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FusionParams {
    /// Least mask IoU between a candidate's silhouette and a learned instance for the instance
    /// to count as agreeing, in `(0, 1]`.
    pub min_iou: f64,
    /// Least fused score of a kept detection, in `[0, 1]`.
    pub threshold: f32,
}

impl Default for FusionParams {
    /// Chosen on the real validation composites (record 0063): the highest mean AP50 over the
    /// two grey sets and the colour set with at most 0.5 false detections per tube-free grey
    /// and per tube-free colour validation frame, and among equal AP50 the highest cut.
    fn default() -> Self {
        FusionParams { min_iou: 0.3, threshold: 0.02 }
    }
}

impl FusionParams {
    /// Checks the ranges in the field docs, naming the field that is out of range.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.min_iou > 0.0 && self.min_iou <= 1.0) {
            return Err(format!("min_iou {} must be in (0, 1]", self.min_iou));
        }
        if !(self.threshold > 0.0 && self.threshold <= 1.0) {
            return Err(format!("threshold {} must be in (0, 1]", self.threshold));
        }
        Ok(())
    }
}

/// The fused score `S = P L` of a candidate with Line2D score `probability` and agreement
/// `agreement` (both in `[0, 1]`).
pub fn fused_score(probability: f32, agreement: f32) -> f32 {
    probability * agreement
}

/// The agreement of the learned instances with a candidate silhouette `mask` (box `bbox`,
/// COCO `[x, y, w, h]`, pixels): the highest score among the instances whose mask overlaps it
/// at IoU ≥ `min_iou`, 0 when none does. Masks are compared only where boxes overlap.
pub fn agreement(mask: &Rle, bbox: &[f64; 4], learned: &[LearnedInstance], min_iou: f64) -> f32 {
    learned.iter().filter(|i| crate::learned::boxes_overlap(bbox, &i.bbox)).filter(|i| Rle::iou(std::slice::from_ref(&i.mask), std::slice::from_ref(mask), &[false])[0] >= min_iou).map(|i| i.score as f32).fold(0.0, f32::max)
}

/// Scores every Line2D candidate by its agreement with `learned` (instances of the same
/// image), sets its `agreement` and its `score` to the fused score, and keeps those at or above
/// `params.threshold`, strongest first (ties keep Line2D's order). The candidate's Line2D
/// score (the clutter verifier's probability when it ran) is `P`.
pub fn fuse(candidates: Vec<Line2dDetection>, learned: &[LearnedInstance], params: &FusionParams) -> Vec<Line2dDetection> {
    let mut kept: Vec<Line2dDetection> = candidates
        .into_iter()
        .filter_map(|mut d| {
            let l = agreement(&d.mask, &d.bbox, learned, params.min_iou);
            let s = fused_score(d.score, l);
            d.agreement = Some(l);
            d.score = s;
            (s >= params.threshold).then_some(d)
        })
        .collect();
    kept.sort_by(|a, b| b.score.total_cmp(&a.score));
    kept
}

/// A fused detector: Line2D (every candidate its verifier scores, whatever the verifier's own
/// cut) and the learned segmenter at its working scale, fused per image (see the module doc).
pub struct FusedDetector {
    line2d: Line2dDetector,
    model: LearnedModel,
    decode: DecodeConfig,
    /// Distances of the tubes for the learned detector's working scale; `None`: the image as
    /// it is.
    pub range: Option<RangeBand>,
    /// The fusion's settings.
    pub params: FusionParams,
}

impl FusedDetector {
    /// A fused detector. The Line2D clutter verifier's cut is set to 0, so that every
    /// candidate it scores reaches the fusion; the learned detector runs with `decode` at the
    /// working scale of `range`.
    pub fn new(mut line2d: Line2dDetector, model: LearnedModel, decode: DecodeConfig, range: Option<RangeBand>, params: FusionParams) -> Result<Self, String> {
        params.validate()?;
        decode.validate()?;
        if let Some(v) = line2d.params.verifier.as_mut() {
            v.set_threshold(0.0);
        }
        Ok(FusedDetector { line2d, model, decode, range, params })
    }

    /// The Line2D detector (library and matching parameters).
    pub fn line2d(&self) -> &Line2dDetector {
        &self.line2d
    }

    /// Detects tubes in an interleaved RGB8 image taken by `camera` (the library's camera when
    /// `None`), with the ground (camera frame) when known: Line2D candidates as
    /// [`Line2dDetector::detect_on_ground`], learned instances at the working scale of `camera`
    /// and `ground` ([`crate::scale::working_scale`]; the image as it is without a camera),
    /// then [`fuse`].
    pub fn detect(&self, rgb: &[u8], width: usize, height: usize, camera: Option<&CameraModel>, ground: Option<&GroundPlane>) -> Result<Vec<Line2dDetection>, String> {
        let candidates = self.line2d.detect_on_ground(rgb, width, height, camera, ground).map_err(|e| e.to_string())?;
        let s = match (self.range, camera) {
            (Some(band), Some(cam)) => working_scale(cam, ground.map(|g| (g.normal, g.offset)), band),
            _ => 1.0,
        };
        let learned = detect_rgb_at_scale(&self.model, rgb, width, height, s, &self.decode).map_err(|e| e.to_string())?;
        Ok(fuse(candidates, &learned, &self.params))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learned::tests::instance as learned;

    /// `S = P L`: full agreement keeps `P`, none drops the candidate under any threshold.
    #[test]
    fn fused_score_follows_the_formula() {
        assert_eq!(fused_score(0.9, 1.0), 0.9);
        assert_eq!(fused_score(1.0, 0.0), 0.0);
        assert!((fused_score(0.8, 0.4) - 0.32).abs() < 1e-6);
    }

    /// The agreement is the best score among instances overlapping at IoU ≥ min_iou; an
    /// instance beside the silhouette or barely touching it does not count.
    #[test]
    fn agreement_takes_the_best_overlapping_instance() {
        let cand = learned(0.0, 10, 20);
        let list = [learned(0.3, 11, 21), learned(0.6, 12, 22), learned(0.9, 18, 28), learned(0.95, 30, 40)];
        // IoU(10-20, 11-21) = 9/11, (10-20, 12-22) = 8/12, (10-20, 18-28) = 2/18.
        assert_eq!(agreement(&cand.mask, &cand.bbox, &list, 0.3), 0.6);
        assert_eq!(agreement(&cand.mask, &cand.bbox, &list, 0.7), 0.3);
        assert_eq!(agreement(&cand.mask, &cand.bbox, &list, 0.9), 0.0);
        assert_eq!(agreement(&cand.mask, &cand.bbox, &[], 0.3), 0.0);
    }

    #[test]
    fn params_out_of_range_are_named() {
        assert!(FusionParams::default().validate().is_ok());
        assert!(FusionParams { min_iou: 0.0, ..Default::default() }.validate().unwrap_err().contains("min_iou"));
        assert!(FusionParams { threshold: 0.0, ..Default::default() }.validate().unwrap_err().contains("threshold"));
        assert!(FusionParams { threshold: 1.5, ..Default::default() }.validate().unwrap_err().contains("threshold"));
    }
}
