//! Ground consistency of template matches: a tube lies on the ground, so where the ground is
//! known a match is kept only when its template's distance agrees with the ground's distance
//! along the ray of the match's centre.
//!
//! A template was rendered with the tube centre at distance `d_t` on the optical axis (times
//! the far search's factor, [`crate::line2d::MatchParams::far_scale`]). Placed at pixel `p`,
//! the centre's unit ray is `r = unproject(p)`; a tube lying on the plane `n · X = d` (`n` up,
//! camera frame) has its centre at height `ρ` (the tube model's body radius) above it, so the
//! ray meets the centre's plane at
//!
//! `t_g = (d + ρ) / (n · r)`  (only when `t_g > 0`: the ray descends to the ground).
//!
//! The match is consistent when `q_min ≤ d_t / t_g ≤ q_max`. A ray that never reaches the
//! ground (the sky, the horizon) admits no tube.

use serde::{Deserialize, Serialize};
use tubeloc_core::{GroundPlane, TubeModel};

/// Bounds on the ratio `q = d_t / t_g` of a match's template distance to the ground's distance
/// along its centre's ray (dimensionless).
///
/// Defaults `[0.55, 1.25]`: on the real validation composites (PDS ground of the grey frames,
/// the assumed mast view of the colour ones) every true detection of the default library has
/// `q` in `[0.62, 1.09]` (median 0.85: the re-ranking's area bonus prefers the nearer, larger
/// template); the bounds add about 10 percent on each side (design record 0054).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct GroundRange {
    /// Smallest admitted ratio `d_t / t_g`.
    pub min_ratio: f64,
    /// Largest admitted ratio `d_t / t_g`.
    pub max_ratio: f64,
    /// Height `ρ` of a lying tube's centre above the ground, metres: the body radius of the
    /// default tube model ([`TubeModel::body_radius`], `data/tube.toml`: 8.55 mm).
    pub centre_height_m: f64,
}

impl Default for GroundRange {
    fn default() -> Self {
        GroundRange { min_ratio: 0.55, max_ratio: 1.25, centre_height_m: TubeModel::default().body_radius() }
    }
}

impl GroundRange {
    /// Bounds `[min_ratio, max_ratio]`; both finite, `0 < min_ratio <= max_ratio`; the default
    /// tube's centre height.
    pub fn new(min_ratio: f64, max_ratio: f64) -> Result<Self, crate::line2d::Line2dError> {
        if !(min_ratio.is_finite() && max_ratio.is_finite() && min_ratio > 0.0 && min_ratio <= max_ratio) {
            return Err(crate::line2d::Line2dError::invalid("ground range", format!("ratios {min_ratio}:{max_ratio} must be finite with 0 < min <= max")));
        }
        Ok(GroundRange { min_ratio, max_ratio, ..GroundRange::default() })
    }

    /// Whether a tube centre at `distance` metres along the unit ray `ray` (camera frame) is
    /// consistent with lying on `ground`: `min_ratio ≤ distance / t_g ≤ max_ratio` with
    /// [`ground_distance`] `t_g`; false when the ray does not reach the ground.
    pub fn admits(&self, ground: &GroundPlane, ray: &nalgebra::Vector3<f64>, distance: f64) -> bool {
        match ground_distance(ground, ray, self.centre_height_m) {
            Some(t) => {
                let q = distance / t;
                q >= self.min_ratio && q <= self.max_ratio
            }
            None => false,
        }
    }
}

/// Distance along the unit ray `ray` (camera frame) at which it meets the plane of a lying
/// tube's centres, `centre_height_m` (`ρ`) above `ground`: `t_g = (d + ρ) / (n · r)`, metres;
/// `None` when the ray does not descend to it (`t_g` not positive and finite).
pub fn ground_distance(ground: &GroundPlane, ray: &nalgebra::Vector3<f64>, centre_height_m: f64) -> Option<f64> {
    let t = (ground.offset + centre_height_m) / ground.normal.dot(ray);
    (t.is_finite() && t > 0.0).then_some(t)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    /// A camera 1.9 m above level ground, looking 30 degrees down (x right, y down, z forward).
    fn mast_ground() -> GroundPlane {
        let p = 30f64.to_radians();
        GroundPlane::new(Vector3::new(0.0, -p.cos(), -p.sin()), -1.9).unwrap()
    }

    #[test]
    fn the_optical_axis_meets_the_ground_at_its_slant_range() {
        // Down the optical axis, 30 degrees below level from 1.9 m: the centres' plane is
        // (1.9 - ρ) / sin 30° away.
        let t = ground_distance(&mast_ground(), &Vector3::z(), 0.00855).unwrap();
        assert!((t - (1.9 - 0.00855) / 0.5).abs() < 1e-12, "{t}");
        assert_eq!(GroundRange::default().centre_height_m, 0.00855, "the default tube's body radius");
    }

    #[test]
    fn a_ray_above_the_horizon_admits_no_tube() {
        // 40 degrees above the optical axis is 10 degrees above level.
        let a = 40f64.to_radians();
        let up = Vector3::new(0.0, -a.sin(), a.cos());
        assert_eq!(ground_distance(&mast_ground(), &up, 0.00855), None);
        assert!(!GroundRange::default().admits(&mast_ground(), &up, 3.0));
    }

    #[test]
    fn the_ratio_bounds_are_inclusive_and_checked() {
        let g = mast_ground();
        let r = GroundRange::default();
        let t = ground_distance(&g, &Vector3::z(), r.centre_height_m).unwrap();
        assert!(r.admits(&g, &Vector3::z(), t));
        assert!(r.admits(&g, &Vector3::z(), 0.55 * t * (1.0 + 1e-12)));
        assert!(!r.admits(&g, &Vector3::z(), 0.5 * t));
        assert!(!r.admits(&g, &Vector3::z(), 1.3 * t));
        let e = GroundRange::new(1.2, 0.8).unwrap_err().to_string();
        assert!(e.contains("ground range") && e.contains("1.2:0.8"), "{e}");
        assert!(GroundRange::new(0.0, 1.0).is_err());
        assert!(GroundRange::new(0.5, f64::INFINITY).is_err());
    }
}
