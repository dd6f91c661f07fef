//! The fit of one seed ([`Refiner::fit_seed`]), in its steps: the seed is checked, the region
//! of interest and its gradient pyramid are built ([`Refiner::region`]), the coarse-search
//! hypotheses and the seed are fitted ([`Refiner::fit_candidates`]), the seal end is decided
//! ([`crate::end_decision`]), and with stereo points the edges re-place the tube in the image
//! ([`stereo_edge_polish`]).

use crate::contour::AxisState;
use crate::detection_seed::EndColour;
use crate::edges::{self, GradientLevel};
use crate::end_decision::{decide_end, EndHypotheses};
use crate::fit::{self, FitResult};
use crate::refiner::{stereo_supports_fit, RefineInput, Refiner};
use crate::scene::Scene;
use crate::search;
use crate::seed::Seed;
use crate::seed_policy::FitSettings;
use nalgebra::{Point3, Vector3};
use tubeloc_core::{CameraModel, FailureReason, TubeAxisPose};

/// One seed to fit, with what its pose reports besides the fit.
pub(crate) struct SeedToFit<'a> {
    /// The seed.
    pub seed: &'a Seed,
    /// COCO image id of the pose.
    pub image_id: u64,
    /// The detector's score, copied to the pose.
    pub score: f64,
    /// COCO box `[x, y, w, h]` that widens the region of interest.
    pub bbox: Option<[f64; 4]>,
    /// The colours that decide the seal end, if any.
    pub ends: Option<EndColour<'a>>,
}

/// A fit's gradient pyramid over its region of interest, the coarsest level used, and the
/// scene with the input's ground plane.
pub(crate) struct FitFrame<'a> {
    /// Levels, index 0 full resolution.
    pub pyr: Vec<GradientLevel>,
    /// Coarsest level fitted.
    pub top: usize,
    /// The input's scene with `ground` from the input when the scene has none.
    pub scene: Scene<'a>,
}

impl Refiner {
    /// Fits `job.seed` with `cfg` (the settings of its seed kind) and returns the pose.
    pub(crate) fn fit_seed(&self, cfg: &FitSettings, input: &RefineInput, job: &SeedToFit) -> TubeAxisPose {
        let (cam, image_id, score) = (input.camera, job.image_id, job.score);
        if input.image.width != cam.width as usize || input.image.height != cam.height as usize {
            let msg = format!("image is {}x{} but the camera is {}x{}", input.image.width, input.image.height, cam.width, cam.height);
            return failed(image_id, score, Some(&job.seed.state), FailureReason::BadSeed, msg);
        }
        let st = job.seed.state;
        if !(st.c.iter().all(|v| v.is_finite()) && st.a.iter().all(|v| v.is_finite())) || st.a.norm() < 1e-9 || st.c.z <= 0.0 {
            return failed(image_id, score, None, FailureReason::BadSeed, "seed is not finite or is behind the camera".into());
        }
        let st = AxisState { c: st.c, a: st.a.normalize() };
        let Some((rect, top)) = self.region(cfg, cam, &st, job.bbox) else {
            return failed(image_id, score, Some(&st), FailureReason::OutOfImage, "the seed projects outside the image".into());
        };
        // Unsmoothed full-resolution gradients only for narrow tubes (fitted at full resolution
        // alone), where smoothing merges a limb's shading ramp with its step.
        let pyr = edges::build_pyramid_with(input.image, cam, rect, top + 1, top > 0);
        let top = top.min(pyr.len() - 1);
        let frame = FitFrame { pyr, top, scene: Scene { ground: input.scene.ground.or(input.ground), ..input.scene } };
        let mut a = self.fit_candidates(cfg, &frame, &st);
        if a.failure.is_some() && cfg.end_decision.enabled {
            // A template flipped end to end misplaces the sections; retry the other end.
            let b = fit::fit(&self.model, cfg, &frame.pyr, top, &frame.scene, AxisState { c: st.c, a: -st.a });
            if b.failure.is_none() {
                a = b;
            }
        }
        let hyp = EndHypotheses { image_id, score, seed: job.seed, seed_axis: st.a };
        let (mut best, conf) = decide_end(self, cfg, &frame, a, &hyp, job.ends.as_ref(), cam);
        if cfg.solver.stereo_edge_polish && !frame.scene.stereo_points.is_empty() && frame.scene.mask.is_none() && best.failure.is_none() {
            best.state = stereo_edge_polish(&self.model, cfg, &frame, &best);
        }
        to_pose(image_id, score, &best, conf)
    }

