//! Stereo points for the refiner's stereo term: rectify a pair, match with SGM only in the
//! regions of the tubes, triangulate, and keep, per region, the points whose left pixel lies in
//! the region's mask (eroded) or box.
//!
//! The disparity window is centred on the seeds: with `f B` the rectified focal length times
//! the baseline (pixels · metres), the search starts at `d_min = f B / (z_max + 0.5 m)` (`z_max`:
//! the farthest seed's depth; 0 without seeds) and spans `num_disparities` pixels.

use anyhow::{Context, Result};
use nalgebra::{Point2, Point3};
use tubeloc_core::{BinaryMask, CameraModel, Plane, Pose, TubeAxisPose};
use tubeloc_refine::{AxisState, CylinderModel};
use tubeloc_stereo::{disparity_regions, Roi, SgmParams, StereoRectification};

/// A tube region in the left image (original pixels): COCO box `[x, y, w, h]` and optional
/// mask of the left image's size.
pub(crate) struct Region {
    /// Box `[x, y, w, h]`, pixels.
    pub bbox: [f64; 4],
    /// Mask (left image size), or `None` to use the box.
    pub mask: Option<BinaryMask>,
    /// Depth of the seed's centre along the left optical axis, metres (if known).
    pub seed_z: Option<f64>,
}

/// Mask eroded by `r` pixels (4-neighbourhood, applied `r` times).
pub(crate) fn erode(m: &BinaryMask, r: usize) -> BinaryMask {
    let mut cur = m.clone();
    for _ in 0..r {
        let prev = cur.clone();
        cur = BinaryMask::from_fn(m.width, m.height, |x, y| {
            prev.get(x, y)
                && x > 0
                && y > 0
                && x + 1 < m.width
                && y + 1 < m.height
                && prev.get(x - 1, y)
                && prev.get(x + 1, y)
                && prev.get(x, y - 1)
                && prev.get(x, y + 1)
        });
    }
    cur
}

/// Stereo points (left camera frame, metres) per region: the pair (`left`/`right` images of
/// cameras `lcam`/`rcam`, `t_left_right` mapping right-camera points into the left frame) is
/// rectified, matched with SGM in the regions' boxes (32 px margin), triangulated and split by
/// region (masks eroded by `erode_px` first to drop the boundary pixels where SGM fattens the
/// foreground).
/// Also returns the rectification and the rectified pair (for [`photo_refine`]).
#[allow(clippy::too_many_arguments)]
pub(crate) fn points_per_region(lcam: &CameraModel, rcam: &CameraModel, t_left_right: &Pose, left: &Plane<u8>, right: &Plane<u8>, regions: &[Region], num_disparities: usize, erode_px: usize) -> Result<(StereoRegions, Rectified)> {
    let rect = StereoRectification::new(lcam, rcam, t_left_right).context("rectifying the pair")?;
    let sr = points_rectified(&rect, lcam, left, right, regions, num_disparities, erode_px)?;
    let mut pair = rectified_pair(rect, left, right)?;
    pair.disparity = Some(sr.disparity.clone());
    Ok((sr, pair))
}

/// What SGM gives the refiner: the points of each region (left camera frame, metres), the
/// scene depth map of the left image and the rectified disparity map.
pub(crate) struct StereoRegions {
    /// Points per region (left camera frame, metres).
    pub points: Vec<Vec<Point3<f64>>>,
    /// Depth `Z` (metres, left camera frame) per left-image pixel where SGM matched (NaN
    /// elsewhere): every triangulated point splatted onto its nearest left pixel, the nearest
    /// point kept. The refiner's scene-occlusion test ([`tubeloc_refine::Scene::depth`]).
    pub depth: Plane<f32>,
    /// Disparity of the rectified left image (NaN where not matched), pixels.
    pub disparity: Plane<f32>,
}

/// Splats points (left camera frame) into a depth map of the left image (nearest pixel, the
/// nearest point wins; NaN where none falls).
fn depth_map(lcam: &CameraModel, pts: &[tubeloc_stereo::StereoPoint]) -> Plane<f32> {
    let (w, h) = (lcam.width as usize, lcam.height as usize);
    let mut depth = Plane::filled(w, h, f32::NAN);
    for p in pts {
        let Some(u) = lcam.project(&p.point) else { continue };
        let (x, y) = (u.x.round(), u.y.round());
        if x < 0.0 || y < 0.0 || x >= w as f64 || y >= h as f64 {
            continue;
        }
        let z = p.point.z as f32;
        let cur = &mut depth.data[y as usize * w + x as usize];
        if !(cur.is_finite() && *cur <= z) {
            *cur = z;
        }
    }
    depth
}

