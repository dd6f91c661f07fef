//! Photometric depth of a fitted tube from a rectified stereo pair.
//!
//! Edges fix the tube's image position and direction well but its distance poorly; block
//! matching (SGM) on a ~15 px wide convex tube is biased by its windows and smoothness terms.
//! Here the fitted cylinder itself predicts the disparity of every left pixel it covers: with
//! `Z(u)` the camera depth of the cylinder's front surface along pixel `u`'s ray (ray-cylinder
//! intersection over the model's sections) and `f B` the rectified focal length times the
//! baseline,
//!
//! ```text
//! d_s(u) = f B / (s · Z(u))
//! ```
//!
//! for the tube scaled by `s` about the camera centre (scaling leaves the left image unchanged,
//! up to the tube's size, and moves the centre along its viewing ray). The scale maximizing the
//! zero-mean normalized cross-correlation between `I_L(u)` and `I_R(u_x - d_s(u), u_y)` over
//! the covered pixels is searched coarse to fine (1 mm, then 0.1 mm of centre distance, then
//! a parabola through the best three).

use crate::contour::AxisState;
use crate::model::CylinderModel;
use nalgebra::Vector3;
use tubeloc_core::{CameraModel, Plane};

/// Result of [`photometric_depth`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PhotoDepth {
    /// Shift of the centre along its viewing ray, metres (positive: away from the camera).
    pub shift_m: f64,
    /// ZNCC at the best shift, in [-1, 1].
    pub zncc: f64,
    /// Left pixels used.
    pub pixels: usize,
}

/// Camera depth of the front surface of the tube along the ray `r` (camera frame, `r.z = 1`),
/// or `None` when the ray misses the lateral surface.
fn front_depth(model: &CylinderModel, st: &AxisState, r: &Vector3<f64>) -> Option<f64> {
    let a = st.a;
    let rp = r - a * r.dot(&a);
    let cp = st.c - a * st.c.dot(&a);
    let qa = rp.norm_squared();
    if qa < 1e-18 {
        return None;
    }
    let qb = rp.dot(&cp);
    let mut best: Option<f64> = None;
    for s in &model.sections {
        let qc = cp.norm_squared() - s.r * s.r;
        let disc = qb * qb - qa * qc;
        if disc < 0.0 {
            continue;
        }
        let t = (qb - disc.sqrt()) / qa;
        if t <= 0.0 {
            continue;
        }
        let z = (r * t - st.c).dot(&a);
        if z >= s.z0 && z <= s.z1 && best.is_none_or(|b| t < b) {
            best = Some(t);
        }
    }
    best.map(|t| t * r.z)
}

/// Searches the centre's distance along its viewing ray within `±range_m` (see the module
/// docs). `camera` is the rectified left camera (no distortion) of the rectified images
/// `left`/`right` (intensities, any scale); `st` is in that camera's frame; `fb` is
/// `f · B` in pixel metres. All shifts are scored on the covered pixels whose match stays
/// inside the right image over the whole search. `None` when fewer than 30 pixels, or fewer
/// than half of the covered ones, are so used, or the correlation is undefined (flat images).
pub fn photometric_depth(model: &CylinderModel, camera: &CameraModel, left: &Plane<f32>, right: &Plane<f32>, fb: f64, st: &AxisState, range_m: f64) -> Option<PhotoDepth> {
    photometric_depth_visible(model, camera, left, right, fb, st, range_m, None)
}

/// Scene occluders for the photometric stage: a disparity map of the rectified left image
/// (pixels; NaN or ≤ 0 where unknown, e.g. SGM). A covered pixel whose scene depth
/// `f B / d(u)` lies more than `margin_m` in front of the cylinder's front depth `Z(u)` shows
/// an occluder (rock, sand), not the tube, and is left out of the correlation.
#[derive(Clone, Copy, Debug)]
pub struct Occluders<'a> {
    /// Disparity of the rectified left image, pixels.
    pub disparity: &'a Plane<f32>,
    /// Least depth in front of the tube's surface for a pixel to count as occluded, metres.
    pub margin_m: f64,
}

