//! Two-view contour fit: the whole occluding contour (limbs of every section and the rims)
//! fitted in both images of a rectified pair at once, over all five pose parameters.
//!
//! In the rectified left frame the right camera sits at `(B, 0, 0)`. For every visible contour
//! sample `X` ([`crate::contour::build_samples`]) and view `v` (left: `X`, right:
//! `X − (B, 0, 0)`) the residual is the offset, along the projected outward normal `n`, from the
//! nearest image edge found by a 1D search ([`crate::edges::GradientLevel::search_all`],
//! unsmoothed full-resolution gradients) to the projection:
//!
//! ```text
//! r_v(X) = n · (π_v(X) − e_v(X)),   cost = Σ ρ_Tukey(r) + priors
//! ```
//!
//! The limbs' sub-pixel edges in two views fix the distance and the tilt (their disparity
//! along the normal is `d sin ψ`, ψ the image axis' angle to the rows); tubes along the rows
//! keep only the rims for it. Parameters: the centre `c` (3), the axis
//! `a = normalize(a₀ + δ₁ u₁ + δ₂ u₂)` (2, `u₁ u₂ ⟂ a₀`) and two nuisance offsets `b` of the
//! limb edges inside the silhouette (body, other sections; the same in both views), so that
//! the shading bias of the limb edges (~0.1-0.3 px inward) is not read as distance through the
//! silhouette's width (for limb residuals `r = n · (π − e) − b`). Gauss-Newton with numeric Jacobians,
//! Tukey IRLS weights, the edges re-searched every iteration (as in [`crate::rims`]). The
//! limbs' contrast polarity is fixed per limb and view after the first iteration. Samples
//! hidden by the tube itself or by the scene (the SGM disparity, [`crate::photo::Occluders`])
//! are left out. Priors: a weak one on the start pose (`start_sigma_*`), one on the centre's
//! distance `|c|` about the start's (`distance_sigma_m`, 2 mm: the photometric stage's
//! distance, from every covered pixel, is better than the edges'), and with a ground plane the
//! tilt `(n·a)/σ_θ`. The foot / seal limbs are left out by default (`end_limb_weight = 0`).
//!
//! Measured (design record 0020): the fit lowers the stereo medians (axis, perpendicular and
//! centre error) but leaves the axis p90 where it was: a tilt error of a few degrees moves the
//! ends' disparity by only ~0.2-0.3 px, and from such a start the edges (like the rims) often
//! hold the tilt where it is; the photometric stage sees it better.

use crate::contour::{build_samples, project_with_normal, AxisState, ContourSample, SampleKind};
use crate::edges::{EdgeHit, GradientLevel};
use crate::model::CylinderModel;
use crate::normal_equations::TwoViewNormalEquations;
use crate::photo::Occluders;
use crate::rims::view;
use crate::robust::tukey_weight;
use nalgebra::{Point3, SVector, Vector3, Vector5};

/// Parameters of one iteration: centre move (3), axis turn (2), limb edge offsets (body, other
/// sections).
type V7 = SVector<f64, 7>;
use tubeloc_core::{CameraModel, Plane};

/// Settings of [`fit_two_view`] (JSON: missing fields keep their defaults).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TwoViewConfig {
    /// Spacing of the contour samples, full-resolution pixels.
    pub spacing_px: f64,
    /// Tukey threshold of the edge residuals, pixels.
    pub tukey_px: f64,
    /// Nominal edge noise, pixels: the priors count against residuals of this size.
    pub noise_px: f64,
    /// Most Gauss-Newton iterations.
    pub iterations: usize,
    /// Least edge samples in each view.
    pub min_samples: usize,
    /// Weight of the limbs of sections other than the body (their edges lie further inside
    /// the silhouette, shading).
    pub end_limb_weight: f64,
    /// Prior on the centre's move from the start, metres (standard deviation).
    pub start_sigma_m: f64,
    /// Prior on the axis' turn from the start, radians (standard deviation).
    pub start_sigma_rad: f64,
    /// Largest accepted move of the centre, metres.
    pub max_move_m: f64,
    /// Largest accepted turn of the axis, degrees.
    pub max_turn_deg: f64,
    /// Fit a common inward offset of the limb edges (one for the body, one for the other
    /// sections; the same in both views) instead of taking the limbs' image width as a
    /// measurement of the distance: shading moves the limb edges ~0.1-0.3 px inside the
    /// silhouette, which the width would turn into centimetres of distance.
    pub limb_offsets: bool,
    /// Prior on the limb edge offsets, pixels (standard deviation about 0).
    pub limb_offset_sigma_px: f64,
    /// Prior on the centre's distance from the camera about the start's (e.g. the
    /// photometric stage's, from every covered pixel), metres; infinite: none.
    pub distance_sigma_m: f64,
    /// Re-locate each edge by the half-maximum centroid of `|∇I · n|` on a 0.25 px grid
    /// instead of the search's parabola.
    pub centroid_edges: bool,
}