    /// Fits from the coarse-search hypotheses ([`search::coarse_search`]) and the seed itself,
    /// best scored first, up to `seed_search.max_hypotheses` fits: the best hypothesis and the
    /// seed are both fitted and the better final score ([`FitResult::score`]) wins; further
    /// hypotheses are tried only while none succeeded. Returns the first failure when all fail.
    fn fit_candidates(&self, cfg: &FitSettings, frame: &FitFrame, st: &AxisState) -> FitResult {
        let (pyr, top, scene) = (&frame.pyr, frame.top, &frame.scene);
        let mut cands: Vec<AxisState> = Vec::new();
        let ss = &cfg.seed_search;
        if ss.enabled {
            let spec = search::SearchSpec { radius_px: ss.radius_px as i32, step_px: ss.step_px as i32, max_rotation_deg: ss.rotation_deg, rotation_step_deg: ss.rotation_step_deg, max_samples: ss.max_samples };
            let hyps = search::coarse_search(&self.model, &pyr[top], st, scene.ground.as_ref(), cfg.priors.ground_height_known, &spec);
            cands.extend(hyps.iter().map(|h| h.state));
        }
        // The seed itself goes second (or first without the search).
        cands.insert(cands.len().min(1), *st);
        let mut first_fail = None;
        let mut best: Option<FitResult> = None;
        for (k, c) in cands.iter().take(ss.max_hypotheses.max(1)).enumerate() {
            let r = fit::fit(&self.model, cfg, pyr, top, scene, *c);
            if r.failure.is_none() {
                if best.as_ref().is_none_or(|b| r.score < b.score) {
                    best = Some(r);
                }
                if k >= 1 {
                    break;
                }
                continue;
            }
            first_fail.get_or_insert(r);
        }
        if let Some(b) = best {
            return b;
        }
        first_fail.expect("at least the seed is fitted")
    }

    /// Region of interest (crop rectangle) and coarsest pyramid level for a state: the crop
    /// covers the state's projection and `bbox`, with a margin for the edge and seed searches;
    /// the coarsest level keeps the body at least `solver.min_body_width_px` wide.
    fn region(&self, cfg: &FitSettings, cam: &CameraModel, st: &AxisState, bbox: Option<[f64; 4]>) -> Option<((usize, usize, usize, usize), usize)> {
        let (mut x0, mut y0, mut x1, mut y1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
        for p in st.bounding_points(&self.model)? {
            if let Some(u) = cam.project(&Point3::from(p)) {
                (x0, y0, x1, y1) = (x0.min(u.x), y0.min(u.y), x1.max(u.x), y1.max(u.y));
            }
        }
        if x0 > x1 {
            return None;
        }
        if let Some(b) = bbox {
            x0 = x0.min(b[0]);
            y0 = y0.min(b[1]);
            x1 = x1.max(b[0] + b[2]);
            y1 = y1.max(b[1] + b[3]);
        }
        let fpx = 0.5 * (cam.fx + cam.fy);
        let body_px = 2.0 * self.model.body_radius() * fpx / st.c.norm();
        let top = ((body_px / cfg.solver.min_body_width_px).max(1.0).log2().floor() as usize).min(cfg.solver.max_levels - 1);
        let extra = if cfg.seed_search.enabled { cfg.seed_search.radius_px as f64 } else { 0.0 };
        let margin = (cfg.edge_search.radius_px as f64 + 4.0 + extra) * (1u64 << top) as f64 + 0.1 * (x1 - x0).max(y1 - y0);
        let rect = edges::roi([x0, y0, x1 - x0, y1 - y0], margin, cam.width as usize, cam.height as usize)?;
        Some((rect, top))
    }
}

/// The stereo edge polish ([`crate::settings::Solver::stereo_edge_polish`]): stereo points fix
/// the distance and tilt but, biased at the tube's outline, also pull it across the image; the
/// edges alone then place it in the image with the distance and tilt kept (the mono keep-depth
/// mode, forced, at full resolution). Where the stereo points support the fit
/// ([`stereo_supports_fit`]) the stereo distance stands: no re-placement at the ground's height,
/// which mask seeds' profile asks for in mono. Without that support the mono settings apply,
/// and the ground may place the tube. Returns the polished state, or `best`'s when the polish
/// fails.
fn stereo_edge_polish(model: &crate::model::CylinderModel, cfg: &FitSettings, frame: &FitFrame, best: &FitResult) -> AxisState {
    let mut polish = *cfg;
    polish.seed.keep_depth = true;
    polish.seed_search.enabled = false;
    polish.end_decision.enabled = false;
    polish.solver.fine_polish = false;
    if stereo_supports_fit(best.stats.stereo_points, frame.scene.stereo_points.len()) {
        polish.seed.ground_relief_sigma_m = 0.0;
    }
    let mono_scene = Scene { stereo_points: &[], ..frame.scene };
    let polished = fit::fit(model, &polish, &frame.pyr, 0, &mono_scene, best.state);
    if polished.failure.is_none() {
        polished.state
    } else {
        best.state
    }
}

/// A failed pose at `st` (or at the origin along +z when `st` is missing or not finite).
pub(crate) fn failed(image_id: u64, score: f64, st: Option<&AxisState>, reason: FailureReason, msg: String) -> TubeAxisPose {
    let (c, a) = match st {
        Some(s) if s.c.iter().chain(s.a.iter()).all(|v| v.is_finite()) && s.a.norm() > 1e-9 => (s.c, s.a),
        _ => (Vector3::zeros(), Vector3::z()),
    };
    TubeAxisPose::new(image_id, score, c, a, 0.5).expect("finite centre and unit axis").fail(reason, msg)
}

/// The pose of a fit result with its end confidence.
pub(crate) fn to_pose(image_id: u64, score: f64, r: &FitResult, end_confidence: f64) -> TubeAxisPose {
    let mut p = match TubeAxisPose::new(image_id, score, r.state.c, r.state.a, end_confidence) {
        Ok(p) => p,
        Err(e) => return failed(image_id, score, None, FailureReason::Diverged, e.to_string()),
    };
    p.covariance = r.covariance;
    p.residuals = r.stats;
    match &r.failure {
        Some((reason, msg)) => p.fail(*reason, msg.clone()),
        None => p,
    }
}
