//! The stereo stages around the fit, on core types (no rectification or matching here: the
//! caller rectifies the pair and runs SGM; this crate depends on `tubeloc-core` alone):
//! - per-region stereo points ([`StereoRegion`], [`region_points`]) for [`crate::Scene::stereo_points`];
//! - the scene depth map ([`depth_map`]) for [`crate::Scene::depth`];
//! - after the fit, the photometric / rims stage ([`photo_refine`]) on a [`RectifiedPair`].

use crate::photo::{self, Occluders};
use crate::two_view::{self, TwoViewConfig};
use crate::{rims, AxisState, CylinderModel};
use nalgebra::{Matrix3, Point3, Vector2, Vector3};
use tubeloc_core::{BinaryMask, CameraModel, Plane, TubeAxisPose};

/// A tube region in the left image (original pixels): COCO box and optional mask.
#[derive(Clone, Debug)]
pub struct StereoRegion {
    /// Box `[x, y, w, h]`, pixels.
    pub bbox: [f64; 4],
    /// Mask (left image size), or `None` to use the box.
    pub mask: Option<BinaryMask>,
    /// Depth of the seed's centre along the left optical axis, metres (if known).
    pub seed_z: Option<f64>,
}

/// Start of the disparity window, pixels: `floor(f B / (z_max + 0.5 m))` with `f B` the
/// rectified focal length times the baseline (pixels · metres) and `z_max` the farthest seed's
/// depth; 0 without seeds.
pub fn min_disparity(regions: &[StereoRegion], fb: f64) -> i32 {
    let z_max = regions.iter().filter_map(|r| r.seed_z).filter(|z| z.is_finite() && *z > 0.0).fold(0.0, f64::max);
    if z_max > 0.0 {
        (fb / (z_max + 0.5)).floor() as i32
    } else {
        0
    }
}

/// Splats points (left camera frame, metres) into a depth map `Z` of the left image of `lcam`
/// (nearest pixel, the nearest point wins; NaN where none falls).
pub fn depth_map<'a>(lcam: &CameraModel, points: impl IntoIterator<Item = &'a Point3<f64>>) -> Plane<f32> {
    let (w, h) = (lcam.width as usize, lcam.height as usize);
    let mut depth = Plane::filled(w, h, f32::NAN);
    for p in points {
        let Some(u) = lcam.project(p) else { continue };
        let (x, y) = (u.x.round(), u.y.round());
        if x < 0.0 || y < 0.0 || x >= w as f64 || y >= h as f64 {
            continue;
        }
        let z = p.z as f32;
        let cur = &mut depth.data[y as usize * w + x as usize];
        if !(cur.is_finite() && *cur <= z) {
            *cur = z;
        }
    }
    depth
}

/// Triangulated points per region (left camera frame, metres). `points` are
/// `(x, X)`: the rectified left column `x` (pixels) of each match and its point `X` in the left
/// camera frame. A point is kept for a region when it projects into the region's mask (eroded
/// by `erode_px`) or box, and its column `x ≥ 1.05 f B / z_seed + 2` (`fb = f B`): columns whose
/// match at about the seed's disparity falls left of the right image cannot be matched (SGM
/// picks a wrong, smaller disparity there).
pub fn region_points(lcam: &CameraModel, points: &[(f32, Point3<f64>)], regions: &[StereoRegion], fb: f64, erode_px: usize) -> Vec<Vec<Point3<f64>>> {
    let masks: Vec<Option<BinaryMask>> = regions.iter().map(|r| r.mask.as_ref().map(|m| m.eroded(erode_px))).collect();
    // Each point's left-image projection, once for all regions.
    let projected: Vec<Option<nalgebra::Point2<f64>>> = points.iter().map(|(_, p)| lcam.project(p)).collect();
    regions
        .iter()
        .zip(&masks)
        .map(|(d, m)| {
            let min_x = d.seed_z.filter(|z| z.is_finite() && *z > 0.0).map_or(f64::NEG_INFINITY, |z| 1.05 * fb / z + 2.0);
            points
                .iter()
                .zip(&projected)
                .filter_map(|((px, p), u)| {
                    if (*px as f64) < min_x {
                        return None;
                    }
                    let u = (*u)?;
                    let [x, y, w, h] = d.bbox;
                    let inside = match m {
                        Some(m) => u.x >= -0.5 && u.y >= -0.5 && (u.x + 0.5) < m.width as f64 && (u.y + 0.5) < m.height as f64 && m.get((u.x + 0.5) as usize, (u.y + 0.5) as usize),
                        None => u.x >= x && u.y >= y && u.x <= x + w && u.y <= y + h,
                    };
                    inside.then_some(*p)
                })
                .collect()
        })
        .collect()
}

