//! Stereo end outlines: each end's distance from the rims (end outlines and section
//! boundaries) seen in both images of a rectified pair.
//!
//! A tube whose image runs along the epipolar lines (rows of the rectified pair) shows its
//! disparity only where its outline crosses the rows: at the rims. Its limbs slide along
//! themselves between the views, and the photometric search ([`crate::photo`]) over the
//! covered pixels is then nearly flat in the tilt toward the camera. Here the rims are fitted in
//! both images at once, in the rectified left camera frame, with two parameters: `τ`, opposite
//! moves `∓τ` of the axis ends `P± = c ± a L/2` along their left viewing rays (as in
//! [`crate::photo::photometric_ends`]: the left image line is kept, the tilt toward the camera
//! changes, the distance of the centre hardly), and `s`, a move of the tube along its axis (the
//! distance is left to the photometric search, which uses every covered pixel). Residuals:
//! for every visible rim sample `X` and view `v` (left: `X`, right: `X − (B, 0, 0)`), the offset
//! along the image normal `n` between the projection and the nearest edge found by a 1D search
//! ([`crate::edges::GradientLevel::search_all`]), Tukey-weighted; Gauss-Newton with numeric
//! Jacobians, re-searching the edges every iteration.

use crate::contour::{build_samples, project_with_normal, AxisState, SampleKind};
use crate::edges::{build_pyramid_with, roi, GradientLevel};
use crate::model::CylinderModel;
use crate::normal_equations::TwoViewNormalEquations;
use crate::robust::tukey_weight;
use nalgebra::{Point2, Vector2, Vector3};
use tubeloc_core::{CameraModel, Plane};

/// Result of [`rim_ends`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RimEnds {
    /// The state with the ends moved (rectified left frame).
    pub state: AxisState,
    /// Moves of the two ends along their left viewing rays (`-τ`, `+τ`), metres, and along
    /// the axis (`s`).
    pub shifts_m: (f64, f64, f64),
    /// Rim samples with an edge: left view, right view.
    pub samples: (usize, usize),
    /// Robust RMS of the rim residuals at the end, pixels.
    pub rms_px: f64,
}

/// One view of a rectified pair: its gradient level (unsmoothed full resolution, cropped to
/// the tube's projection plus 16 px) and its camera centre in the rectified left frame.
pub(crate) struct View {
    pub(crate) level: GradientLevel,
    pub(crate) origin: Vector3<f64>,
}