/// [`photometric_depth`] leaving out the pixels hidden by `occluders`.
#[allow(clippy::too_many_arguments)]
pub fn photometric_depth_visible(model: &CylinderModel, camera: &CameraModel, left: &Plane<f32>, right: &Plane<f32>, fb: f64, st: &AxisState, range_m: f64, occluders: Option<&Occluders>) -> Option<PhotoDepth> {
    let covered = covered_pixels(model, camera, left, st, fb, occluders)?;
    let w = left.width as f64;
    let dist = st.c.norm();
    // Every shift is scored on the same pixels: those whose match stays inside the right image
    // over the whole search (its column `x - f B / (s Z)` grows with `s`). A set that changed
    // with the shift, at a tube cut by the right image's border, would favour the shifts that
    // keep or drop the border pixels rather than those that align the views.
    let reach = range_m + 2e-3;
    let (s_lo, s_hi) = ((dist - reach) / dist, (dist + reach) / dist);
    let px: Vec<_> = covered.iter().copied().filter(|&(x, _, _, z)| x as f64 - fb / (s_lo * z) >= 0.0 && x as f64 - fb / (s_hi * z) <= w - 1.0).collect();
    // ZNCC for a centre shift `s_m` along the ray (scale (dist + s_m) / dist).
    let zncc = |s_m: f64| -> Option<f64> {
        let s = (dist + s_m) / dist;
        let pairs: Vec<(f64, f64)> = px.iter().map(|&(x, y, l, z)| (l as f64, right.sample_bilinear((x as f64 - fb / (s * z)) as f32, y) as f64)).collect();
        zncc_of(&pairs, covered.len())
    };
    let scan = |lo: f64, hi: f64, step: f64| -> Option<(f64, f64)> {
        let k = ((hi - lo) / step).round() as i64;
        (0..=k)
            .filter_map(|i| {
                let s = lo + i as f64 * step;
                zncc(s).map(|c| (s, c))
            })
            .max_by(|a, b| a.1.total_cmp(&b.1))
    };
    let (s1, _) = scan(-range_m, range_m, 1e-3)?;
    let (s2, c2) = scan(s1 - 1.5e-3, s1 + 1.5e-3, 1e-4)?;
    // Parabola through the best three fine samples.
    let shift = match (zncc(s2 - 1e-4), zncc(s2 + 1e-4)) {
        (Some(a), Some(b)) if a + b - 2.0 * c2 < 0.0 => s2 + 0.5 * 1e-4 * (a - b) / (a + b - 2.0 * c2),
        _ => s2,
    };
    Some(PhotoDepth { shift_m: shift, zncc: c2, pixels: px.len() })
}

/// Result of [`photometric_ends`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PhotoEnds {
    /// The state with both ends moved along their viewing rays.
    pub state: AxisState,
    /// Shifts of the two ends (`c - a L/2`, `c + a L/2`) along their rays, metres.
    pub shifts_m: (f64, f64),
    /// ZNCC at the best shifts.
    pub zncc: f64,
    /// Left pixels used.
    pub pixels: usize,
}

/// Like [`photometric_depth`] but with two parameters: each end of the axis segment
/// (`P± = c ± a L/2`) moves along its own viewing ray by `δ±`, which keeps the image of the
/// axis segment (edges fix it) while the distance and the tilt toward the camera (weak in one
/// image) follow the stereo pair. The front depth `Z(u)` of every pixel covered by the input
/// state is recomputed per hypothesis; a grid of 2 mm over `±range_m`, then 0.25 mm over
/// ±2 mm and 0.05 mm over ±0.25 mm around the best.
pub fn photometric_ends(model: &CylinderModel, camera: &CameraModel, left: &Plane<f32>, right: &Plane<f32>, fb: f64, st: &AxisState, range_m: f64) -> Option<PhotoEnds> {
    photometric_ends_visible(model, camera, left, right, fb, st, range_m, None)
}