/// The rectified pair of `left`/`right` (intensities in [0, 1]) under `rect`.
pub(crate) fn rectified_pair(rect: StereoRectification, left: &Plane<u8>, right: &Plane<u8>) -> Result<Rectified> {
    let (rl, rr) = rect.rectify_pair(left, right)?;
    let f = |p: &Plane<u8>| Plane::from_vec(p.width, p.height, p.data.iter().map(|&v| v as f32 / 255.0).collect());
    Ok(Rectified { left: f(&rl), right: f(&rr), rect, disparity: None })
}

/// A rectified pair (intensities in [0, 1]) with its rectification.
pub(crate) struct Rectified {
    /// Rectified left image.
    pub left: Plane<f32>,
    /// Rectified right image.
    pub right: Plane<f32>,
    /// The rectification.
    pub rect: StereoRectification,
    /// SGM disparity of the rectified left image (NaN where not matched), for the photometric
    /// stage's occlusion test.
    pub disparity: Option<Plane<f32>>,
}

/// Moves a converged pose along its centre's viewing ray to the photometric depth of
/// [`tubeloc_refine::photo`] (searched within `±range_m`), or with `ends` each end along its
/// own ray ([`tubeloc_refine::photo::photometric_ends`]: distance and tilt); returns the
/// centre's change of distance (metres), `None` (pose unchanged) when the search gave no
/// answer, a correlation below `min_zncc` or a shift at the edge of the range. `occlusion`
/// leaves out pixels hidden by the scene (SGM disparity, [`Rectified::disparity`]). Then, for
/// axes within `rim_max_epipolar_deg` of the rows, the axis direction is taken from the rims in
/// both views ([`tubeloc_refine::rims`]) about the photometric centre, with a prior of
/// `rim_tilt_prior_deg` (degrees) on the tilt change when given (a ground plane's tilt prior);
/// the rims alone also apply when the photometric search gave no answer.
#[allow(clippy::too_many_arguments)]
pub(crate) fn photo_refine(pose: &mut TubeAxisPose, model: &CylinderModel, pair: &Rectified, range_m: f64, min_zncc: f64, ends: bool, occlusion: bool, rim_max_epipolar_deg: f64, rim_tilt_prior_deg: Option<f64>) -> Option<f64> {
    if !pose.converged {
        return None;
    }
    let r1 = pair.rect.r_left;
    let st = AxisState { c: r1 * pose.centre, a: r1 * pose.end_direction };
    let g = pair.rect.geometry();
    let fb = g.f * g.baseline;
    let occ = pair.disparity.as_ref().filter(|_| occlusion).map(|d| tubeloc_refine::photo::Occluders { disparity: d, margin_m: model.occlusion_margin() });
    let debug = std::env::var_os("TUBELOC_DEBUG_PHOTO").is_some();
    let photo = if ends {
        tubeloc_refine::photo::photometric_ends_visible(model, &pair.rect.rectified, &pair.left, &pair.right, fb, &st, range_m, occ.as_ref()).and_then(|pe| {
            // Diagnostics: TUBELOC_DEBUG_PHOTO=1 prints each photometric result.
            if debug {
                eprintln!("photo image {} centre {:.4} {:.4} {:.4}: shifts {:.2} {:.2} mm zncc {:.3} pixels {}", pose.image_id, pose.centre.x, pose.centre.y, pose.centre.z, pe.shifts_m.0 * 1e3, pe.shifts_m.1 * 1e3, pe.zncc, pe.pixels);
            }
            (pe.zncc >= min_zncc && pe.shifts_m.0.abs() < range_m && pe.shifts_m.1.abs() < range_m).then_some(pe.state)
        })
    } else {
        tubeloc_refine::photo::photometric_depth_visible(model, &pair.rect.rectified, &pair.left, &pair.right, fb, &st, range_m, occ.as_ref())
            .and_then(|pd| (pd.zncc >= min_zncc && pd.shift_m.abs() < range_m).then(|| tubeloc_refine::photo::shifted(&st, pd.shift_m)))
    };
    // The axis direction from the rims in both views (`tubeloc_refine::rims`) about the
    // photometric centre (whose distance, from all covered pixels, is better than the rims'),
    // for axes within `rim_max_epipolar_deg` of the rows.
    let base = photo.unwrap_or(st);
    let dir = nalgebra::Vector2::new(base.a.x - base.a.z * base.c.x / base.c.z, base.a.y - base.a.z * base.c.y / base.c.z);
    let psi = dir.y.abs().atan2(dir.x.abs()).to_degrees();
    // With a ground plane, the rims weigh against the tilt fitted under the ground's tilt prior
    // (`rim_tilt_prior_deg`, its standard deviation: σ_τ = (L/2) σ_θ).
    let tau_sigma = rim_tilt_prior_deg.map_or(f64::INFINITY, |d| 0.5 * model.length * d.to_radians());
    let rims = if psi < rim_max_epipolar_deg { tubeloc_refine::rims::rim_ends_with_prior(model, &pair.rect.rectified, &pair.left, &pair.right, g.baseline, &base, range_m, 6, tau_sigma) } else { None };
    if let (true, Some(r)) = (debug, &rims) {
        eprintln!("rims image {} centre {:.4} psi {psi:.1}: shifts {:.2} {:.2} {:.2} mm samples {:?} rms {:.2}", pose.image_id, pose.centre.x, r.shifts_m.0 * 1e3, r.shifts_m.1 * 1e3, r.shifts_m.2 * 1e3, r.samples, r.rms_px);
    }
    let moved = match (photo, rims) {
        (_, Some(r)) => AxisState { c: base.c, a: r.state.a },
        (Some(p), None) => p,
        (None, None) => return None,
    };
    let shift = moved.c.norm() - st.c.norm();
    let (c, a) = (r1.transpose() * moved.c, r1.transpose() * moved.a);
    let mut p = match TubeAxisPose::new(pose.image_id, pose.score, c, a, pose.end_confidence) {
        Ok(p) => p,
        Err(_) => return None,
    };
    p.covariance = pose.covariance;
    p.residuals = pose.residuals.clone();
    *pose = p;
    Some(shift)
}