/// A rectified stereo pair (intensities in [0, 1]) with the geometry the photometric stage needs.
pub struct RectifiedPair {
    /// Rectified left image.
    pub left: Plane<f32>,
    /// Rectified right image.
    pub right: Plane<f32>,
    /// Camera of the rectified left image (no distortion; the right one is it shifted by the
    /// baseline along x).
    pub camera: CameraModel,
    /// Rotation from the original left camera frame into the rectified left frame.
    pub r_left: Matrix3<f64>,
    /// Baseline, metres.
    pub baseline: f64,
    /// SGM disparity of the rectified left image (NaN where not matched), pixels, for the
    /// photometric stage's occlusion test.
    pub disparity: Option<Plane<f32>>,
}

impl RectifiedPair {
    /// The pair from 8-bit rectified images (`v / 255`).
    pub fn from_u8(left: &Plane<u8>, right: &Plane<u8>, camera: CameraModel, r_left: Matrix3<f64>, baseline: f64) -> Self {
        let f = |p: &Plane<u8>| Plane::from_vec(p.width, p.height, p.data.iter().map(|&v| v as f32 / 255.0).collect());
        RectifiedPair { left: f(left), right: f(right), camera, r_left, baseline, disparity: None }
    }

    /// `f B`: rectified focal length times baseline (pixels · metres; disparity = `f B / Z`).
    pub fn fb(&self) -> f64 {
        self.camera.fx * self.baseline
    }
}

/// Settings of [`photo_refine`].
#[derive(Clone, Copy, Debug)]
pub struct PhotoStage {
    /// Search range of the photometric shifts, ± metres.
    pub range_m: f64,
    /// Least ZNCC for the photometric result to be applied.
    pub min_zncc: f64,
    /// Move each end along its own ray (distance and tilt, [`photo::photometric_ends`]) rather
    /// than the centre along its ray (distance, [`photo::photometric_depth`]).
    pub ends: bool,
    /// Leave out pixels hidden by the scene ([`RectifiedPair::disparity`]).
    pub occlusion: bool,
    /// Take the axis direction from the rims for axes within this angle of the rows, degrees.
    pub rim_max_epipolar_deg: f64,
    /// Standard deviation of a prior on the rims' tilt change, degrees (a ground plane's tilt
    /// prior), or `None`.
    pub rim_tilt_prior_deg: Option<f64>,
    /// Last, fit the whole contour in both views over all five pose parameters
    /// ([`two_view::fit_two_view`]) with these settings, or `None`.
    pub two_view: Option<TwoViewConfig>,
    /// Ground plane's unit upward normal in the original left camera frame and the tilt
    /// prior's standard deviation (degrees), for the two-view fit.
    pub ground: Option<(Vector3<f64>, f64)>,
}

