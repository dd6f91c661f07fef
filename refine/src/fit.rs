//! Levenberg-Marquardt fit of the cylinder contour to image edges (plus optional stereo points),
//! coarse to fine.
//!
//! Each outer iteration (re)selects the visible silhouette samples, searches each one's image
//! normal for the strongest edge ([`GradientLevel::search`]) and fixes these edge points `e_i`.
//! The residuals are then `r_i(θ) = n_i · (π(X_i(θ)) - e_i) / σ_px` (pixels along the normal,
//! normalized by the nominal edge noise) and, for stereo points `P_j`,
//! `s_j(θ) = (ρ_j - R(z_j)) / σ_s` with `z_j = (P_j - c)·a`, `ρ_j = |P_j - c - z_j a|`,
//! and the quadratic (not robust) prior residuals of the `priors` module: with a ground plane,
//! the centre height and the axis tilt; the detector's image axis.
//! After the first iteration of each level, the contrast polarity of each limb is fixed to the
//! sign most of its samples found (tube brighter or darker than the ground along that limb), so
//! that texture and shading edges of the other polarity are not associated.
//! One damped Gauss-Newton step minimizes `Σ ρ_Tukey(r)`:
//! `(JᵀWJ + λ diag(JᵀWJ)) δ = -JᵀW r`, accepted when the robust cost drops (λ ÷ 3), else
//! λ × 4 and retry. Jacobians from [`crate::jacobian`] (analytic projection, cheap 3D
//! differences). θ = (c, δ1, δ2): centre plus an axis step in the tangent plane.

use crate::contour::{build_samples_capped, project_with_normal, AxisState, ContourSample};
use crate::edges::{EdgeHits, GradientLevel};
use crate::jacobian::{stereo_row, FrameDerivatives};
use crate::model::CylinderModel;
use crate::mono::{damped_step, mono_basis, mono_ground_depth, mono_mode};
use crate::priors;
use crate::robust::{mad_scale, tukey_rho, tukey_weight};
use crate::scene::{image_axis_prior, Scene};
use crate::seed_policy::FitSettings;
use nalgebra::{Matrix2x5, Matrix5, Point2, Point3, Vector2, Vector3, Vector5};
use tubeloc_core::tube_pose::{axis_angle, canonical_axis, tangent_basis};
use tubeloc_core::{FailureReason, ResidualStats};

/// What stays fixed through one fit: the tube, the scene and the settings.
#[derive(Clone, Copy)]
struct Problem<'a> {
    model: &'a CylinderModel,
    scene: &'a Scene<'a>,
    cfg: &'a FitSettings,
}

/// Offset (level pixels along `n`, from the sample's level position) of the mask boundary seen
/// from full-resolution pixel `uf` along the outward normal `n`: the outermost inside → outside
/// transition within `radius_full` pixels, sampled every 0.25 px (nearest pixel).
fn mask_boundary(mask: &tubeloc_core::BinaryMask, uf: &Point2<f64>, n: &Vector2<f64>, radius_full: f64, scale: f64) -> Option<f64> {
    let at = |t: f64| -> bool {
        let q = uf + n * t;
        q.x >= -0.5 && q.y >= -0.5 && mask.get((q.x + 0.5) as usize, (q.y + 0.5) as usize)
    };
    let steps = (radius_full / 0.25).ceil() as i64;
    let mut best = None;
    let mut prev = at(-(steps as f64) * 0.25);
    for k in -steps + 1..=steps {
        let t = k as f64 * 0.25;
        let cur = at(t);
        if prev && !cur {
            best = Some(t - 0.125);
        }
        prev = cur;
    }
    best.map(|t| t * scale)
}

/// Outcome of [`fit`].
#[derive(Clone, Debug)]
pub struct FitResult {
    /// Final pose parameters.
    pub state: AxisState,
    /// Residual statistics at the finest level (pixels of full resolution).
    pub stats: ResidualStats,
    /// 5x5 covariance over (centre, axis tangent in `tangent_basis(canonical axis)`).
    pub covariance: [[f64; 5]; 5],
    /// Fraction of visible samples whose edge lies within `inlier_px` of the fitted contour.
    pub inlier_fraction: f64,
    /// Mean truncated quadratic cost per visible sample at the finest level (for comparing the
    /// two end hypotheses): `mean(min(r/τ, 1)²)` with missing edges counted as 1.
    pub score: f64,
    /// Why the fit failed, if it did.
    pub failure: Option<(FailureReason, String)>,
}

