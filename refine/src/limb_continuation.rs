//! Whether a fitted tube ends where the tube ends: the edges along its limbs, measured past
//! each end, against the same along its body.
//!
//! A tube is short: past its ends lies ground. A slab rim, a crack or a layer of bedrock that a
//! detector and a cylinder fit take for a tube goes on: its two straight edges continue past the
//! ends of the fitted tube. With the projected axis ends `e₀, e₁` (centre `∓ a L/2`, `L` the
//! tube's length), `ℓ = |e₁ − e₀|` px, `u = (e₁ − e₀)/ℓ`, `n = (−u_y, u_x)`, the body's width
//! `w = f_x d / z` px (`d` its diameter, `z` the centre's depth), the limb edge strength over an
//! along-axis range `[t₀, t₁)` is
//!
//! `G(t₀, t₁) = Σ_{s = ±1} max_{o ∈ w/2 + {−1.5, −1, …, 1.5}} | mean_t ( I(p + n/2) − I(p − n/2) ) |`,
//! `p = e₀ + t u + s o n`, `t = t₀, t₀ + 1, … < t₁`
//!
//! (`I` the grey levels, bilinear; the offset searched because the limb of a real tube lies
//! within a pixel or so of the fitted one). The continuation is
//!
//! `C = max_k G_k / G(0.2ℓ, 0.8ℓ)`, `G_0 = G(−0.5ℓ, −0.1ℓ)`, `G_1 = G(1.1ℓ, 1.5ℓ)`,
//!
//! over the ends whose samples lie (90 % of them) inside the image: about 0.15 for a tube on
//! ground (median on the real validation composites, 90 % of them below 0.33), 0.5 to 2 for a
//! rim. Record 0080 chose the cut `locate` applies.

use nalgebra::Point3;
use tubeloc_core::{CameraModel, Plane, TubeAxisPose, TubeModel};

/// The along-axis ranges past each end, as fractions of the projected length `ℓ`.
const PAST_ENDS: [(f64, f64); 2] = [(-0.5, -0.1), (1.1, 1.5)];
/// The body's along-axis range, as fractions of `ℓ`.
const BODY: (f64, f64) = (0.2, 0.8);
/// Share of a range's samples that must lie inside the image for it to count.
const MIN_INSIDE: f64 = 0.9;

/// The limb continuation `C` of `pose` in `gray` seen by `camera` (see the module docs), or
/// `None` where it cannot be measured: the tube's image shorter than 4 px, no edge along its
/// body, an end behind the camera, or neither end's range inside the image.
pub fn limb_continuation(gray: &Plane<u8>, camera: &CameraModel, tube: &TubeModel, pose: &TubeAxisPose) -> Option<f64> {
    let half = pose.axis * (tube.length / 2.0);
    let e0 = camera.project(&Point3::from(pose.centre - half))?;
    let e1 = camera.project(&Point3::from(pose.centre + half))?;
    let d = e1 - e0;
    let ell = d.norm();
    if ell.is_nan() || ell < 4.0 || pose.centre.z <= 0.0 {
        return None;
    }
    let u = d / ell;
    let n = [-u.y, u.x];
    let width = camera.fx * 2.0 * tube.body_radius() / pose.centre.z;
    let strength = |t0: f64, t1: f64| -> Option<f64> {
        let steps = ((t1 - t0) * ell).ceil().max(0.0) as usize;
        if steps < 2 {
            return None;
        }
        let mut total = 0.0;
        for side in [-1.0, 1.0] {
            let mut best: Option<f64> = None;
            for k in 0..=6 {
                let o = side * (width / 2.0 - 1.5 + 0.5 * k as f64);
                let (mut sum, mut inside) = (0.0, 0usize);
                for i in 0..steps {
                    let t = t0 * ell + i as f64;
                    let (x, y) = (e0.x + t * u.x + o * n[0], e0.y + t * u.y + o * n[1]);
                    if let (Some(a), Some(b)) = (grey_at(gray, x + 0.5 * n[0], y + 0.5 * n[1]), grey_at(gray, x - 0.5 * n[0], y - 0.5 * n[1])) {
                        sum += a - b;
                        inside += 1;
                    }
                }
                if (inside as f64) < MIN_INSIDE * steps as f64 {
                    return None;
                }
                let g = (sum / inside as f64).abs();
                best = Some(best.map_or(g, |b| b.max(g)));
            }
            total += best?;
        }
        Some(total)
    };
    let body = strength(BODY.0, BODY.1).filter(|&b| b > 1e-9)?;
    PAST_ENDS.iter().filter_map(|&(a, b)| strength(a, b)).map(|g| g / body).reduce(f64::max)
}

