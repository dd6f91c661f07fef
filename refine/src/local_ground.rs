//! The terrain's height around a tube, from the stereo points of the terrain beside it.
//!
//! A ground plane taken from the camera's pose over the nominal ground (`--ground auto`: world
//! `z = 0`) has the right orientation but not the right height under a given tube: the
//! terrain's relief puts tubes up to ~3 cm above or below it (flagstone slabs stand 1-3 cm
//! proud). A tube that gets no stereo points of its own (it lies outside the right camera's
//! view, or is not matched) is placed at that plane's height along its ray, and lands
//! centimetres off. In a stereo run the terrain beside the tube is matched too: the median
//! height
//!
//! ```text
//! h = median_i (n · X_i - d)
//! ```
//!
//! of the `k` terrain points `X_i` nearest the tube's box in the left image (outside every
//! tube's mask, grown by a clearance) moves the plane `n · X = d` to `n · X = d + h`.
//!
//! Points are kept only where a match is possible: a left column `x` (rectified) whose match
//! `x - D` at the terrain's disparity `D` falls left of the right image cannot be matched, and
//! SGM gives it a wrong, smaller disparity. The nominal plane's disparity along the point's own
//! ray stands in for `D` ([`nominal_disparity`], with 5 % to spare as in
//! [`crate::stereo_stage::region_points`]).

use crate::seed::GroundPlane;
use crate::stereo_stage::StereoRegion;
use nalgebra::{Point3, Vector3};
use tubeloc_core::{BinaryMask, CameraModel};

/// Settings of [`local_grounds`].
#[derive(Clone, Debug)]
pub struct LocalGroundConfig {
    /// Terrain points used per tube: the nearest to its box.
    pub points: usize,
    /// Fewer usable terrain points than this within `max_distance_px` of the box: no local
    /// ground.
    pub min_points: usize,
    /// Farthest a terrain point may lie from the tube's box, left-image pixels.
    pub max_distance_px: f64,
    /// Pixels within this distance of any tube's mask (or box, without a mask) are not terrain.
    pub clearance_px: usize,
    /// Largest height change accepted, metres (a larger one is taken as a mismatch: no local
    /// ground).
    pub max_shift_m: f64,
}

impl Default for LocalGroundConfig {
    fn default() -> Self {
        LocalGroundConfig { points: 300, min_points: 100, max_distance_px: 160.0, clearance_px: 4, max_shift_m: 0.1 }
    }
}

/// A tube's local ground: the plane moved to the terrain's median height beside it.
#[derive(Clone, Copy, Debug)]
pub struct LocalGround {
    /// The moved plane (camera frame).
    pub plane: GroundPlane,
    /// Height of the terrain above the given plane, metres (`plane.offset - given.offset`).
    pub shift_m: f64,
    /// Terrain points the median was taken over.
    pub points: usize,
    /// Spread of their heights about the median: 1.4826 × the median absolute deviation, metres.
    pub spread_m: f64,
}

/// Disparity (pixels) of the plane `ground` seen along the ray `ray` (left camera frame, any
/// length): `f B / Z` with `Z` the depth where the ray meets the plane and `fb = f B` (the
/// rectified focal length times the baseline, pixels · metres). `None` when the ray does not
/// meet the plane in front of the camera.
pub fn nominal_disparity(ground: &GroundPlane, ray: &Vector3<f64>, fb: f64) -> Option<f64> {
    let nr = ground.normal.dot(ray);
    if nr.abs() < 1e-12 {
        return None;
    }
    let t = ground.offset / nr;
    let z = t * ray.z;
    (t > 0.0 && z > 1e-6).then(|| fb / z)
}