/// A contour sample with its edge hypotheses: offsets along `n` from `u0`; the residual uses the
/// hypothesis nearest to the current projection (a multi-hypothesis, ICP-like association).
struct Assoc {
    sample: ContourSample,
    /// Residual scale: `sqrt(end_limb_weight)` for limbs of sections other than the body during
    /// the fit, else 1.
    scale: f64,
    n: Vector2<f64>,
    u0: Point2<f64>,
    hyps: EdgeHits,
}

impl Assoc {
    #[inline]
    fn residual(&self, u: &Point2<f64>) -> f64 {
        let s = self.n.dot(&(u - self.u0));
        let mut best = f64::INFINITY;
        for h in &self.hyps.hits[..self.hyps.len] {
            let r = s - h.offset;
            if r.abs() < best.abs() {
                best = r;
            }
        }
        best
    }
}

/// One pyramid level as a stage of the fit sees it.
struct Level<'a> {
    lv: &'a GradientLevel,
    /// Half length of the edge search, level pixels.
    radius: usize,
    /// Edge noise of the residual normalization (`solver.edge_sigma_px`, used as is at every
    /// level).
    sigma_px: f64,
}

/// The residuals of one linearization with their robust weighting: the Tukey thresholds of
/// the image and stereo groups, and the scale of the stereo rows' information (1 in the fit;
/// `1 / stereo_points_per_measurement` for the output covariance).
#[derive(Clone, Copy)]
struct Weighting<'r> {
    r: &'r [Option<f64>],
    c: (f64, f64),
    stereo_info: f64,
}

fn is_visible(model: &CylinderModel, st: &AxisState, x: &Point3<f64>, out: &Vector3<f64>, scene: &Scene) -> bool {
    let push = 0.02 * model.body_radius() + 1e-4;
    let xp = x + out * push;
    if model.occludes(&st.c, &st.a, &xp) {
        return false;
    }
    if let Some((depth, cam)) = scene.depth {
        if let Some(u) = cam.project(x) {
            let (ix, iy) = (u.x.round(), u.y.round());
            if ix >= 0.0 && iy >= 0.0 && (ix as usize) < depth.width && (iy as usize) < depth.height {
                let z = depth.get(ix as usize, iy as usize) as f64;
                if z.is_finite() && z > 0.0 && z < x.z - model.occlusion_margin() {
                    return false;
                }
            }
        }
    }
    if let Some((shown, cam)) = scene.shown {
        if let Some(u) = cam.project(x) {
            let (ix, iy) = (u.x.round(), u.y.round());
            if ix >= 0.0 && iy >= 0.0 && ix < cam.width as f64 && iy < cam.height as f64 && !shown.get(ix as usize, iy as usize) {
                return false;
            }
        }
    }
    true
}