/// [`photometric_ends`] leaving out the pixels hidden by `occluders`.
#[allow(clippy::too_many_arguments)]
pub fn photometric_ends_visible(model: &CylinderModel, camera: &CameraModel, left: &Plane<f32>, right: &Plane<f32>, fb: f64, st: &AxisState, range_m: f64, occluders: Option<&Occluders>) -> Option<PhotoEnds> {
    let half = 0.5 * model.length;
    let (pm, pp) = (st.c - st.a * half, st.c + st.a * half);
    let (rm, rp) = (pm.normalize(), pp.normalize());
    let state_of = |dm: f64, dp: f64| -> Option<AxisState> {
        let (qm, qp) = (pm + rm * dm, pp + rp * dp);
        let a = qp - qm;
        (a.norm() > 1e-6 && qm.z > 0.0 && qp.z > 0.0).then(|| AxisState { c: 0.5 * (qm + qp), a: a.normalize() })
    };
    let covered = covered_pixels(model, camera, left, st, fb, occluders)?;
    let w = left.width as f64;
    // As in [`photometric_depth_visible`], every hypothesis is scored on the same pixels: those
    // whose match stays inside the right image for front depths within the search's reach.
    let reach = range_m + 2.5e-3;
    let pix: Vec<_> = covered.iter().copied().filter(|&(x, _, _, z)| z > reach && x as f64 - fb / (z - reach) >= 0.0 && x as f64 - fb / (z + reach) <= w - 1.0).collect();
    let mut pairs = Vec::with_capacity(pix.len());
    let mut score = |dm: f64, dp: f64| -> Option<f64> {
        let s = state_of(dm, dp)?;
        pairs.clear();
        for &(x, y, l, z0) in &pix {
            let r = Vector3::new((x as f64 - camera.cx) / camera.fx, (y as f64 - camera.cy) / camera.fy, 1.0);
            let z = front_depth(model, &s, &r).unwrap_or(z0 * s.c.norm() / st.c.norm());
            let xr = x as f64 - fb / z;
            pairs.push((l as f64, right.sample_bilinear(xr.clamp(0.0, w - 1.0) as f32, y) as f64));
        }
        zncc_of(&pairs, covered.len())
    };
    let mut best: Option<(f64, f64, f64)> = None;
    let mut grid = |c: (f64, f64), r: f64, step: f64, best: &mut Option<(f64, f64, f64)>| {
        let k = (r / step).round() as i64;
        for i in -k..=k {
            for j in -k..=k {
                let (dm, dp) = (c.0 + i as f64 * step, c.1 + j as f64 * step);
                if let Some(v) = score(dm, dp) {
                    if best.is_none_or(|b| v > b.2) {
                        *best = Some((dm, dp, v));
                    }
                }
            }
        }
    };
    grid((0.0, 0.0), range_m, 2e-3, &mut best);
    let (dm, dp, _) = best?;
    grid((dm, dp), 2e-3, 2.5e-4, &mut best);
    let (dm, dp, _) = best?;
    grid((dm, dp), 2.5e-4, 5e-5, &mut best);
    let (dm, dp, v) = best?;
    Some(PhotoEnds { state: state_of(dm, dp)?, shifts_m: (dm, dp), zncc: v, pixels: pix.len() })
}

/// Pixels covered by the tube's lateral surface at `st` and not hidden by `occluders`, each
/// `(x, y, left intensity, front depth)`; `None` when fewer than 30.
fn covered_pixels(model: &CylinderModel, camera: &CameraModel, left: &Plane<f32>, st: &AxisState, fb: f64, occluders: Option<&Occluders>) -> Option<Vec<(f32, f32, f32, f64)>> {
    let (mut x0, mut y0, mut x1, mut y1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
    for p in st.bounding_points(model)? {
        let u = camera.project(&nalgebra::Point3::from(p))?;
        (x0, y0, x1, y1) = (x0.min(u.x), y0.min(u.y), x1.max(u.x), y1.max(u.y));
    }
    let (w, h) = (left.width as f64, left.height as f64);
    let (xa, ya, xb, yb) = (x0.floor().max(0.0), y0.floor().max(0.0), x1.ceil().min(w - 1.0), y1.ceil().min(h - 1.0));
    if xa > xb || ya > yb {
        return None;
    }
    let mut px = Vec::new();
    for y in ya as usize..=yb as usize {
        for x in xa as usize..=xb as usize {
            let r = Vector3::new((x as f64 - camera.cx) / camera.fx, (y as f64 - camera.cy) / camera.fy, 1.0);
            if let Some(z) = front_depth(model, st, &r) {
                let hidden = occluders.is_some_and(|o| {
                    let d = if x < o.disparity.width && y < o.disparity.height { o.disparity.get(x, y) as f64 } else { f64::NAN };
                    d.is_finite() && d > 0.0 && fb / d < z - o.margin_m
                });
                if !hidden {
                    px.push((x as f32, y as f32, left.get(x, y), z));
                }
            }
        }
    }
    (px.len() >= 30).then_some(px)
}

/// ZNCC of `(left, right)` intensity pairs; `None` when fewer than half of the `total` covered
/// pixels (or fewer than 30) fall inside the right image, or either side is flat.
fn zncc_of(pairs: &[(f64, f64)], total: usize) -> Option<f64> {
    if pairs.len() < 30 || 2 * pairs.len() < total {
        return None;
    }
    let n = pairs.len() as f64;
    let (ml, mr) = pairs.iter().fold((0.0, 0.0), |a, p| (a.0 + p.0 / n, a.1 + p.1 / n));
    let (mut cov, mut vl, mut vr) = (0.0, 0.0, 0.0);
    for &(l, r) in pairs {
        cov += (l - ml) * (r - mr);
        vl += (l - ml) * (l - ml);
        vr += (r - mr) * (r - mr);
    }
    (vl > 1e-12 && vr > 1e-12).then(|| cov / (vl * vr).sqrt())
}

/// `st` moved by `shift_m` along its centre's viewing ray (the axis direction is unchanged).
pub fn shifted(st: &AxisState, shift_m: f64) -> AxisState {
    let d = st.c.norm();
    AxisState { c: st.c * ((d + shift_m) / d), a: st.a }
}