/// The local ground of each region (see the module docs). `points` are `(x, X)`: the rectified
/// left column `x` of each match and its point `X` (left camera frame, metres), as for
/// [`crate::stereo_stage::region_points`]; `lcam` the left camera, `ground` the given plane.
pub fn local_grounds(lcam: &CameraModel, points: &[(f32, Point3<f64>)], regions: &[StereoRegion], ground: &GroundPlane, fb: f64, cfg: &LocalGroundConfig) -> Vec<Option<LocalGround>> {
    let (w, h) = (lcam.width as usize, lcam.height as usize);
    let tubes = tube_pixels(regions, w, h, cfg.clearance_px);
    // Usable terrain points: projected pixel and height above the given plane.
    let terrain: Vec<([f64; 2], f64)> = points
        .iter()
        .filter_map(|(x, p)| {
            let d = nominal_disparity(ground, &p.coords, fb)?;
            if (*x as f64) < 1.05 * d + 2.0 {
                return None;
            }
            let u = lcam.project(p)?;
            let (px, py) = ((u.x + 0.5).floor(), (u.y + 0.5).floor());
            if px < 0.0 || py < 0.0 || px >= w as f64 || py >= h as f64 || tubes.get(px as usize, py as usize) {
                return None;
            }
            Some(([u.x, u.y], ground.normal.dot(&p.coords) - ground.offset))
        })
        .collect();
    regions.iter().map(|r| local_ground_of(&r.bbox, &terrain, ground, cfg)).collect()
}

/// Every region's mask (or box) grown by `clearance` pixels, as one mask of the left image.
fn tube_pixels(regions: &[StereoRegion], w: usize, h: usize, clearance: usize) -> BinaryMask {
    let mut out = BinaryMask::new(w, h);
    for r in regions {
        match &r.mask {
            Some(m) if m.width == w && m.height == h => {
                let g = m.dilated(clearance);
                for (o, v) in out.data.iter_mut().zip(&g.data) {
                    *o |= *v;
                }
            }
            _ => {
                let [x, y, bw, bh] = r.bbox;
                let c = clearance as f64;
                let (x0, y0) = ((x - c).floor().max(0.0) as usize, (y - c).floor().max(0.0) as usize);
                let (x1, y1) = (((x + bw + c).ceil().max(0.0) as usize).min(w), ((y + bh + c).ceil().max(0.0) as usize).min(h));
                for yy in y0..y1 {
                    for xx in x0..x1 {
                        out.set(xx, yy, true);
                    }
                }
            }
        }
    }
    out
}