/// Associates visible samples with image edges at `level`. Returns the associations, the
/// number of visible samples inside the image, and the number of visible samples wherever
/// they project (inside the image or not).
/// `end_limb_scale` scales the residuals of the limbs of sections other than the body (see
/// the seed profile's `end_limb_weight`); with 0 they are left out.
fn associate(p: &Problem, st: &AxisState, samples: &[ContourSample], level: &Level, polarity: &[i8], end_limb_scale: f64) -> (Vec<Assoc>, usize, usize) {
    let Problem { model, scene, cfg } = *p;
    let mut out = Vec::with_capacity(samples.len());
    let mut total = 0;
    let Some(f) = st.frame() else { return (out, 0, total) };
    let cam = &level.lv.camera;
    let mut visible = 0;
    for (i, s) in samples.iter().enumerate() {
        let Some(p) = s.eval(model, &f) else { continue };
        if !s.on_silhouette(model, &f, &p) {
            continue;
        }
        let Some((u, n)) = project_with_normal(cam, &p) else { continue };
        let is_limb = matches!(s.kind, crate::contour::SampleKind::Limb { .. });
        let scale = if is_limb && model.sections[s.section].r != model.body_radius() { end_limb_scale } else { 1.0 };
        if scale == 0.0 {
            continue;
        }
        if !is_visible(model, st, &p.x, &p.out, scene) {
            continue;
        }
        total += 1;
        if !level.lv.inside(&u, level.radius as f64 + 1.0) {
            continue;
        }
        visible += 1;
        if let Some((mask, fcam)) = scene.mask {
            let Some(uf) = fcam.project(&p.x) else { continue };
            let scale = level.lv.scale;
            if let Some(off) = mask_boundary(mask, &uf, &n, level.radius as f64 / scale, scale) {
                let mut hyps = EdgeHits::default();
                hyps.hits[0] = crate::edges::EdgeHit { offset: off, strength: -1.0 };
                hyps.len = 1;
                out.push(Assoc { sample: *s, scale, n, u0: u, hyps });
            }
            continue;
        }
        let pol = polarity.get(i).copied().unwrap_or(0);
        let hyps = level.lv.search_all(&u, &n, level.radius, cfg.edge_search.min_gradient, pol, cfg.edge_search.rel_edge_strength);
        if hyps.len > 0 {
            out.push(Assoc { sample: *s, scale, n, u0: u, hyps });
        }
    }
    (out, visible, total)
}

/// Limb polarity from the associations: for each limb (section, side) whose strongest edges
/// agree in sign for at least 2/3 of at least 3 samples, every sample of that limb gets that
/// sign (`+1`: intensity rises outward along the normal); others keep 0 (either sign).
fn limb_polarity(samples: &[ContourSample], assoc: &[Assoc]) -> Vec<i8> {
    use crate::contour::SampleKind;
    let key = |s: &ContourSample| match s.kind {
        SampleKind::Limb { side, .. } => Some(2 * s.section + (side > 0.0) as usize),
        SampleKind::Rim { .. } => None,
    };
    let nk = 2 * samples.iter().map(|s| s.section + 1).max().unwrap_or(0);
    let mut votes = vec![(0usize, 0usize); nk];
    for a in assoc {
        if let (Some(k), true) = (key(&a.sample), a.hyps.len > 0) {
            if a.hyps.hits[0].strength > 0.0 {
                votes[k].0 += 1;
            } else {
                votes[k].1 += 1;
            }
        }
    }
    let sign: Vec<i8> = votes
        .iter()
        .map(|&(p, m)| {
            let n = p + m;
            if n >= 3 && 3 * p >= 2 * n {
                1
            } else if n >= 3 && 3 * m >= 2 * n {
                -1
            } else {
                0
            }
        })
        .collect();
    samples.iter().map(|s| key(s).map_or(0, |k| sign[k])).collect()
}

/// Residuals (normalized) of the associations and stereo points at state `st`; missing
/// projections give `None` entries (skipped).
fn residuals(p: &Problem, st: &AxisState, assoc: &[Assoc], level: &Level, out: &mut Vec<Option<f64>>) {
    let Problem { model, scene, cfg } = *p;
    let (cam, sigma_px) = (&level.lv.camera, level.sigma_px);
    out.clear();
    let f = st.frame();
    for a in assoc {
        let r = f.and_then(|f| a.sample.eval(model, &f)).and_then(|p| cam.project(&p.x)).map(|u| a.scale * a.residual(&u) / sigma_px);
        out.push(r);
    }
    let half = 0.5 * model.length;
    for p in scene.stereo_points {
        let rel = p.coords - st.c;
        let z = rel.dot(&st.a);
        if z.abs() > half + 0.01 {
            out.push(None);
            continue;
        }
        let rho = (rel - st.a * z).norm();
        let rz = model.radius_at(z.clamp(-half, half));
        out.push(Some((rho - rz) / cfg.solver.stereo_sigma_m));
    }
    priors::push_residuals(model, st, scene.ground.as_ref(), image_axis_prior(scene), cfg, out);
}

