//! Coarse seed search: widens the basin of the fit beyond the edge-search radius.
//!
//! A seed off by ~10 mm and ~5 degrees (one Line2D template step, or a learned mask axis placed
//! by its width) puts the projected contour 10-30 full-resolution pixels from the tube, beyond
//! what the 1D normal searches of [`crate::fit`] associate reliably. Before the fit, the seed's
//! contour is therefore aligned exhaustively at the coarsest pyramid level over
//! - rotations of the axis by `θ ∈ {0, ±Δ, ±2Δ, ...}` about the ground normal (with a ground
//!   plane: the axis stays parallel to it) or about the viewing ray through the centre, and
//! - image translations `d` of the projected contour on a grid of `step` pixels within `±R`,
//!   then ±1 pixel around the best,
//!
//! scoring each by the edge support `S(θ, d) = Σ_i |∇I(u_i + d) · n_i| / N` of the visible
//! contour samples `u_i` with normals `n_i` (nearest-pixel gradient lookups). The best
//! translation is turned back into 3D by moving the centre along the image ray of the shifted
//! centre pixel, keeping its depth (or, with a ground plane, its height above the ground).

use crate::contour::{build_samples_capped, project_with_normal, AxisState};
use crate::edges::GradientLevel;
use crate::model::CylinderModel;
use crate::seed::GroundPlane;
use nalgebra::{Point2, Point3, Rotation3, Unit, Vector2, Vector3};

/// Settings of [`coarse_search`] (level pixels and degrees).
#[derive(Clone, Copy, Debug)]
pub struct SearchSpec {
    /// Half width of the translation grid, level pixels.
    pub radius_px: i32,
    /// Spacing of the translation grid, level pixels (refined by ±1 around the best).
    pub step_px: i32,
    /// Largest rotation of the axis tried, degrees.
    pub max_rotation_deg: f64,
    /// Rotation step, degrees.
    pub rotation_step_deg: f64,
    /// Most contour samples scored.
    pub max_samples: usize,
}

/// One scored hypothesis.
#[derive(Clone, Copy, Debug)]
pub struct Hypothesis {
    /// The moved seed.
    pub state: AxisState,
    /// Mean edge support `S` (intensity per pixel).
    pub score: f64,
}

/// Projected visible contour of a state at a level: pixel, normal.
fn projected(model: &CylinderModel, st: &AxisState, lv: &GradientLevel, max_samples: usize, out: &mut Vec<(Point2<f64>, Vector2<f64>)>) {
    out.clear();
    let Some(f) = st.frame() else { return };
    let spacing = 2.0;
    for s in build_samples_capped(model, st, &lv.camera, spacing, max_samples) {
        let Some(p) = s.eval(model, &f) else { continue };
        if !s.on_silhouette(model, &f, &p) || model.occludes(&st.c, &st.a, &(p.x + p.out * (0.02 * model.body_radius() + 1e-4))) {
            continue;
        }
        if let Some(un) = project_with_normal(&lv.camera, &p) {
            out.push(un);
        }
    }
}

/// A projected sample rounded to its nearest pixel, with its normal.
#[derive(Clone, Copy)]
struct Tap {
    x: i32,
    y: i32,
    nx: f32,
    ny: f32,
    /// Index of `(x, y)` in the level's gradient plane relative to the taps' box corner,
    /// `(y - y_min) width + x - x_min`.
    at: u32,
}

/// The rounded samples and their pixel box `(x_min, y_min, x_max, y_max)`.
struct Taps {
    taps: Vec<Tap>,
    bounds: (i32, i32, i32, i32),
}

fn taps(pts: &[(Point2<f64>, Vector2<f64>)], width: usize) -> Taps {
    let mut taps: Vec<Tap> = pts.iter().map(|(u, n)| Tap { x: u.x.round() as i32, y: u.y.round() as i32, nx: n.x as f32, ny: n.y as f32, at: 0 }).collect();
    let bounds = taps.iter().fold((i32::MAX, i32::MAX, i32::MIN, i32::MIN), |b, t| (b.0.min(t.x), b.1.min(t.y), b.2.max(t.x), b.3.max(t.y)));
    for t in &mut taps {
        t.at = ((t.y - bounds.1) as i64 * width as i64 + (t.x - bounds.0) as i64).clamp(0, u32::MAX as i64) as u32;
    }
    Taps { taps, bounds }
}

/// Mean edge support of the projected samples shifted by `(dx, dy)` level pixels. Where the
/// shifted box lies inside the level, the taps are read without the per-tap bounds test (the
/// same sum, in the same order).
fn support(lv: &GradientLevel, pts: &Taps, dx: i32, dy: i32) -> f64 {
    let (w, h) = (lv.width as i32, lv.height as i32);
    let (x0, y0, x1, y1) = pts.bounds;
    let mut s = 0.0f32;
    if x0 + dx >= 0 && y0 + dy >= 0 && x1 + dx < w && y1 + dy < h {
        // Every shifted tap `(x + dx, y + dy)` is inside: its index is `at` past the shifted
        // box's corner.
        let grad = &lv.grad[(y0 + dy) as usize * w as usize + (x0 + dx) as usize..];
        for t in &pts.taps {
            let g = grad[t.at as usize];
            s += (g[0] * t.nx + g[1] * t.ny).abs();
        }
    } else {
        for t in &pts.taps {
            let (x, y) = (t.x + dx, t.y + dy);
            if x < 0 || y < 0 || x >= w || y >= h {
                continue;
            }
            let g = lv.grad[(y * w + x) as usize];
            s += (g[0] * t.nx + g[1] * t.ny).abs();
        }
    }
    s as f64 / pts.taps.len().max(1) as f64
}

