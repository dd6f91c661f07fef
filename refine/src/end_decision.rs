//! Which end of a fitted axis is the seal end ([`crate::settings::EndDecision`]): from the
//! colours where the fitted silhouette shows both the seal section and the body
//! ([`crate::seal_end`]), else by fitting the flipped hypothesis and comparing the two fits'
//! edge support ([`crate::fit::FitResult::score`]).

use crate::contour::AxisState;
use crate::detection_seed::EndColour;
use crate::fit::{self, FitResult};
use crate::refiner::Refiner;
use crate::seal_end;
use crate::seed::Seed;
use crate::seed_fit::{to_pose, FitFrame};
use crate::seed_policy::FitSettings;
use nalgebra::Vector3;
use tubeloc_core::CameraModel;

/// The seed whose fit's end is decided, and what the pose reports.
pub(crate) struct EndHypotheses<'a> {
    /// COCO image id of the pose.
    pub image_id: u64,
    /// The detector's score.
    pub score: f64,
    /// The seed (`end_known`: the detector claims the end).
    pub seed: &'a Seed,
    /// The seed's unit axis.
    pub seed_axis: Vector3<f64>,
}

/// The fit `a` or its flipped hypothesis, whichever the evidence favours, and the end
/// confidence. With colours (`ends`) that show both sections, they decide: the flipped
/// hypothesis is fitted (its sections placed) when they favour it, else `a` is simply turned
/// end to end. Without them the flipped hypothesis is fitted from the second-coarsest level and
/// the lower score wins, with confidence `1 / (1 + exp(-|Δscore| / score_scale))`; a seed that
/// claims its end (a template pose) is overruled only with at least `override_confidence`
/// (small tubes often cannot tell the ends apart in grey levels). Without the decision the
/// confidence is 0.5 (0.6 when the seed claims its end).
pub(crate) fn decide_end(refiner: &Refiner, cfg: &FitSettings, frame: &FitFrame, a: FitResult, hyp: &EndHypotheses, ends: Option<&EndColour>, cam: &CameraModel) -> (FitResult, f64) {
    let model = &refiner.model;
    let flip_fit = |st: &AxisState| fit::fit(model, cfg, &frame.pyr, frame.top.min(1), &frame.scene, AxisState { c: st.c, a: -st.a });
    let colour_evidence = ends.and_then(|e| {
        let pose = to_pose(hyp.image_id, hyp.score, &a, 0.5);
        (a.failure.is_none()).then(|| seal_end::seal_end_evidence(model, &pose, cam, e.image, e.visible)).flatten()
    });
    if let (true, Some(ev)) = (cfg.end_decision.enabled, colour_evidence) {
        let p = seal_end::end_confidence(&ev);
        if ev.contrast >= 0.0 {
            return (a, p);
        }
        let b = flip_fit(&a.state);
        if b.failure.is_none() {
            return (b, p);
        }
        return (FitResult { state: AxisState { c: a.state.c, a: -a.state.a }, ..a }, p);
    }
    if !(cfg.end_decision.enabled && a.failure.is_none()) {
        return (a, if hyp.seed.end_known { 0.6 } else { 0.5 });
    }
    let b = flip_fit(&a.state);
    let dscore = if b.failure.is_none() { b.score - a.score } else { 1.0 };
    let p = 1.0 / (1.0 + (-dscore.abs() / cfg.end_decision.score_scale).exp());
    let keeps_claim = hyp.seed.end_known && a.state.a.dot(&hyp.seed_axis) > 0.0;
    if dscore < 0.0 && (!keeps_claim || p >= cfg.end_decision.override_confidence) {
        (b, p)
    } else if dscore < 0.0 {
        (a, 0.5)
    } else {
        (a, p)
    }
}