/// Threshold of residual `i`: image (`i < n_img`), stereo (`i < n_img + n_st`) or prior
/// (effectively quadratic).
#[inline]
fn group_threshold(i: usize, n_img: usize, n_st: usize, c: (f64, f64)) -> f64 {
    if i < n_img {
        c.0
    } else if i < n_img + n_st {
        c.1
    } else {
        1e6
    }
}

fn robust_cost(r: &[Option<f64>], c_img: f64, c_st: f64, n_img: usize, n_st: usize) -> f64 {
    r.iter()
        .enumerate()
        .map(|(i, v)| {
            let c = group_threshold(i, n_img, n_st, (c_img, c_st));
            if c >= 1e6 {
                return v.map_or(0.0, |x| 0.5 * x * x);
            }
            v.map_or(c * c / 6.0, |x| tukey_rho(x, c))
        })
        .sum()
}

/// Tukey thresholds (normalized units) for the image and stereo groups: `4.685 · MAD scale`,
/// the image one clamped to `[2 px, 0.6 · search radius]` in level pixels so that a majority of
/// wrong associations cannot inflate it.
fn thresholds(r: &[Option<f64>], n_img: usize, n_st: usize, scratch: &mut Vec<f64>, sigma_px: f64, radius: usize) -> (f64, f64) {
    let img: Vec<f64> = r[..n_img].iter().flatten().copied().collect();
    let st: Vec<f64> = r[n_img..(n_img + n_st).min(r.len())].iter().flatten().copied().collect();
    let s_img = mad_scale(&img, scratch).unwrap_or(1.0);
    let s_st = mad_scale(&st, scratch).unwrap_or(1.0).max(1.0);
    let lo = 2.0 / sigma_px;
    let hi = (0.6 * radius as f64 / sigma_px).max(lo);
    ((4.685 * s_img).clamp(lo, hi), 4.685 * s_st)
}

/// Largest predicted image motion (level pixels) of the associated samples for step `d`, from
/// their image Jacobians (linearized; the step is small by construction).
fn max_motion(jac: &[Option<Matrix2x5<f64>>], d: &Vector5<f64>) -> f64 {
    jac.iter().flatten().map(|j| (j * d).norm()).fold(0.0, f64::max)
}

/// Normal equations `JᵀWJ`, `JᵀWr` at `st` for the perturbation basis `(u1, u2)` with the
/// Jacobians of [`crate::jacobian`]; fills `jac` with the image Jacobian of each association
/// and returns `Σ w r²` and `Σ w`. The stereo rows enter `JᵀWJ` scaled by
/// [`Weighting::stereo_info`].
fn normal_equations(p: &Problem, st: &AxisState, assoc: &[Assoc], level: &Level, u: (&Vector3<f64>, &Vector3<f64>), w: &Weighting, jac: &mut Vec<Option<Matrix2x5<f64>>>) -> (Matrix5<f64>, Vector5<f64>, f64, f64) {
    let Problem { model, scene, cfg } = *p;
    let (cam, sigma_px) = (&level.lv.camera, level.sigma_px);
    let Weighting { r: r0, c, stereo_info } = *w;
    let n_img = assoc.len();
    let n_st = scene.stereo_points.len();
    jac.clear();
    let fd = FrameDerivatives::new(st, u.0, u.1);
    for a in assoc {
        jac.push(fd.as_ref().and_then(|fd| a.sample.eval(model, fd.base()).and_then(|p| fd.image_jacobian(model, &a.sample, cam, &p.x))));
    }
    let mut h = Matrix5::zeros();
    let mut g = Vector5::zeros();
    let (mut wrr, mut wsum) = (0.0, 0.0);
    for (i, r) in r0.iter().enumerate() {
        let Some(r) = *r else { continue };
        let cthr = group_threshold(i, n_img, n_st, c);
        let w = if cthr >= 1e6 { 1.0 } else { tukey_weight(r, cthr) };
        if w <= 0.0 {
            continue;
        }
        let info = if i >= n_img && i < n_img + n_st { stereo_info } else { 1.0 };
        let j: Vector5<f64> = if i < n_img {
            let Some(ji) = &jac[i] else { continue };
            (ji.transpose() * assoc[i].n) * (assoc[i].scale / sigma_px)
        } else if i < n_img + n_st {
            Vector5::from(stereo_row(st, u.0, u.1, &scene.stereo_points[i - n_img])) / cfg.solver.stereo_sigma_m
        } else {
            priors::jacobian_row(i - n_img - n_st, scene.ground.as_ref(), image_axis_prior(scene), cfg, u)
        };
        if !j.iter().all(|v| v.is_finite()) {
            continue;
        }
        // The upper triangle of `j jᵀ (w info)`, mirrored below: the same products.
        let s = w * info;
        for a in 0..5 {
            for b in a..5 {
                h[(a, b)] += j[a] * j[b] * s;
            }
        }
        g += j * (w * r);
        wrr += w * r * r;
        wsum += w;
    }
    for a in 0..5 {
        for b in 0..a {
            h[(a, b)] = h[(b, a)];
        }
    }
    (h, g, wrr, wsum)
}