/// Best translation on the grid, then ±1 around it: `(score, dx, dy)`.
fn best_shift(lv: &GradientLevel, pts: &Taps, spec: &SearchSpec) -> (f64, i32, i32) {
    let step = spec.step_px.max(1);
    let r = spec.radius_px.max(0) / step * step;
    let mut best = (f64::MIN, 0, 0);
    let mut dy = -r;
    while dy <= r {
        let mut dx = -r;
        while dx <= r {
            let s = support(lv, pts, dx, dy);
            // Ties prefer the smaller move.
            if s > best.0 || (s == best.0 && dx * dx + dy * dy < best.1 * best.1 + best.2 * best.2) {
                best = (s, dx, dy);
            }
            dx += step;
        }
        dy += step;
    }
    let (_, bx, by) = best;
    for ddy in -1..=1 {
        for ddx in -1..=1 {
            if ddx == 0 && ddy == 0 {
                continue;
            }
            let s = support(lv, pts, bx + ddx, by + ddy);
            if s > best.0 {
                best = (s, bx + ddx, by + ddy);
            }
        }
    }
    best
}

/// Moves the centre of `st` so that its projection moves by `d` level pixels: along the new
/// image ray at the same depth, or at the same height above `ground`.
fn shifted(st: &AxisState, lv: &GradientLevel, d: Vector2<f64>, ground: Option<&GroundPlane>) -> Option<AxisState> {
    let u = lv.camera.project(&Point3::from(st.c))?;
    let ray = lv.camera.unproject(&(u + d));
    let t = match ground {
        Some(g) => {
            let den = g.normal.dot(&ray);
            let h = g.normal.dot(&st.c) - g.offset;
            if den.abs() < 1e-9 {
                return None;
            }
            (g.offset + h) / den
        }
        None => st.c.z / ray.z,
    };
    (t.is_finite() && t > 0.0).then(|| AxisState { c: ray * t, a: st.a })
}

/// The seed resting on `g`: centre moved along its viewing ray to height `h`, axis projected
/// onto the plane. `None` when the ray does not meet that height in front of the camera or
/// the axis is perpendicular to the plane.
pub fn onto_ground(st: &AxisState, g: &GroundPlane, h: f64) -> Option<AxisState> {
    let den = g.normal.dot(&st.c);
    if den.abs() < 1e-9 {
        return None;
    }
    let t = (g.offset + h) / den;
    let a = st.a - g.normal * g.normal.dot(&st.a);
    (t > 0.0 && t.is_finite() && a.norm() > 1e-3).then(|| AxisState { c: st.c * t, a: a.normalize() })
}

/// Scores rotated and shifted copies of `seed` at level `lv` (`height_known`: see
/// [`crate::settings::Priors::ground_height_known`]) and returns them best first (one
/// per rotation, each at its best translation). The unmoved seed is among the candidates
/// scored (rotation 0, translation 0 competes on the same grid).
pub fn coarse_search(model: &CylinderModel, lv: &GradientLevel, seed: &AxisState, ground: Option<&GroundPlane>, height_known: bool, spec: &SearchSpec) -> Vec<Hypothesis> {
    // With a ground plane, first put the seed on it: centre `max_radius` above the plane along
    // its viewing ray (same pixel; with `height_known` false the seed keeps its height), axis
    // parallel to the plane.
    let seed = &match ground.and_then(|g| onto_ground(seed, g, if height_known { model.max_radius() } else { g.normal.dot(&seed.c) - g.offset })) {
        Some(s) => s,
        None => *seed,
    };
    let axis_of_rotation = match ground {
        Some(g) => g.normal,
        None => seed.c.normalize(),
    };
    let Some(rot_axis) = Unit::try_new(axis_of_rotation, 1e-9) else { return Vec::new() };
    let nrot = if spec.rotation_step_deg > 0.0 { (spec.max_rotation_deg / spec.rotation_step_deg).floor() as i32 } else { 0 };
    let mut pts = Vec::new();
    let mut out = Vec::new();
    for k in -nrot..=nrot {
        let th = (k as f64 * spec.rotation_step_deg).to_radians();
        let a: Vector3<f64> = Rotation3::from_axis_angle(&rot_axis, th) * seed.a;
        let st = AxisState { c: seed.c, a };
        projected(model, &st, lv, spec.max_samples, &mut pts);
        if pts.len() < 8 {
            continue;
        }
        let (score, dx, dy) = best_shift(lv, &taps(&pts, lv.width), spec);
        // Over a ground of unknown height the seed's depth is the better guess than its height.
        if let Some(moved) = shifted(&st, lv, Vector2::new(dx as f64, dy as f64), ground.filter(|_| height_known)) {
            out.push(Hypothesis { state: moved, score });
        }
    }
    out.sort_by(|a, b| b.score.total_cmp(&a.score));
    out
}