impl TwoViewConfig {
    /// Checks every value (positive and finite where a scale, `distance_sigma_m` may be
    /// infinite); the error names the field and its value.
    pub fn validate(&self) -> Result<(), String> {
        use tubeloc_core::field_range::{
            check_all, check_count, check_real,
            Bound::{Closed, Open},
        };
        let positive = [
            ("spacing_px", self.spacing_px),
            ("tukey_px", self.tukey_px),
            ("noise_px", self.noise_px),
            ("start_sigma_m", self.start_sigma_m),
            ("start_sigma_rad", self.start_sigma_rad),
            ("max_move_m", self.max_move_m),
            ("max_turn_deg", self.max_turn_deg),
            ("limb_offset_sigma_px", self.limb_offset_sigma_px),
        ];
        check_all(&positive, Open(0.0), Open(f64::INFINITY))?;
        check_real("end_limb_weight", self.end_limb_weight, Closed(0.0), Open(f64::INFINITY))?;
        if self.distance_sigma_m.is_nan() || self.distance_sigma_m <= 0.0 {
            return Err(format!("distance_sigma_m = {}: expected a positive number (inf: no prior)", self.distance_sigma_m));
        }
        check_count("iterations", self.iterations, 1, 1000)?;
        if self.min_samples < 3 {
            return Err(format!("min_samples = {}: expected at least 3", self.min_samples));
        }
        Ok(())
    }
}

impl Default for TwoViewConfig {
    fn default() -> Self {
        TwoViewConfig {
            spacing_px: 1.5,
            tukey_px: 1.0,
            noise_px: 0.5,
            iterations: 20,
            min_samples: 12,
            end_limb_weight: 0.0,
            start_sigma_m: 0.02,
            start_sigma_rad: 5f64.to_radians(),
            max_move_m: 0.03,
            max_turn_deg: 8.0,
            limb_offsets: true,
            limb_offset_sigma_px: 1.0,
            distance_sigma_m: 0.002,
            centroid_edges: false,
        }
    }
}

/// Result of [`fit_two_view`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TwoViewFit {
    /// The fitted state (rectified left frame).
    pub state: AxisState,
    /// Edge samples with a nonzero weight at the end: left view, right view.
    pub samples: (usize, usize),
    /// Robust RMS of the edge residuals at the end, pixels.
    pub rms_px: f64,
    /// Move of the centre from the start, metres.
    pub moved_m: f64,
    /// Turn of the axis from the start, degrees.
    pub turned_deg: f64,
    /// Fitted inward offsets of the limb edges (body, other sections), pixels.
    pub limb_offsets_px: (f64, f64),
    /// Iterations run.
    pub iterations: usize,
}

/// Sub-pixel edge offset along `n` from `u` near the search's `offset`: the centroid of
/// `|∇I · n| − ½ max` (where positive) sampled every 0.25 px over ±1.5 px about the
/// strongest sample. The search's parabola through samples one pixel apart, taken from the
/// projection `u`, locks onto that grid (biased toward offset 0, so that a fit stays where it
/// starts); the half-maximum centroid on a finer grid does not.
fn refine_offset(level: &GradientLevel, u: &nalgebra::Point2<f64>, n: &nalgebra::Vector2<f64>, offset: f64) -> f64 {
    const H: f64 = 0.25;
    let mut s = [0f64; 13];
    for (k, v) in s.iter_mut().enumerate() {
        let o = offset + (k as f64 - 6.0) * H;
        *v = (level.directional(&(u + n * o), n) as f64).abs();
    }
    let (imax, &smax) = s.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)).unwrap_or((6, &0.0));
    if smax <= 0.0 {
        return offset;
    }
    let centre = offset + (imax as f64 - 6.0) * H;
    let (mut sw, mut swx) = (0.0, 0.0);
    for k in -6i32..=6 {
        let o = centre + k as f64 * H;
        let v = (level.directional(&(u + n * o), n) as f64).abs() - 0.5 * smax;
        if v > 0.0 {
            sw += v;
            swx += v * o;
        }
    }
    if sw > 0.0 {
        swx / sw
    } else {
        offset
    }
}

/// Two unit vectors perpendicular to `a` (and to each other).
fn tangent_basis(a: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let t = if a.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
    let u1 = a.cross(&t).normalize();
    (u1, a.cross(&u1))
}