/// Fits the model starting from `seed` over `levels` (coarsest last in the slice order given by
/// [`crate::edges::build_pyramid`]: index 0 is full resolution). `first_level` is the coarsest
/// index used; the stages ([`stages`]) run from it down to 0, each by [`run_stage`]. A mono
/// keep-depth fit is finally moved along its ray by the ground ([`mono_ground_depth`]); the
/// acceptance and statistics come from [`finish`].
pub(crate) fn fit(model: &CylinderModel, cfg: &FitSettings, levels: &[GradientLevel], first_level: usize, scene: &Scene, seed: AxisState) -> FitResult {
    let p = Problem { model, scene, cfg };
    let top = first_level.min(levels.len().saturating_sub(1));
    let mono = levels.first().is_some_and(|l0| mono_mode(cfg, scene, model, &seed, &l0.camera));
    let mut run = StageRun { st: seed, seed, iterations: 0, mono, bufs: Buffers::default() };
    for (si, &(li, radius)) in stages(&p, top).iter().enumerate() {
        if let Some(failed) = run_stage(&p, &mut run, &levels[li], li, radius, si == 0) {
            return failed;
        }
    }
    let mut st = run.st;
    if mono {
        st = mono_ground_depth(model, cfg, scene, st, seed.c.norm());
    }
    // Acceptance and statistics on the smoothed level (texture and noise make more edges in the
    // unsmoothed one), the score that ranks hypotheses and ends on the level fitted.
    let mut r = finish(&p, levels[0].smooth(), st, run.iterations, mono);
    if levels[0].smoothed.is_some() {
        r.score = Evaluation::new(&p, &levels[0], &st).score;
    }
    r
}

/// The stages (level, search radius) of a fit from level `top`: the coarsest level with the
/// wide search, the finer ones with the fine search; when the coarsest level is full
/// resolution (narrow tubes), it is run again with the fine search (fewer shading and texture
/// edges within reach), in mono fits: no stereo points, no depth map (`solver.fine_polish`).
fn stages(p: &Problem, top: usize) -> Vec<(usize, usize)> {
    let (cfg, scene) = (p.cfg, p.scene);
    let (wide, fine) = (cfg.edge_search.radius_px, cfg.fine_radius_px());
    let mut stages: Vec<(usize, usize)> = (0..=top).rev().map(|li| (li, if li == top { wide } else { fine })).collect();
    if top == 0 && cfg.solver.fine_polish && scene.stereo_points.is_empty() && scene.depth.is_none() && fine < wide {
        stages.push((0, fine));
    }
    stages
}

/// Scratch buffers reused across the iterations of a fit.
#[derive(Default)]
struct Buffers {
    scratch: Vec<f64>,
    r: Vec<Option<f64>>,
    trial: Vec<Option<f64>>,
    jac: Vec<Option<Matrix2x5<f64>>>,
}

/// The state of a fit between its stages.
struct StageRun {
    /// Current estimate.
    st: AxisState,
    /// The fit's seed (divergence is measured from it).
    seed: AxisState,
    /// Outer iterations so far, all stages.
    iterations: usize,
    /// The fit is in mono keep-depth mode ([`mono_mode`]).
    mono: bool,
    bufs: Buffers,
}