/// Bilinear grey level at `(x, y)` (pixel centres at integers), `None` outside the image.
fn grey_at(gray: &Plane<u8>, x: f64, y: f64) -> Option<f64> {
    let (w, h) = (gray.width as f64, gray.height as f64);
    if !(x >= 0.0 && y >= 0.0 && x <= w - 1.001 && y <= h - 1.001) {
        return None;
    }
    let (x0, y0) = (x.floor() as usize, y.floor() as usize);
    let (fx, fy) = (x - x0 as f64, y - y0 as f64);
    let g = |xx: usize, yy: usize| gray.get(xx, yy) as f64;
    Some((g(x0, y0) * (1.0 - fx) + g(x0 + 1, y0) * fx) * (1.0 - fy) + (g(x0, y0 + 1) * (1.0 - fx) + g(x0 + 1, y0 + 1) * fx) * fy)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    /// A camera looking straight down from 1 m: 1 px = 1 mm at the ground.
    fn camera() -> CameraModel {
        CameraModel { width: 400, height: 200, fx: 1000.0, fy: 1000.0, cx: 200.0, cy: 100.0, distortion: Default::default() }
    }

    /// A bright bar 17 px wide along x, from `x0` to `x1`, on mid-grey ground.
    fn bar(x0: usize, x1: usize) -> Plane<u8> {
        let mut p = Plane::filled(400, 200, 80u8);
        for y in 92..109 {
            for x in x0..x1 {
                *p.get_mut(x, y) = 200;
            }
        }
        p
    }

    fn tube_pose() -> TubeAxisPose {
        TubeAxisPose::new(1, 0.9, Vector3::new(0.0, 0.0, 1.0), Vector3::x(), 0.5).unwrap()
    }

    #[test]
    fn a_tube_ends_and_a_rim_goes_on() {
        let (cam, tube) = (camera(), TubeModel::default());
        // The tube is 150 px long here, centred at x = 200.
        let tube_like = limb_continuation(&bar(125, 275), &cam, &tube, &tube_pose()).unwrap();
        let rim = limb_continuation(&bar(0, 400), &cam, &tube, &tube_pose()).unwrap();
        assert!(tube_like < 0.05, "a bar that ends with the tube: {tube_like}");
        assert!((rim - 1.0).abs() < 0.05, "a bar that goes on: {rim}");
        // A bar that goes on past one end only counts by that end.
        let one_end = limb_continuation(&bar(125, 400), &cam, &tube, &tube_pose()).unwrap();
        assert!((one_end - 1.0).abs() < 0.05, "{one_end}");
    }

    #[test]
    fn nothing_is_measured_without_a_body_edge_or_inside_the_image() {
        let (cam, tube) = (camera(), TubeModel::default());
        assert_eq!(limb_continuation(&Plane::filled(400, 200, 80u8), &cam, &tube, &tube_pose()), None);
        // Both ranges past the ends fall outside a 160 px wide image.
        let narrow = CameraModel { width: 160, cx: 80.0, ..camera() };
        let mut p = Plane::filled(160, 200, 80u8);
        for y in 92..109 {
            for x in 5..155 {
                *p.get_mut(x, y) = 200;
            }
        }
        assert_eq!(limb_continuation(&p, &narrow, &tube, &tube_pose()), None);
        // A tube seen end-on is a few pixels long.
        let end_on = TubeAxisPose::new(1, 0.9, Vector3::new(0.0, 0.0, 1.0), Vector3::z(), 0.5).unwrap();
        assert_eq!(limb_continuation(&bar(125, 275), &cam, &tube, &end_on), None);
    }
}