/// Fits centre and axis to the contour in both views of a rectified pair (module docs).
/// `camera`: the rectified camera of both views (no distortion); `baseline_m`: the right
/// camera's offset along the rectified x axis; `st` in the rectified left frame; `occluders`:
/// the scene's disparity in the rectified left image; `ground`: the ground's unit upward normal
/// in the rectified left frame and the tilt prior's standard deviation (radians). `None` when
/// either view has fewer than `min_samples` edges, the system is singular, or the result moved
/// beyond `max_move_m` / `max_turn_deg`.
#[allow(clippy::too_many_arguments)]
pub fn fit_two_view(model: &CylinderModel, camera: &CameraModel, left: &Plane<f32>, right: &Plane<f32>, baseline_m: f64, st: &AxisState, occluders: Option<&Occluders>, ground: Option<(Vector3<f64>, f64)>, cfg: &TwoViewConfig) -> Option<TwoViewFit> {
    let views = [view(model, camera, left, st, Vector3::zeros())?, view(model, camera, right, st, Vector3::new(baseline_m, 0.0, 0.0))?];
    let samples = build_samples(model, st, camera, cfg.spacing_px);
    let body_r = model.body_radius();
    let scale_of = |s: &ContourSample| match s.kind {
        SampleKind::Limb { .. } if model.sections[s.section].r != body_r => cfg.end_limb_weight.sqrt(),
        _ => 1.0,
    };
    let fb = camera.fx * baseline_m;
    // Scene occlusion of a point (rectified left frame) from the left view's disparity.
    let scene_hidden = |x: &Point3<f64>| -> bool {
        let Some(o) = occluders else { return false };
        let Some(u) = camera.project(x) else { return false };
        let (ix, iy) = (u.x.round(), u.y.round());
        if ix < 0.0 || iy < 0.0 || ix >= o.disparity.width as f64 || iy >= o.disparity.height as f64 {
            return false;
        }
        let d = o.disparity.get(ix as usize, iy as usize) as f64;
        d.is_finite() && d > 0.0 && fb / d < x.z - o.margin_m
    };
    // Limb index for the polarity: (section, side).
    let limb_key = |s: &ContourSample| match s.kind {
        SampleKind::Limb { side, .. } => Some(2 * s.section + (side > 0.0) as usize),
        _ => None,
    };
    let n_limbs = 2 * model.sections.len();
    let mut polarity = [vec![0i8; n_limbs], vec![0i8; n_limbs]];
    let (c0, a0) = (st.c, st.a);
    let mut cur = *st;
    let hc = 1e-4;
    let ha = 1e-4;
    let wc = (cfg.noise_px / cfg.start_sigma_m).powi(2);
    let wa = (cfg.noise_px / cfg.start_sigma_rad).powi(2);
    let mut counts = (0, 0);
    let mut rms = 0.0;
    let mut iters = 0;
    let mut boff = [0.0f64; 2];
    for it in 0..cfg.iterations {
        iters = it + 1;
        let radius = if it < 3 { 4 } else { 2 };
        let (u1, u2) = tangent_basis(&cur.a);
        let state_of = |d: &Vector5<f64>| -> AxisState { AxisState { c: cur.c + Vector3::new(d[0], d[1], d[2]), a: (cur.a + u1 * d[3] + u2 * d[4]).normalize() } };
        let perturbed: Vec<AxisState> = (0..5).map(|k| state_of(&(Vector5::ith(k, if k < 3 { hc } else { ha })))).collect();
        let f0 = cur.frame()?;
        let frames: Vec<_> = perturbed.iter().map(|s| s.frame()).collect();
        let mut eq = TwoViewNormalEquations::<7>::new();
        let mut votes = [vec![0i32; n_limbs], vec![0i32; n_limbs]];
        for s in &samples {
            let Some(q) = s.eval(model, &f0) else { continue };
            if !s.on_silhouette(model, &f0, &q) || model.occludes(&cur.c, &cur.a, &(q.x + q.out * (0.02 * body_r + 1e-4))) || scene_hidden(&q.x) {
                continue;
            }
            let scale = scale_of(s);
            if scale <= 0.0 {
                continue;
            }
            let qk: Vec<Option<Point3<f64>>> = frames.iter().map(|f| f.as_ref().and_then(|f| s.eval(model, f)).map(|p| p.x)).collect();
            for (vi, v) in views.iter().enumerate() {
                let mut qv = q;
                qv.x -= v.origin;
                let Some((u, n)) = project_with_normal(&v.level.camera, &qv) else { continue };
                if !v.level.inside(&u, 5.0) {
                    continue;
                }
                let key = limb_key(s);
                let pol = key.map_or(0, |k| polarity[vi][k]);
                let hits = v.level.search_all(&u, &n, radius, 0.004, pol, 0.25);
                let Some(hit) = (0..hits.len).map(|k| hits.hits[k]).min_by(|a, b| a.offset.abs().total_cmp(&b.offset.abs())) else { continue };
                let hit = if cfg.centroid_edges { EdgeHit { offset: refine_offset(&v.level, &u, &n, hit.offset), ..hit } } else { hit };
                if let (Some(k), 0) = (key, it) {
                    // The strongest hit's sign votes for the limb's polarity.
                    votes[vi][k] += if hits.hits[0].strength > 0.0 { 1 } else { -1 };
                }
                let mut j = V7::zeros();
                let mut ok = true;
                for k in 0..5 {
                    let uk = qk[k].and_then(|p| v.level.camera.project(&Point3::from(p.coords - v.origin)));
                    match uk {
                        Some(uk) => j[k] = n.dot(&(uk - u)) / if k < 3 { hc } else { ha },
                        None => ok = false,
                    }
                }
                if !ok {
                    continue;
                }
                // Limbs: the edge is expected `b` px inside (offset -b): r = -offset - b.
                let mut r = -hit.offset;
                if cfg.limb_offsets {
                    if let SampleKind::Limb { .. } = s.kind {
                        let k = if model.sections[s.section].r == body_r { 5 } else { 6 };
                        r -= boff[k - 5];
                        j[k] = -1.0;
                    }
                }
                let w = tukey_weight(r, cfg.tukey_px) * scale * scale;
                if w <= 0.0 {
                    continue;
                }
                eq.add(vi, &j, r, w);
            }
        }
        if it == 0 {
            for vi in 0..2 {
                for k in 0..n_limbs {
                    polarity[vi][k] = votes[vi][k].signum() as i8;
                }
            }
        }
        (counts, rms) = (eq.counts, eq.rms());
        if counts.0 < cfg.min_samples || counts.1 < cfg.min_samples {
            return None;
        }
        // Priors (in the current parameters): the start pose, weakly, and the ground tilt.
        let mut a = eq.jtj;
        let mut g = eq.jtr;
        let dc = cur.c - c0;
        for k in 0..3 {
            a[(k, k)] += wc;
            g[k] += wc * dc[k];
        }
        // Turn from the start in the (u1, u2) basis: (a·u1, a0·u) ≈ -(a0·u_k).
        for (k, u) in [(3, u1), (4, u2)] {
            a[(k, k)] += wa;
            g[k] += wa * (-a0.dot(&u));
        }
        if cfg.distance_sigma_m.is_finite() && cfg.distance_sigma_m > 0.0 {
            // The centre's distance (|c|) about the start's: J = ĉ for the centre.
            let s = cfg.noise_px / cfg.distance_sigma_m;
            let ch = cur.c.normalize();
            let jd = V7::from_column_slice(&[ch.x, ch.y, ch.z, 0.0, 0.0, 0.0, 0.0]) * s;
            a += jd * jd.transpose();
            g += jd * (s * (cur.c.norm() - c0.norm()));
        }
        let wb = if cfg.limb_offsets { (cfg.noise_px / cfg.limb_offset_sigma_px).powi(2) } else { 1.0 };
        for k in 5..7 {
            a[(k, k)] += wb;
            g[k] += wb * boff[k - 5];
        }
        if let Some((nrm, sigma)) = ground {
            // Residual g = (n·a)/σ in units of the nominal noise: J = (n·u1, n·u2)/σ.
            let s = cfg.noise_px / sigma;
            let jg = V7::from_column_slice(&[0.0, 0.0, 0.0, nrm.dot(&u1), nrm.dot(&u2), 0.0, 0.0]) * s;
            a += jg * jg.transpose();
            g += jg * (s * nrm.dot(&cur.a));
        }
        for k in 0..7 {
            a[(k, k)] += 1e-3 * eq.jtj[(k, k)];
        }
        let step = a.lu().solve(&(-g))?;
        if !step.iter().all(|v| v.is_finite()) {
            return None;
        }
        let mut step = step;
        for k in 0..3 {
            step[k] = step[k].clamp(-0.004, 0.004);
        }
        for k in 3..5 {
            step[k] = step[k].clamp(-0.01, 0.01);
        }
        for k in 5..7 {
            boff[k - 5] += step[k].clamp(-0.5, 0.5);
        }
        cur = state_of(&step.fixed_rows::<5>(0).into_owned());
        if step.fixed_rows::<3>(0).amax() < 2e-5 && step.fixed_rows::<2>(3).amax() < 2e-5 && it >= 3 {
            break;
        }
    }
    let moved = (cur.c - c0).norm();
    let turned = cur.a.dot(&a0).clamp(-1.0, 1.0).acos().to_degrees();
    (moved <= cfg.max_move_m && turned <= cfg.max_turn_deg).then_some(TwoViewFit { state: cur, samples: counts, rms_px: rms, moved_m: moved, turned_deg: turned, limb_offsets_px: (boff[0], boff[1]), iterations: iters })
}