impl StageRun {
    /// A failed fit at `st` after the iterations so far.
    fn failed(&self, st: AxisState, reason: FailureReason, msg: String) -> FitResult {
        FitResult { state: st, stats: ResidualStats { iterations: self.iterations, ..Default::default() }, covariance: [[0.0; 5]; 5], inlier_fraction: 0.0, score: 1.0, failure: Some((reason, msg)) }
    }
}

/// One stage of the fit at level `li` with search radius `radius`: outer iterations of edge
/// association and damped Gauss-Newton steps ([`damped_step`], within the mono subspace in
/// keep-depth mode) until a step right after a fresh edge search moves the contour less than
/// `solver.converged_px`. Edge associations are refreshed when the contour has moved more than
/// `solver.reassociate_px` since the last search (and on the first two iterations, before and
/// after the limb polarity is fixed); in between the residuals follow the stored hypotheses
/// along the normals. Returns the failed fit when too few samples are visible or matched, or
/// when the stage leaves the seed further than the acceptance allows; `None` when it succeeds.
fn run_stage(p: &Problem, run: &mut StageRun, lv: &GradientLevel, li: usize, radius: usize, first_stage: bool) -> Option<FitResult> {
    let Problem { model, cfg, .. } = *p;
    let level = Level { lv, radius, sigma_px: cfg.solver.edge_sigma_px };
    let samples = build_samples_capped(model, &run.st, &lv.camera, cfg.edge_search.sample_spacing_px, cfg.edge_search.max_samples);
    let mut polarity = vec![0i8; samples.len()];
    let max_it = if first_stage { cfg.solver.max_iterations } else { cfg.solver.max_iterations.div_ceil(2) };
    let mut lambda = 1e-3;
    let mut assoc = Vec::new();
    let mut drift = f64::INFINITY;
    for it in 0..max_it {
        run.iterations += 1;
        let fresh = it <= 1 || drift > cfg.solver.reassociate_px;
        if fresh {
            let (a, visible, _) = associate(p, &run.st, &samples, &level, &polarity, cfg.seed.end_limb_weight.sqrt());
            assoc = a;
            drift = 0.0;
            if cfg.edge_search.limb_polarity && it == 0 {
                polarity = limb_polarity(&samples, &assoc);
            }
            if visible < cfg.acceptance.min_samples {
                return Some(run.failed(run.st, FailureReason::OutOfImage, format!("only {visible} contour samples visible in the image at level {li}")));
            }
            if assoc.len() < cfg.acceptance.min_samples {
                return Some(run.failed(run.st, FailureReason::TooFewEdges, format!("{} of {visible} contour samples found an edge at level {li}", assoc.len())));
            }
        }
        let Some((next, motion)) = damped_iteration(p, run, &assoc, &level, &mut lambda) else {
            if fresh {
                break;
            }
            drift = f64::INFINITY;
            continue;
        };
        run.st = next;
        drift += motion;
        let st = run.st;
        if !(st.c.iter().all(|v| v.is_finite()) && st.a.iter().all(|v| v.is_finite())) || st.c.z < 0.02 {
            return Some(run.failed(run.seed, FailureReason::Diverged, format!("pose left the valid range (centre {:?})", st.c.as_slice())));
        }
        if motion < cfg.solver.converged_px {
            if fresh {
                break;
            }
            drift = f64::INFINITY;
        }
    }
    let (st, seed) = (run.st, run.seed);
    let moved = (st.c - seed.c).norm();
    if moved > cfg.acceptance.max_centre_shift_frac * seed.c.norm() || axis_angle(&st.a, &seed.a) > cfg.acceptance.max_axis_change_deg.to_radians() {
        return Some(run.failed(seed, FailureReason::Diverged, format!("fit moved {:.1} mm and turned {:.1} deg from the seed", moved * 1e3, axis_angle(&st.a, &seed.a).to_degrees())));
    }
    None
}

