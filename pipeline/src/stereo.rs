//! Stereo for the refiner (the SGM call; the computation on its points is in
//! [`tubeloc_refine::stereo_stage`]):
//! rectify a pair, match with SGM only in the regions of the tubes, triangulate, and split the
//! points by region ([`stereo_stage::region_points`]); the scene depth map and the rectified
//! pair for the photometric / rims stage ([`stereo_stage::photo_refine`]).
//!
//! The disparity window is centred on the seeds ([`stereo_stage::min_disparity`]) and spans
//! `num_disparities` pixels.

use crate::error::Result;
use nalgebra::{Point2, Point3};
use tubeloc_core::{CameraModel, Plane, Pose, TubeDetection};
use tubeloc_refine::local_ground::{self, LocalGround, LocalGroundConfig};
use tubeloc_refine::stereo_stage::{self, RectifiedPair, StereoRegion};
use tubeloc_refine::GroundPlane;
use tubeloc_stereo::{disparity_regions, Roi, SgmParams, StereoRectification};

/// Stereo points (left camera frame, metres) per region: the pair (`left`/`right` images of
/// cameras `lcam`/`rcam`, `t_left_right` mapping right-camera points into the left frame) is
/// rectified and matched ([`match_regions`]).
#[allow(clippy::too_many_arguments)]
pub fn points_per_region(
    lcam: &CameraModel,
    rcam: &CameraModel,
    t_left_right: &Pose,
    left: &Plane<u8>,
    right: &Plane<u8>,
    regions: &[StereoRegion],
    num_disparities: usize,
    erode_px: usize,
    ground: Option<&GroundPlane>,
) -> Result<(StereoRegions, RectifiedPair)> {
    let rect = StereoRectification::new(lcam, rcam, t_left_right)?;
    match_regions(&rect, lcam, left, right, regions, num_disparities, erode_px, ground)
}

/// The stereo region of a detection: its box, its mask (if it decodes) and its template pose's
/// depth (if any).
pub fn region_of(d: &TubeDetection) -> StereoRegion {
    StereoRegion { bbox: d.bbox, mask: d.mask.as_ref().and_then(|m| m.to_mask().ok()), seed_z: d.t_cam_tube.as_ref().map(|t| t.translation().z) }
}

/// What SGM gives the refiner: the points of each region (left camera frame, metres), the
/// scene depth map of the left image and the rectified disparity map.
pub struct StereoRegions {
    /// Points per region (left camera frame, metres).
    pub points: Vec<Vec<Point3<f64>>>,
    /// Depth `Z` (metres, left camera frame) per left-image pixel where SGM matched (NaN
    /// elsewhere; [`stereo_stage::depth_map`]). The refiner's scene-occlusion test
    /// ([`tubeloc_refine::Scene::depth`]).
    pub depth: Plane<f32>,
    /// Disparity of the rectified left image (NaN where not matched), pixels.
    pub disparity: Plane<f32>,
    /// Per region, the given ground plane moved to the height of the matched terrain beside
    /// it ([`local_ground::local_grounds`]); all `None` without a ground plane.
    pub local_grounds: Vec<Option<LocalGround>>,
}

impl StereoRegions {
    /// The ground plane of each region: its local ground where there is one, else `ground`.
    pub fn tube_grounds(&self, ground: Option<GroundPlane>) -> Vec<Option<GroundPlane>> {
        self.local_grounds.iter().map(|l| l.map(|l| l.plane).or(ground)).collect()
    }
}

/// The pair rectified under `rect`, matched with SGM in the regions' boxes mapped into the
/// rectified left image (32 px margin), triangulated and split by region (masks eroded by
/// `erode_px` first); also the rectified pair (intensities in [0, 1]) with its SGM disparity for
/// the photometric stage. With a `ground` plane, also each region's local ground; a region
/// whose box lies where the left image cannot be matched (left of the nominal ground's
/// disparity, near the left border) gets a 64 px wide strip of terrain matched just right of
/// that column for it.
#[allow(clippy::too_many_arguments)]
pub fn match_regions(rect: &StereoRectification, lcam: &CameraModel, left: &Plane<u8>, right: &Plane<u8>, regions: &[StereoRegion], num_disparities: usize, erode_px: usize, ground: Option<&GroundPlane>) -> Result<(StereoRegions, RectifiedPair)> {
    let (rl, rr) = rect.rectify_pair(left, right)?;
    let sr = points_rectified(rect, lcam, &rl, &rr, regions, num_disparities, erode_px, ground)?;
    let mut pair = RectifiedPair::from_u8(&rl, &rr, rect.rectified.clone(), rect.r_left, rect.baseline);
    pair.disparity = Some(sr.disparity.clone());
    Ok((sr, pair))
}

