//! Tubes with one end hidden: the visible end anchors the centre (stereo).
//!
//! Where a rock, a sand mound or the image border hides one end of a tube, the fit has no end
//! outline there and its centre slides toward the middle of what is visible: along the axis
//! the centre was off by about half the hidden length (30-50 mm, the p90 of the along-axis
//! error on the stereo sets). The detector's mask says how much of the tube is visible, and
//! the scene's depth map says which end is hidden: beyond a hidden end something nearer than
//! the tube covers it, beyond a visible end the ground lies at or behind the tube.
//!
//! Along the fitted tube's image axis `u` (from its projected foot end `p₀` to its seal end
//! `p₁`, `ℓ = |p₁ - p₀|` pixels) the mask's pixels span `[t₋, t₊]` (1st and 99th percentiles
//! about the projected middle). When the mask covers less than `max_visible_fraction` of `ℓ`,
//! the depth map is read just beyond each mask end (`gap_px` along `u`, `±half_width_px`
//! across): the median of `Z_scene - Z_axis` over those pixels, with `Z_axis` the depth of the
//! tube's axis point that projects there. An end is hidden when that median is below
//! `-occluder_margin_m` (something in front) or when all its pixels lie outside the image (the
//! border cuts the tube); it is visible when the median is at least `-occluder_margin_m`. With
//! exactly one end hidden the tube is moved along its axis until its visible end's projection
//! meets the mask's end there: by `-(ℓ/2 - t₊) L / ℓ` metres (seal end visible) or
//! `+(t₋ + ℓ/2) L / ℓ` (foot end visible), `L` the tube's length. Otherwise nothing changes.
//!
//! Whether anchored or not, the fit's covariance does not know how far the centre may slide
//! along the axis where the mask shows only part of the tube; [`unseen_length_variance`] and
//! [`widen_along_axis`] add that to the centre's covariance (any mask seed, mono or stereo).

use nalgebra::{Point2, Point3, Vector2};
use tubeloc_core::{BoundedMask, CameraModel, Plane, TubeAxisPose};

/// Settings of [`anchor_visible_end`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HiddenEnd {
    /// The mask must cover less than this fraction of the tube's projected length.
    pub max_visible_fraction: f64,
    /// Scene depth this much nearer than the tube's axis (metres) beyond a mask end hides it.
    pub occluder_margin_m: f64,
    /// Pixels beyond a mask end read from the depth map, along the axis (first, last).
    pub gap_px: (usize, usize),
    /// Pixels on each side of the axis read from the depth map.
    pub half_width_px: usize,
    /// Least valid depth pixels for a decision at an end inside the image.
    pub min_depth_pixels: usize,
}

impl Default for HiddenEnd {
    /// Chosen on the three calibration stereo sets (seeds 11-13) with learned detections,
    /// stereo + ground: fraction 0.9 among 0.8 / 0.9 / 1.0 and margin 5 mm among 5 / 10 / 20 mm
    /// (`docs/design/0022-hidden-end-and-unseen-length.md`).
    fn default() -> Self {
        HiddenEnd { max_visible_fraction: 0.9, occluder_margin_m: 0.005, gap_px: (3, 12), half_width_px: 3, min_depth_pixels: 5 }
    }
}

/// What the depth map says about one end of the tube.
#[derive(Clone, Copy, Debug, PartialEq)]
enum EndView {
    /// Something nearer than the tube lies beyond the mask's end, or the image ends there.
    Hidden,
    /// The ground beyond the mask's end lies at or behind the tube.
    Visible,
    /// Too few depth pixels to tell.
    Unknown,
}