/// One damped Gauss-Newton iteration from `run.st` with the associations `assoc`: the robust
/// cost and normal equations, then up to six steps with growing damping `lambda` (each limited
/// to `solver.max_step_px` of image motion, the trust region that keeps samples from jumping
/// between edge hypotheses) until one lowers the cost. Returns the new state and the step's
/// largest image motion, or `None` when no step lowered the cost.
fn damped_iteration(p: &Problem, run: &mut StageRun, assoc: &[Assoc], level: &Level, lambda: &mut f64) -> Option<(AxisState, f64)> {
    let (scene, cfg) = (p.scene, p.cfg);
    let st = run.st;
    let b = &mut run.bufs;
    let n_img = assoc.len();
    residuals(p, &st, assoc, level, &mut b.r);
    let n_st = scene.stereo_points.len();
    let c = thresholds(&b.r, n_img, n_st, &mut b.scratch, level.sigma_px, level.radius);
    let cost0 = robust_cost(&b.r, c.0, c.1, n_img, n_st);
    let (u1, u2) = tangent_basis(&st.a);
    let (h, g, _, _) = normal_equations(p, &st, assoc, level, (&u1, &u2), &Weighting { r: &b.r, c, stereo_info: 1.0 }, &mut b.jac);
    let basis = if run.mono { mono_basis(&st, &u1, &u2, scene.ground.is_some()) } else { None };
    for _ in 0..6 {
        let Some(mut d) = damped_step(&h, &g, *lambda, basis.as_deref()) else {
            *lambda *= 10.0;
            continue;
        };
        let motion = max_motion(&b.jac, &d);
        if motion > cfg.solver.max_step_px {
            d *= cfg.solver.max_step_px / motion;
        }
        let trial = st.updated(&[d[0], d[1], d[2], d[3], d[4]], &u1, &u2);
        residuals(p, &trial, assoc, level, &mut b.trial);
        let cost = robust_cost(&b.trial, c.0, c.1, n_img, n_st);
        if cost.is_finite() && cost <= cost0 {
            *lambda = (*lambda / 3.0).max(1e-7);
            return Some((trial, max_motion(&b.jac, &d)));
        }
        *lambda *= 4.0;
    }
    None
}

/// The fitted contour's edges at the finest level, as [`finish`] and the unsmoothed level's
/// score see them: fine-search associations (no limb polarity), their residuals, and the
/// inlier counts and score of [`FitResult`].
struct Evaluation<'a> {
    level: Level<'a>,
    assoc: Vec<Assoc>,
    /// Visible samples inside the level, and wherever they project.
    visible: usize,
    total: usize,
    /// Residuals (normalized) of `assoc`, the stereo points and the priors.
    r: Vec<Option<f64>>,
    /// Image residuals within `inlier_px`: count and sum of squares (full-resolution pixels²).
    inliers: usize,
    inlier_ss: f64,
    /// [`FitResult::score`].
    score: f64,
}

impl<'a> Evaluation<'a> {
    /// The evaluation of state `st` at level `lv` (the finest).
    fn new(p: &Problem, lv: &'a GradientLevel, st: &AxisState) -> Self {
        let cfg = p.cfg;
        let level = Level { lv, radius: cfg.fine_radius_px(), sigma_px: cfg.solver.edge_sigma_px };
        let samples = build_samples_capped(p.model, st, &lv.camera, cfg.edge_search.sample_spacing_px, cfg.edge_search.max_samples);
        let polarity = vec![0i8; samples.len()];
        let (assoc, visible, total) = associate(p, st, &samples, &level, &polarity, 1.0);
        let mut r = Vec::new();
        residuals(p, st, &assoc, &level, &mut r);
        let n_img = assoc.len();
        let to_px = level.sigma_px / lv.scale; // normalized -> full-resolution pixels (level 0: scale 1)
        let tau = cfg.acceptance.inlier_px / to_px;
        let (mut inliers, mut inlier_ss, mut score) = (0usize, 0.0, 0.0);
        for v in r[..n_img].iter().flatten() {
            if v.abs() < tau {
                inliers += 1;
                inlier_ss += (v * to_px).powi(2);
            }
            score += (v / tau).powi(2).min(1.0);
        }
        score += (visible.saturating_sub(n_img)) as f64;
        let score = if visible > 0 { score / visible as f64 } else { 1.0 };
        Evaluation { level, assoc, visible, total, r, inliers, inlier_ss, score }
    }
}