/// The median height (the upper one for an even count) of the `cfg.points` terrain points
/// nearest the box `[x, y, w, h]`.
fn local_ground_of(bbox: &[f64; 4], terrain: &[([f64; 2], f64)], ground: &GroundPlane, cfg: &LocalGroundConfig) -> Option<LocalGround> {
    let [x, y, bw, bh] = *bbox;
    let mut near: Vec<(f64, f64)> = terrain
        .iter()
        .filter_map(|([u, v], hgt)| {
            let dx = (x - u).max(u - (x + bw)).max(0.0);
            let dy = (y - v).max(v - (y + bh)).max(0.0);
            let d2 = dx * dx + dy * dy;
            (d2 <= cfg.max_distance_px * cfg.max_distance_px).then_some((d2, *hgt))
        })
        .collect();
    if near.len() < cfg.min_points.max(1) {
        return None;
    }
    let k = cfg.points.max(1);
    if near.len() > k {
        near.select_nth_unstable_by(k - 1, |a, b| a.0.total_cmp(&b.0));
        near.truncate(k);
    }
    let mut hs: Vec<f64> = near.iter().map(|n| n.1).collect();
    let mid = hs.len() / 2;
    let shift = *hs.select_nth_unstable_by(mid, f64::total_cmp).1;
    if !shift.is_finite() || shift.abs() > cfg.max_shift_m {
        return None;
    }
    let dev: Vec<f64> = hs.iter().map(|v| v - shift).collect();
    let spread = crate::robust::mad_scale(&dev, &mut hs)?;
    Some(LocalGround { plane: GroundPlane { normal: ground.normal, offset: ground.offset + shift }, shift_m: shift, points: dev.len(), spread_m: spread })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A camera 1 m above flat ground, looking straight down: up is `-z` in the camera frame,
    /// so the nominal ground is `-Z = -1` (`n = (0, 0, -1)`, `d = -1`).
    fn setup() -> (CameraModel, GroundPlane) {
        let cam = CameraModel { width: 640, height: 480, fx: 500.0, fy: 500.0, cx: 320.0, cy: 240.0, distortion: Default::default() };
        (cam, GroundPlane { normal: Vector3::new(0.0, 0.0, -1.0), offset: -1.0 })
    }

    fn at(cam: &CameraModel, u: f64, v: f64, z: f64) -> (f32, Point3<f64>) {
        (u as f32, Point3::new((u - cam.cx) / cam.fx * z, (v - cam.cy) / cam.fy * z, z))
    }

    #[test]
    fn nominal_disparity_is_fb_over_the_planes_depth() {
        let (_, g) = setup();
        assert!((nominal_disparity(&g, &Vector3::new(0.0, 0.0, 1.0), 100.0).unwrap() - 100.0).abs() < 1e-12);
        // A ray 45 degrees off the axis meets the plane at the same depth Z = 1.
        assert!((nominal_disparity(&g, &Vector3::new(1.0, 0.0, 1.0), 100.0).unwrap() - 100.0).abs() < 1e-12);
        assert!(nominal_disparity(&g, &Vector3::new(0.0, 0.0, -1.0), 100.0).is_none());
        assert!(nominal_disparity(&g, &Vector3::new(1.0, 0.0, 0.0), 100.0).is_none());
    }

    /// Terrain 2 cm above the nominal ground all over; a tube standing 5 cm proud in the middle
    /// (its mask), and wrong disparities (points 50 cm too far) in the columns that cannot be
    /// matched (left of `1.05 f B / Z + 2 = 107` with `f B = 100`). Both the middle tube and one
    /// at the left border, whose own columns cannot be matched, get the terrain's 2 cm.
    #[test]
    fn local_ground_is_the_terrain_beside_the_tube() {
        let (cam, g) = setup();
        let fb = 100.0;
        let mid = BinaryMask::from_fn(640, 480, |x, y| (300..360).contains(&x) && (200..220).contains(&y));
        let regions = [StereoRegion { bbox: [300.0, 200.0, 60.0, 20.0], mask: Some(mid.clone()), seed_z: None }, StereoRegion { bbox: [10.0, 100.0, 60.0, 20.0], mask: None, seed_z: None }];
        let mut pts = Vec::new();
        for v in (0..480).step_by(2) {
            for u in (0..640).step_by(2) {
                let (uf, vf) = (u as f64, v as f64);
                let z = if u < 107 {
                    1.5
                } else if mid.get(u, v) {
                    0.93
                } else {
                    0.98
                };
                pts.push(at(&cam, uf, vf, z));
            }
        }
        let out = local_grounds(&cam, &pts, &regions, &g, fb, &LocalGroundConfig::default());
        for (i, l) in out.iter().enumerate() {
            let l = l.unwrap_or_else(|| panic!("region {i}: no local ground"));
            assert!((l.shift_m - 0.02).abs() < 1e-9, "region {i}: shift {}", l.shift_m);
            assert!((l.plane.offset - (-0.98)).abs() < 1e-9 && l.plane.normal == g.normal);
            assert_eq!(l.points, 300);
            assert!(l.spread_m < 1e-9);
        }
        // Without the points of the terrain (only the unmatchable columns' and the tube's):
        // no local ground.
        let few: Vec<_> = pts.iter().copied().filter(|(x, p)| *x < 107.0 || p.z < 0.95).collect();
        assert!(local_grounds(&cam, &few, &regions, &g, fb, &LocalGroundConfig::default()).iter().all(Option::is_none));
        // A height change beyond `max_shift_m` is refused.
        let cfg = LocalGroundConfig { max_shift_m: 0.01, ..LocalGroundConfig::default() };
        assert!(local_grounds(&cam, &pts, &regions, &g, fb, &cfg).iter().all(Option::is_none));
    }

    /// The nearest points win: terrain 3 cm up within 20 px of the box, 1 cm down farther out.
    #[test]
    fn local_ground_takes_the_nearest_terrain() {
        let (cam, g) = setup();
        let region = StereoRegion { bbox: [300.0, 200.0, 40.0, 20.0], mask: None, seed_z: None };
        let mut pts = Vec::new();
        for v in 0..480 {
            for u in 107..640 {
                let (uf, vf) = (u as f64, v as f64);
                let near = (280.0..=360.0).contains(&uf) && (180.0..=240.0).contains(&vf);
                pts.push(at(&cam, uf, vf, if near { 0.97 } else { 1.01 }));
            }
        }
        let l = local_grounds(&cam, &pts, &[region], &g, 100.0, &LocalGroundConfig::default())[0].expect("local ground");
        assert!((l.shift_m - 0.03).abs() < 1e-9, "shift {}", l.shift_m);
    }
}