/// Moves `pose` (camera frame, metres) along its axis so that its visible end meets the end of
/// the detector's `mask` when the other end is hidden (module docs); `depth` is the scene's
/// depth map (Z, metres, non-finite or ≤ 0 unknown) in `camera`'s image, `length_m` the tube's
/// length. Returns the move (metres along `pose.end_direction`), or `None` when nothing moved.
pub fn anchor_visible_end(pose: &mut TubeAxisPose, length_m: f64, mask: &BoundedMask, depth: &Plane<f32>, camera: &CameraModel, cfg: &HiddenEnd) -> Option<f64> {
    if !pose.converged || mask.width != camera.width as usize || mask.height != camera.height as usize || depth.width != mask.width || depth.height != mask.height {
        return None;
    }
    let (c, a) = (pose.centre, pose.end_direction);
    let half = a * (0.5 * length_m);
    let p0 = camera.project(&Point3::from(c - half))?;
    let p1 = camera.project(&Point3::from(c + half))?;
    let ell = (p1 - p0).norm();
    if ell.is_nan() || ell < 10.0 {
        return None;
    }
    let u = (p1 - p0) / ell;
    let mid = Point2::from((p0.coords + p1.coords) * 0.5);
    let (t_lo, t_hi) = mask_span(mask, &mid, &u)?;
    if (t_hi - t_lo) / ell >= cfg.max_visible_fraction {
        return None;
    }
    let view = |t_end: f64, side: f64| end_view(t_end, side, &mid, &u, depth, camera, pose, length_m / ell, cfg);
    let (foot, seal) = (view(t_lo, -1.0), view(t_hi, 1.0));
    let shift = match (foot, seal) {
        (EndView::Hidden, EndView::Visible) => -(0.5 * ell - t_hi) * length_m / ell,
        (EndView::Visible, EndView::Hidden) => (t_lo + 0.5 * ell) * length_m / ell,
        _ => return None,
    };
    if !shift.is_finite() || shift.abs() > 0.5 * length_m {
        return None;
    }
    pose.centre = c + a * shift;
    let which = if shift < 0.0 { "foot" } else { "seal" };
    pose.end_anchored = Some(format!("the {which} end is hidden: moved {:.1} mm along the axis to meet the mask's other end", shift.abs() * 1e3));
    Some(shift)
}

/// How far the mask lets the centre slide along the axis: the variance (m²) of the centre's
/// along-axis position that the fit's covariance does not hold, for `pose` and the detector's
/// `mask` (module docs for `ℓ`, `t₋`, `t₊`).
///
/// The mask covers the fraction `f = (min(t₊, ℓ/2) - max(t₋, -ℓ/2)) / ℓ` of the projected
/// tube. Where an end is hidden the edges do not say where the tube ends, and the centre can
/// sit anywhere over the hidden length `h = (1 - f) L`: the variance of a uniform spread,
/// `h² / 12`. A tube anchored at its visible end ([`anchor_visible_end`]) keeps that end's
/// uncertainty instead, `(anchor_px · L / ℓ)²`. `None` when the pose did not converge, the
/// mask is empty or of another size, or the tube projects shorter than 10 px.
pub fn unseen_length_variance(pose: &TubeAxisPose, length_m: f64, mask: &BoundedMask, camera: &CameraModel, anchor_px: f64) -> Option<f64> {
    if !pose.converged || mask.width != camera.width as usize || mask.height != camera.height as usize {
        return None;
    }
    let half = pose.end_direction * (0.5 * length_m);
    let p0 = camera.project(&Point3::from(pose.centre - half))?;
    let p1 = camera.project(&Point3::from(pose.centre + half))?;
    let ell = (p1 - p0).norm();
    if ell.is_nan() || ell < 10.0 {
        return None;
    }
    if pose.end_anchored.is_some() {
        return Some((anchor_px * length_m / ell).powi(2));
    }
    let (t_lo, t_hi) = mask_span(mask, &Point2::from((p0.coords + p1.coords) * 0.5), &((p1 - p0) / ell))?;
    let f = ((t_hi.min(0.5 * ell) - t_lo.max(-0.5 * ell)) / ell).clamp(0.0, 1.0);
    Some(((1.0 - f) * length_m).powi(2) / 12.0)
}

/// Adds `variance` (m²) along the axis to `pose`'s centre covariance: `Σ_c += v a aᵀ`.
pub fn widen_along_axis(pose: &mut TubeAxisPose, variance: f64) {
    let a = pose.axis;
    for i in 0..3 {
        for j in 0..3 {
            pose.covariance[i][j] += variance * a[i] * a[j];
        }
    }
}

/// The 1st and 99th percentiles of the mask pixels' positions along `u` from `mid` (pixels);
/// `None` for an empty mask.
fn mask_span(mask: &BoundedMask, mid: &Point2<f64>, u: &Vector2<f64>) -> Option<(f64, f64)> {
    let [bx, by, bw, bh] = mask.bbox();
    let mut t = Vec::new();
    for y in by as usize..(by + bh) as usize {
        for x in bx as usize..(bx + bw) as usize {
            if mask.data[y * mask.width + x] != 0 {
                t.push((x as f64 - mid.x) * u.x + (y as f64 - mid.y) * u.y);
            }
        }
    }
    if t.is_empty() {
        return None;
    }
    t.sort_by(|a, b| a.total_cmp(b));
    let at = |q: f64| t[((t.len() - 1) as f64 * q).round() as usize];
    Some((at(0.01), at(0.99)))
}