/// The [`View`] of `image` (camera centre `origin`) for the tube at `st`; `None` when the tube
/// does not project into the image.
pub(crate) fn view(model: &CylinderModel, camera: &CameraModel, image: &Plane<f32>, st: &AxisState, origin: Vector3<f64>) -> Option<View> {
    let (mut x0, mut y0, mut x1, mut y1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
    for p in st.bounding_points(model)? {
        let u = camera.project(&nalgebra::Point3::from(p - origin))?;
        (x0, y0, x1, y1) = (x0.min(u.x), y0.min(u.y), x1.max(u.x), y1.max(u.y));
    }
    let rect = roi([x0, y0, x1 - x0, y1 - y0], 16.0, image.width, image.height)?;
    let level = build_pyramid_with(image, camera, rect, 1, false).into_iter().next()?;
    Some(View { level, origin })
}

/// Fits the ends' distances and the axial placement to the rims in both views of a rectified
/// pair (module docs). `camera`: the rectified camera of both views; `baseline_m`: the right
/// camera's offset along the rectified x axis; `st` in the rectified left frame;
/// `range_m` bounds each end's move. `None` when either view has fewer than `min_samples` rim
/// edges or the fit leaves the range.
#[allow(clippy::too_many_arguments)]
pub fn rim_ends(model: &CylinderModel, camera: &CameraModel, left: &Plane<f32>, right: &Plane<f32>, baseline_m: f64, st: &AxisState, range_m: f64, min_samples: usize) -> Option<RimEnds> {
    rim_ends_with_prior(model, camera, left, right, baseline_m, st, range_m, min_samples, f64::INFINITY)
}

/// [`rim_ends`] with a prior on `τ`: standard deviation `tau_sigma_m` (metres) about 0, i.e.
/// about the input's tilt (e.g. one fitted under a ground plane's tilt prior: `σ_τ ≈ (L/2) σ_θ`);
/// the rim residuals count with a nominal 0.5 px noise against it.
#[allow(clippy::too_many_arguments)]
pub fn rim_ends_with_prior(model: &CylinderModel, camera: &CameraModel, left: &Plane<f32>, right: &Plane<f32>, baseline_m: f64, st: &AxisState, range_m: f64, min_samples: usize, tau_sigma_m: f64) -> Option<RimEnds> {
    let views = [view(model, camera, left, st, Vector3::zeros())?, view(model, camera, right, st, Vector3::new(baseline_m, 0.0, 0.0))?];
    let half = 0.5 * model.length;
    let (pm, pp) = (st.c - st.a * half, st.c + st.a * half);
    let (rm, rp) = (pm.normalize(), pp.normalize());
    let state_of = |p: &Vector2<f64>| -> Option<AxisState> {
        let (qm, qp) = (pm - rm * p.x, pp + rp * p.x);
        let a = (qp - qm).try_normalize(1e-9)?;
        (qm.z > 0.0 && qp.z > 0.0).then(|| AxisState { c: 0.5 * (qm + qp) + a * p.y, a })
    };
    let samples: Vec<_> = build_samples(model, st, camera, 1.5).into_iter().filter(|s| matches!(s.kind, SampleKind::Rim { .. })).collect();
    // Projections (pixel, normal) of the visible rim samples in view `v` at parameters `p`.
    let project = |v: &View, p: &Vector2<f64>| -> Vec<Option<(Point2<f64>, Vector2<f64>)>> {
        let Some(s) = state_of(p) else { return vec![None; samples.len()] };
        let sv = AxisState { c: s.c - v.origin, a: s.a };
        let Some(f) = sv.frame() else { return vec![None; samples.len()] };
        samples
            .iter()
            .map(|smp| {
                let q = smp.eval(model, &f)?;
                if !smp.on_silhouette(model, &f, &q) || model.occludes(&sv.c, &sv.a, &(q.x + q.out * (0.02 * model.body_radius() + 1e-4))) {
                    return None;
                }
                let (u, n) = project_with_normal(&v.level.camera, &q)?;
                v.level.inside(&u, 5.0).then_some((u, n))
            })
            .collect()
    };
    let mut p = Vector2::zeros();
    let h = 2e-4;
    let mut counts = (0, 0);
    let mut rms = 0.0;
    for it in 0..20 {
        let radius = if it < 3 { 4 } else { 2 };
        let mut eq = TwoViewNormalEquations::<2>::new();
        for (vi, v) in views.iter().enumerate() {
            let base = project(v, &p);
            let dirs: Vec<_> = (0..2).map(|k| project(v, &(p + Vector2::ith(k, h)))).collect();
            for (i, b) in base.iter().enumerate() {
                let Some((u, n)) = b else { continue };
                let hits = v.level.search_all(u, n, radius, 0.004, 0, 0.25);
                let Some(off) = (0..hits.len).map(|k| hits.hits[k].offset).min_by(|a, b| a.abs().total_cmp(&b.abs())) else { continue };
                let mut j = Vector2::zeros();
                let mut ok = true;
                for k in 0..2 {
                    match dirs[k][i] {
                        Some((uk, _)) => j[k] = n.dot(&(uk - u)) / h,
                        None => ok = false,
                    }
                }
                if !ok {
                    continue;
                }
                // Residual: projection minus edge along n, in pixels.
                let r = -off;
                let w = tukey_weight(r, 1.5);
                if w <= 0.0 {
                    continue;
                }
                eq.add(vi, &j, r, w);
            }
        }
        (counts, rms) = (eq.counts, eq.rms());
        if counts.0 < min_samples || counts.1 < min_samples {
            return None;
        }
        // Light damping (1e-3 of the diagonal) and a tiny prior keep weakly observed
        // directions (e.g. a tube across the rows) where they are.
        let mut a = eq.jtj;
        for k in 0..2 {
            a[(k, k)] += 1e-3 * eq.jtj[(k, k)] + 1e-2;
        }
        let mut g = eq.jtr;
        if tau_sigma_m.is_finite() && tau_sigma_m > 0.0 {
            let wp = (0.5 / tau_sigma_m).powi(2);
            a[(0, 0)] += wp;
            g[0] += wp * p.x;
        }
        let step = a.lu().solve(&(-g))?;
        let step = step.map(|v| v.clamp(-0.005, 0.005));
        p += step;
        if p.x.abs() > range_m || p.y.abs() > range_m {
            return None;
        }
        if step.amax() < 2e-5 {
            break;
        }
    }
    Some(RimEnds { state: state_of(&p)?, shifts_m: (-p.x, p.x, p.y), samples: counts, rms_px: rms })
}