/// Final statistics, covariance and acceptance at the finest level `lv`.
/// `mono`: keep-depth mode, where a tube cut by the image border keeps its seed's distance, so
/// the in-image fraction is not checked.
fn finish(p: &Problem, lv: &GradientLevel, st: AxisState, iterations: usize, mono: bool) -> FitResult {
    let (scene, cfg) = (p.scene, p.cfg);
    let Evaluation { level, assoc, visible, total, r, inliers: inl, inlier_ss: ss, score } = Evaluation::new(p, lv, &st);
    let n_img = assoc.len();
    let sigma_m = cfg.solver.stereo_sigma_m;
    let stereo: Vec<f64> = r[n_img..(n_img + scene.stereo_points.len()).min(r.len())].iter().flatten().map(|v| v * sigma_m).collect();
    let stereo_in: Vec<f64> = stereo.iter().copied().filter(|v| v.abs() < 3.0 * sigma_m.max(1e-4) * 3.0).collect();
    let stats = ResidualStats {
        rms_px: if inl > 0 { (ss / inl as f64).sqrt() } else { 0.0 },
        inliers: inl,
        count: visible,
        stereo_rms_m: if stereo_in.is_empty() { 0.0 } else { (stereo_in.iter().map(|v| v * v).sum::<f64>() / stereo_in.len() as f64).sqrt() },
        stereo_points: stereo_in.len(),
        iterations,
    };
    // Covariance in the tangent basis of the canonical axis.
    let axis = canonical_axis(&st.a).unwrap_or(st.a);
    let sgn = if axis.dot(&st.a) >= 0.0 { 1.0 } else { -1.0 };
    let (b1, b2) = tangent_basis(&axis);
    let (u1, u2) = (b1 * sgn, b2 * sgn);
    let c = if r.is_empty() { (1.0, 1.0) } else { thresholds(&r, n_img, scene.stereo_points.len(), &mut Vec::new(), level.sigma_px, level.radius) };
    let weighting = Weighting { r: &r, c, stereo_info: 1.0 / cfg.solver.stereo_points_per_measurement };
    let (h, _, wrr, wsum) = normal_equations(p, &st, &assoc, &level, (&u1, &u2), &weighting, &mut Vec::new());
    let mut cov = [[0.0; 5]; 5];
    if wsum > 6.0 {
        if let Some(inv) = h.try_inverse() {
            let s2 = (wrr / (wsum - 5.0)).max(1e-12);
            // D Σ D with D = diag(1, 1, 1, k, k): the axis's σ times k (`axis_sigma_scale`).
            let d = |i: usize| if i >= 3 { cfg.solver.axis_sigma_scale } else { 1.0 };
            for i in 0..5 {
                for j in 0..5 {
                    let v = inv[(i, j)] * s2 * d(i) * d(j);
                    cov[i][j] = if v.is_finite() { v } else { 0.0 };
                }
            }
        }
    }
    let inlier_fraction = if visible > 0 { inl as f64 / visible as f64 } else { 0.0 };
    let acc = &cfg.acceptance;
    let failure = if visible < acc.min_samples {
        Some((FailureReason::OutOfImage, format!("only {visible} contour samples visible at full resolution")))
    } else if !mono && (visible as f64) < acc.min_in_image_fraction * total as f64 {
        Some((FailureReason::OutOfImage, format!("only {visible} of {total} visible contour samples ({:.0}%) lie inside the image: depth is not constrained enough", 100.0 * visible as f64 / total.max(1) as f64)))
    } else if inlier_fraction < acc.min_inlier_fraction {
        Some((FailureReason::EmptyTerrain, format!("only {inl} of {visible} contour samples ({:.0}%) lie on an image edge within {} px", 100.0 * inlier_fraction, acc.inlier_px)))
    } else {
        None
    };
    FitResult { state: st, stats, covariance: cov, inlier_fraction, score, failure }
}