/// The depth map beyond the mask's end at `t_end` on `side` (+1 seal, -1 foot) of the tube.
#[allow(clippy::too_many_arguments)]
fn end_view(t_end: f64, side: f64, mid: &Point2<f64>, u: &Vector2<f64>, depth: &Plane<f32>, camera: &CameraModel, pose: &TubeAxisPose, metres_per_px: f64, cfg: &HiddenEnd) -> EndView {
    let n = Vector2::new(-u.y, u.x);
    let (mut diffs, mut inside) = (Vec::new(), 0);
    for k in cfg.gap_px.0..=cfg.gap_px.1 {
        let t = t_end + side * k as f64;
        // The axis point that projects (about) here: its depth is the tube's.
        let z_axis = (pose.centre + pose.end_direction * (t * metres_per_px)).z;
        for j in -(cfg.half_width_px as i64)..=cfg.half_width_px as i64 {
            let q = mid + u * t + n * j as f64;
            let (x, y) = (q.x.round(), q.y.round());
            if !(x >= 0.0 && y >= 0.0 && x < camera.width as f64 && y < camera.height as f64) {
                continue;
            }
            inside += 1;
            let z = depth.get(x as usize, y as usize) as f64;
            if z.is_finite() && z > 0.0 {
                diffs.push(z - z_axis);
            }
        }
    }
    if inside == 0 {
        return EndView::Hidden;
    }
    if diffs.len() < cfg.min_depth_pixels {
        return EndView::Unknown;
    }
    let m = diffs.len() / 2;
    let (_, med, _) = diffs.select_nth_unstable_by(m, |a, b| a.total_cmp(b));
    if *med < -cfg.occluder_margin_m {
        EndView::Hidden
    } else {
        EndView::Visible
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;
    use tubeloc_core::BinaryMask;

    /// A tube 1 m ahead across the view, its foot half hidden by a rock 5 cm nearer: the mask
    /// covers the seal half, and the pose, centred on what is visible, moves back by the hidden
    /// quarter length onto the truth.
    #[test]
    fn a_tube_half_hidden_by_a_nearer_rock_is_anchored_at_its_visible_end() {
        let cam = CameraModel::from_hfov(400, 300, 40.0);
        let (len, truth) = (0.15, Vector3::new(0.0, 0.0, 1.0));
        let px = |x: f64| cam.project(&Point3::new(x, 0.0, 1.0)).unwrap().x;
        // Visible: the axis from x = 0 (hidden beyond) to x = +L/2 (seal end).
        let (x_lo, x_hi) = (px(0.0), px(0.5 * len));
        let mask = BoundedMask::new(BinaryMask::from_fn(400, 300, |x, y| (x as f64) >= x_lo && (x as f64) <= x_hi && (y as f64 - cam.cy).abs() <= 8.0));
        // Ground 5 cm behind the tube, a rock 5 cm in front of it left of x = 0.
        let depth = Plane::from_vec(400, 300, (0..400 * 300).map(|i| if ((i % 400) as f64) < x_lo { 0.95f32 } else { 1.05 }).collect());
        let fitted = Vector3::new(0.25 * len, 0.0, 1.0);
        let mut pose = TubeAxisPose::new(0, 1.0, fitted, Vector3::x(), 0.9).unwrap();
        let shift = anchor_visible_end(&mut pose, len, &mask, &depth, &cam, &HiddenEnd::default()).expect("anchored");
        assert!((pose.centre - truth).norm() < 0.002, "centre {:?}, moved {shift}", pose.centre);
        assert!(pose.end_anchored.as_deref().unwrap().contains("foot end is hidden"));
        // Without the rock (ground behind on both sides) neither end is hidden: nothing moves.
        let open = Plane::from_vec(400, 300, vec![1.05f32; 400 * 300]);
        let mut pose = TubeAxisPose::new(0, 1.0, fitted, Vector3::x(), 0.9).unwrap();
        assert_eq!(anchor_visible_end(&mut pose, len, &mask, &open, &cam, &HiddenEnd::default()), None);
        assert_eq!(pose.centre, fitted);
        // A mask covering the whole tube: nothing is hidden.
        let whole = BoundedMask::new(BinaryMask::from_fn(400, 300, |x, y| (x as f64) >= px(-0.5 * len) && (x as f64) <= x_hi && (y as f64 - cam.cy).abs() <= 8.0));
        let mut pose = TubeAxisPose::new(0, 1.0, truth, Vector3::x(), 0.9).unwrap();
        assert_eq!(anchor_visible_end(&mut pose, len, &whole, &depth, &cam, &HiddenEnd::default()), None);
    }

    /// The centre's unseen along-axis spread: half the tube masked gives the uniform variance
    /// of the hidden half, a whole mask next to none, an anchored tube its end's few pixels; the
    /// widening adds along the axis only.
    #[test]
    fn the_unseen_length_widens_the_centre_along_the_axis() {
        let cam = CameraModel::from_hfov(400, 300, 40.0);
        let len = 0.15;
        let px = |x: f64| cam.project(&Point3::new(x, 0.0, 1.0)).unwrap().x;
        let band = |x0: f64, x1: f64| BoundedMask::new(BinaryMask::from_fn(400, 300, move |x, y| (x as f64) >= px(x0) && (x as f64) <= px(x1) && (y as f64 - cam.cy).abs() <= 8.0));
        let pose = TubeAxisPose::new(0, 1.0, Vector3::new(0.0, 0.0, 1.0), Vector3::x(), 0.9).unwrap();
        let half = unseen_length_variance(&pose, len, &band(0.0, 0.5 * len), &cam, 3.0).unwrap();
        let expected = (0.5 * len).powi(2) / 12.0;
        assert!((half.sqrt() - expected.sqrt()).abs() < 0.002, "σ {} vs {}", half.sqrt(), expected.sqrt());
        let whole = unseen_length_variance(&pose, len, &band(-0.5 * len, 0.5 * len), &cam, 3.0).unwrap();
        assert!(whole.sqrt() < 0.002, "whole tube masked: σ {}", whole.sqrt());
        let ell = px(0.5 * len) - px(-0.5 * len);
        let mut anchored = pose.clone();
        anchored.end_anchored = Some("test".into());
        let v = unseen_length_variance(&anchored, len, &band(0.0, 0.5 * len), &cam, 3.0).unwrap();
        assert!((v.sqrt() - 3.0 * len / ell).abs() < 1e-9);
        assert_eq!(unseen_length_variance(&pose, len, &BoundedMask::new(BinaryMask::new(40, 30)), &cam, 3.0), None, "a mask of another size");
        let mut widened = pose.clone();
        widen_along_axis(&mut widened, half);
        assert!((widened.covariance[0][0] - pose.covariance[0][0] - half).abs() < 1e-15);
        for (i, j) in [(1, 1), (2, 2), (0, 1), (3, 3), (4, 4)] {
            assert_eq!(widened.covariance[i][j], pose.covariance[i][j], "entry {i},{j}");
        }
    }

    /// The image border hides the seal end: the foot end anchors.
    #[test]
    fn a_tube_cut_by_the_border_is_anchored_at_its_foot() {
        let cam = CameraModel::from_hfov(400, 300, 40.0);
        let len = 0.15;
        // Seal end beyond the right border: the tube's axis from x_f to past 400 px.
        let f = cam.fx;
        let z = 1.0;
        let x_edge = (399.5 - cam.cx) / f * z;
        // 45 mm of the tube are in view, from its foot.
        let foot = x_edge - 0.045;
        let truth = Vector3::new(foot + 0.5 * len, 0.0, z);
        let mask = BoundedMask::new(BinaryMask::from_fn(400, 300, |x, y| (x as f64) >= cam.project(&Point3::new(foot, 0.0, z)).unwrap().x && (y as f64 - cam.cy).abs() <= 8.0));
        let depth = Plane::from_vec(400, 300, vec![1.05f32; 400 * 300]);
        // The fit centred on the visible part.
        let fitted = Vector3::new(0.5 * (foot + x_edge), 0.0, z);
        let mut pose = TubeAxisPose::new(0, 1.0, fitted, Vector3::x(), 0.9).unwrap();
        anchor_visible_end(&mut pose, len, &mask, &depth, &cam, &HiddenEnd::default()).expect("anchored");
        assert!((pose.centre - truth).norm() < 0.002, "centre {:?} vs {truth:?}", pose.centre);
    }
}