/// [`match_regions`]' points of the rectified pair `rl`/`rr`.
#[allow(clippy::too_many_arguments)]
fn points_rectified(rect: &StereoRectification, lcam: &CameraModel, rl: &Plane<u8>, rr: &Plane<u8>, regions: &[StereoRegion], num_disparities: usize, erode_px: usize, ground: Option<&GroundPlane>) -> Result<StereoRegions> {
    let empty = |n: usize| StereoRegions {
        points: vec![Vec::new(); n],
        depth: Plane::filled(lcam.width as usize, lcam.height as usize, f32::NAN),
        disparity: Plane::filled(rect.rectified.width as usize, rect.rectified.height as usize, f32::NAN),
        local_grounds: vec![None; n],
    };
    let geom = rect.geometry();
    let fb = geom.f * geom.baseline;
    if regions.is_empty() {
        return Ok(empty(0));
    }
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
            // Terrain for the local ground where the box (grown by the 32 px margin) has
            // fewer than 64 columns that can be matched.
            let centre = Point2::new(x + 0.5 * w, y + 0.5 * h);
            if let Some(d) = ground.and_then(|g| local_ground::nominal_disparity(g, &lcam.unproject(&centre), fb)) {
                let first = (1.05 * d + 2.0).ceil();
                if x1 + 32.0 < first + 64.0 && first >= 0.0 && first + 32.0 <= rect.rectified.width as f64 {
                    rois.push(Roi::new(first as i64, y0.floor() as i64, 32, (y1 - y0).ceil() as i64 + 1));
                }
            }
        }
    }
    if rois.is_empty() {
        return Ok(empty(regions.len()));
    }
    let params = SgmParams { num_disparities, min_disparity: stereo_stage::min_disparity(regions, fb), ..SgmParams::default() };
    let disp = disparity_regions(rl, rr, &params, &rois, 32)?;
    let pts: Vec<(f32, Point3<f64>)> = rect.points_in_left_camera(&tubeloc_stereo::triangulate(&disp, &geom, 0.25)).into_iter().map(|p| (p.pixel[0], p.point)).collect();
    let depth = stereo_stage::depth_map(lcam, pts.iter().map(|(_, p)| p));
    let points = stereo_stage::region_points(lcam, &pts, regions, fb, erode_px);
    let local_grounds = match ground {
        Some(g) => local_ground::local_grounds(lcam, &pts, regions, g, fb, &LocalGroundConfig::default()),
        None => vec![None; regions.len()],
    };
    Ok(StereoRegions { points, depth, disparity: disp, local_grounds })
}

/// The scene points (left camera frame, metres) within `radius` metres of `centre`, from the
/// scene depth map `depth` (Z per left-image pixel, NaN where SGM did not match) of camera
/// `lcam`: every `step`-th pixel of the window that a sphere of that radius covers in the
/// image is unprojected at its depth. The terrain near a tube for the grasp check.
pub fn points_near(depth: &Plane<f32>, lcam: &CameraModel, centre: &nalgebra::Vector3<f64>, radius: f64, step: usize) -> Vec<Point3<f64>> {
    let Some(c) = lcam.project(&Point3::from(*centre)) else { return Vec::new() };
    let near_z = (centre.z - radius).max(0.05);
    let r_px = lcam.fx.max(lcam.fy) * radius / near_z;
    let (w, h) = (depth.width as f64, depth.height as f64);
    let (x0, x1) = ((c.x - r_px).floor().max(0.0), (c.x + r_px).ceil().min(w - 1.0));
    let (y0, y1) = ((c.y - r_px).floor().max(0.0), (c.y + r_px).ceil().min(h - 1.0));
    if x1 < x0 || y1 < y0 {
        return Vec::new();
    }
    let step = step.max(1);
    let mut out = Vec::new();
    for y in (y0 as usize..=y1 as usize).step_by(step) {
        let row = depth.row(y);
        for x in (x0 as usize..=x1 as usize).step_by(step) {
            let z = row[x];
            if z.is_finite() && z > 0.0 {
                let p = lcam.unproject_depth(&Point2::new(x as f64, y as f64), z as f64);
                if (p.coords - centre).norm() <= radius {
                    out.push(p);
                }
            }
        }
    }
    out
}