/// [`points_per_region`] with a rectification already made.
pub(crate) fn points_rectified(rect: &StereoRectification, lcam: &CameraModel, left: &Plane<u8>, right: &Plane<u8>, regions: &[Region], num_disparities: usize, erode_px: usize) -> Result<StereoRegions> {
    let empty = |n: usize| StereoRegions {
        points: vec![Vec::new(); n],
        depth: Plane::filled(lcam.width as usize, lcam.height as usize, f32::NAN),
        disparity: Plane::filled(rect.rectified.width as usize, rect.rectified.height as usize, f32::NAN),
    };
    if regions.is_empty() {
        return Ok(empty(0));
    }
    let (rl, rr) = rect.rectify_pair(left, right)?;
    // Regions: each box mapped into rectified left pixels through its corners.
    let mut rois = Vec::new();
    for d in regions {
        let [x, y, w, h] = d.bbox;
        let (mut x0, mut y0, mut x1, mut y1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
        for (u, v) in [(x, y), (x + w, y), (x, y + h), (x + w, y + h)] {
            if let Some(p) = rect.project_left(&Point3::from(lcam.unproject(&Point2::new(u, v)))) {
                (x0, y0, x1, y1) = (x0.min(p.x), y0.min(p.y), x1.max(p.x), y1.max(p.y));
            }
        }
        if x1 > x0 && y1 > y0 {
            rois.push(Roi::new(x0.floor() as i64, y0.floor() as i64, (x1 - x0).ceil() as i64 + 1, (y1 - y0).ceil() as i64 + 1));
        }
    }
    if rois.is_empty() {
        return Ok(empty(regions.len()));
    }
    let geom = rect.geometry();
    let fb = geom.f * geom.baseline;
    let z_max = regions.iter().filter_map(|r| r.seed_z).filter(|z| z.is_finite() && *z > 0.0).fold(0.0, f64::max);
    let min_disparity = if z_max > 0.0 { (fb / (z_max + 0.5)).floor() as i32 } else { 0 };
    let params = SgmParams { num_disparities, min_disparity, ..SgmParams::default() };
    let disp = disparity_regions(&rl, &rr, &params, &rois, 32).context("matching the regions")?;
    let pts = rect.points_in_left_camera(&tubeloc_stereo::triangulate(&disp, &geom, 0.25));
    let depth = depth_map(lcam, &pts);
    let masks: Vec<Option<BinaryMask>> = regions.iter().map(|r| r.mask.as_ref().map(|m| erode(m, erode_px))).collect();
    let points = regions
        .iter()
        .zip(&masks)
        .map(|(d, m)| {
            // Rectified left columns whose match (at about the seed's disparity) lies left of the
            // right image cannot be matched: SGM picks a wrong, smaller disparity there.
            let min_x = d.seed_z.filter(|z| z.is_finite() && *z > 0.0).map_or(f64::NEG_INFINITY, |z| 1.05 * fb / z + 2.0);
            pts.iter()
                .filter_map(|p| {
                    if (p.pixel[0] as f64) < min_x {
                        return None;
                    }
                    let u = lcam.project(&p.point)?;
                    let [x, y, w, h] = d.bbox;
                    let inside = match m {
                        Some(m) => u.x >= -0.5 && u.y >= -0.5 && (u.x + 0.5) < m.width as f64 && (u.y + 0.5) < m.height as f64 && m.get((u.x + 0.5) as usize, (u.y + 0.5) as usize),
                        None => u.x >= x && u.y >= y && u.x <= x + w && u.y <= y + h,
                    };
                    inside.then_some(p.point)
                })
                .collect()
        })
        .collect();
    Ok(StereoRegions { points, depth, disparity: disp })
}