/// Moves a converged pose along its centre's viewing ray to the photometric depth of
/// [`photo`] (searched within `±range_m`), or with `ends` each end along its own ray
/// ([`photo::photometric_ends`]: distance and tilt); returns the centre's change of distance
/// (metres), `None` (pose unchanged) when the search gave no answer, a correlation below
/// `min_zncc` or a shift at the edge of the range. `occlusion` leaves out pixels hidden by the
/// scene. Then, for axes within `rim_max_epipolar_deg` of the rows, the axis direction is taken
/// from the rims in both views ([`rims`]) about the photometric centre, with a prior of
/// `rim_tilt_prior_deg` on the tilt change when given; the rims alone also apply when the
/// photometric search gave no answer. Last, with `two_view`, the whole contour is fitted in
/// both views from that result ([`two_view::fit_two_view`], with the ground's tilt prior
/// `ground`), and replaces it when the fit succeeds. `TUBELOC_DEBUG_PHOTO=1` prints each result.
pub fn photo_refine(pose: &mut TubeAxisPose, model: &CylinderModel, pair: &RectifiedPair, cfg: &PhotoStage) -> Option<f64> {
    if !pose.converged {
        return None;
    }
    let range_m = cfg.range_m;
    let r1 = pair.r_left;
    let st = AxisState { c: r1 * pose.centre, a: r1 * pose.end_direction };
    let fb = pair.fb();
    let occ = pair.disparity.as_ref().filter(|_| cfg.occlusion).map(|d| Occluders { disparity: d, margin_m: model.occlusion_margin() });
    let debug = std::env::var_os("TUBELOC_DEBUG_PHOTO").is_some();
    let photo = if cfg.ends {
        photo::photometric_ends_visible(model, &pair.camera, &pair.left, &pair.right, fb, &st, range_m, occ.as_ref()).and_then(|pe| {
            if debug {
                eprintln!("photo image {} centre {:.4} {:.4} {:.4}: shifts {:.2} {:.2} mm zncc {:.3} pixels {}", pose.image_id, pose.centre.x, pose.centre.y, pose.centre.z, pe.shifts_m.0 * 1e3, pe.shifts_m.1 * 1e3, pe.zncc, pe.pixels);
            }
            (pe.zncc >= cfg.min_zncc && pe.shifts_m.0.abs() < range_m && pe.shifts_m.1.abs() < range_m).then_some(pe.state)
        })
    } else {
        photo::photometric_depth_visible(model, &pair.camera, &pair.left, &pair.right, fb, &st, range_m, occ.as_ref()).and_then(|pd| (pd.zncc >= cfg.min_zncc && pd.shift_m.abs() < range_m).then(|| photo::shifted(&st, pd.shift_m)))
    };
    // The axis direction from the rims in both views about the photometric centre (whose
    // distance, from all covered pixels, is better than the rims'), for axes within
    // `rim_max_epipolar_deg` of the rows (angle ψ of the image direction to the rows).
    let base = photo.unwrap_or(st);
    let dir = Vector2::new(base.a.x - base.a.z * base.c.x / base.c.z, base.a.y - base.a.z * base.c.y / base.c.z);
    let psi = dir.y.abs().atan2(dir.x.abs()).to_degrees();
    // With a ground plane, the rims weigh against the tilt fitted under the ground's tilt prior
    // (its standard deviation σ_θ gives the end offsets' σ_τ = (L/2) σ_θ).
    let tau_sigma = cfg.rim_tilt_prior_deg.map_or(f64::INFINITY, |d| 0.5 * model.length * d.to_radians());
    let rims = if psi < cfg.rim_max_epipolar_deg { rims::rim_ends_with_prior(model, &pair.camera, &pair.left, &pair.right, pair.baseline, &base, range_m, 6, tau_sigma) } else { None };
    if let (true, Some(r)) = (debug, &rims) {
        eprintln!("rims image {} centre {:.4} psi {psi:.1}: shifts {:.2} {:.2} {:.2} mm samples {:?} rms {:.2}", pose.image_id, pose.centre.x, r.shifts_m.0 * 1e3, r.shifts_m.1 * 1e3, r.shifts_m.2 * 1e3, r.samples, r.rms_px);
    }
    let moved = match (photo, rims) {
        (_, Some(r)) => Some(AxisState { c: base.c, a: r.state.a }),
        (Some(p), None) => Some(p),
        (None, None) => None,
    };
    // The whole contour in both views, from the stages' result (or the fit's).
    let tv = cfg.two_view.as_ref().and_then(|tc| {
        let ground = cfg.ground.map(|(n, deg)| (r1 * n, deg.to_radians()));
        two_view::fit_two_view(model, &pair.camera, &pair.left, &pair.right, pair.baseline, &moved.unwrap_or(st), occ.as_ref(), ground, tc)
    });
    if let (true, Some(t)) = (debug, &tv) {
        eprintln!(
            "two-view image {} centre {:.4}: moved {:.2} mm turned {:.2} deg samples {:?} rms {:.2} limb offsets {:.2} {:.2} px it {}",
            pose.image_id,
            pose.centre.x,
            t.moved_m * 1e3,
            t.turned_deg,
            t.samples,
            t.rms_px,
            t.limb_offsets_px.0,
            t.limb_offsets_px.1,
            t.iterations
        );
    }
    let moved = tv.map(|t| t.state).or(moved)?;
    let shift = moved.c.norm() - st.c.norm();
    let (c, a) = (r1.transpose() * moved.c, r1.transpose() * moved.a);
    // The new centre and axis; covariance, residuals and `end_anchored` stay the fit's. A kept
    // seed (`seed_kept`) is the detector's no longer.
    let p = TubeAxisPose::new(pose.image_id, pose.score, c, a, pose.end_confidence).ok()?;
    (pose.centre, pose.axis, pose.end_direction) = (p.centre, p.axis, p.end_direction);
    pose.seed_kept = None;
    Some(shift)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam() -> CameraModel {
        CameraModel { width: 100, height: 100, fx: 100.0, fy: 100.0, cx: 50.0, cy: 50.0, distortion: Default::default() }
    }

    #[test]
    fn depth_map_keeps_the_nearest_point() {
        let cam = cam();
        let pts = [Point3::new(0.0, 0.0, 2.0), Point3::new(0.0, 0.0, 1.0), Point3::new(0.0, 0.0, 3.0), Point3::new(10.0, 0.0, 1.0)];
        let d = depth_map(&cam, &pts);
        assert_eq!(d.get(50, 50), 1.0);
        assert_eq!(d.data.iter().filter(|v| v.is_finite()).count(), 1);
    }

    #[test]
    fn region_points_drop_unmatchable_columns_and_use_the_box() {
        let cam = cam();
        let region = StereoRegion { bbox: [40.0, 40.0, 20.0, 20.0], mask: None, seed_z: Some(2.0) };
        // f B = 10: min column 1.05 * 10 / 2 + 2 = 7.25.
        let pts = [(10.0, Point3::new(0.0, 0.0, 2.0)), (5.0, Point3::new(0.01, 0.0, 2.0)), (10.0, Point3::new(1.0, 0.0, 2.0))];
        let per = region_points(&cam, &pts, &[region], 10.0, 0);
        assert_eq!(per, vec![vec![Point3::new(0.0, 0.0, 2.0)]]);
        assert_eq!(min_disparity(&[StereoRegion { bbox: [0.0; 4], mask: None, seed_z: Some(1.5) }], 100.0), 50);
    }
}
