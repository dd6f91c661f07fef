//! A located tube as a solid: its model's coaxial sections as parry3d cylinders placed in the
//! camera frame, and the test that two located tubes overlap.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use parry3d_f64::query;
use parry3d_f64::shape::Cylinder;
use tubeloc_core::{TubeAxisPose, TubeModel};

/// A tube's sections as cylinders in the camera frame (metres). parry3d's cylinders lie along
/// their local y axis; each `pose` maps that axis onto the tube's axis.
#[derive(Clone, Debug)]
pub struct TubeSolid {
    /// Each section: its placement (camera frame) and cylinder (half height, radius).
    pub sections: Vec<(Isometry3<f64>, Cylinder)>,
    /// Tube centre, camera frame, metres.
    pub centre: Vector3<f64>,
    /// Radius of a sphere about `centre` that holds the tube, metres.
    pub bounding_radius: f64,
}

impl TubeSolid {
    /// The solid of `model` at `pose` (sections along `pose.end_direction`, toward the seal end).
    pub fn new(model: &TubeModel, pose: &TubeAxisPose) -> Self {
        let t_cam_tube = pose.to_pose().0;
        // parry's cylinder axis (local y) onto the tube frame's z.
        let y_to_z = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::FRAC_PI_2);
        let sections = model
            .sections
            .iter()
            .map(|s| {
                let (z0, z1) = model.section_z_in_tube_frame(s);
                let local = Isometry3::from_parts(Translation3::new(0.0, 0.0, 0.5 * (z0 + z1)), y_to_z);
                (t_cam_tube * local, Cylinder::new(0.5 * (z1 - z0), s.radius))
            })
            .collect();
        let bounding_radius = (model.length / 2.0).hypot(model.max_radius());
        TubeSolid { sections, centre: pose.centre, bounding_radius }
    }

    /// Whether two tubes' solids interpenetrate by more than `tolerance` metres: whether some
    /// pair of their sections still intersects with each cylinder shrunk by half the tolerance
    /// in radius and at each end (parry's exact boolean GJK test; its penetration depths from
    /// EPA were found unreliable for cylinders crossing at their centres).
    pub fn overlaps(&self, other: &TubeSolid, tolerance: f64) -> bool {
        if (self.centre - other.centre).norm() > self.bounding_radius + other.bounding_radius {
            return false;
        }
        let shrink = |c: &Cylinder| Cylinder::new((c.half_height - tolerance / 2.0).max(1e-6), (c.radius - tolerance / 2.0).max(1e-6));
        self.sections.iter().any(|(pa, ca)| other.sections.iter().any(|(pb, cb)| query::intersection_test(pa, &shrink(ca), pb, &shrink(cb)).unwrap_or(false)))
    }
}

/// Tube-tube consistency: two located tubes whose solids interpenetrate by more than
/// `tolerance` metres cannot both be right. `tubes` are taken best first; each tube that
/// overlaps an earlier kept one is marked with that one's index. Returns, per tube, `None`
/// (kept) or `Some(index of the stronger tube it overlaps)`.
pub fn overlapping_tubes(model: &TubeModel, tubes: &[TubeAxisPose], tolerance: f64) -> Vec<Option<usize>> {
    let solids: Vec<TubeSolid> = tubes.iter().map(|t| TubeSolid::new(model, t)).collect();
    let mut verdict: Vec<Option<usize>> = vec![None; tubes.len()];
    for i in 0..tubes.len() {
        verdict[i] = (0..i).find(|&k| verdict[k].is_none() && solids[i].overlaps(&solids[k], tolerance));
    }
    verdict
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tube(centre: [f64; 3], axis: [f64; 3]) -> TubeAxisPose {
        TubeAxisPose::new(0, 1.0, Vector3::from(centre), Vector3::from(axis), 0.5).unwrap()
    }

    #[test]
    fn side_by_side_tubes_touch_and_crossing_tubes_overlap() {
        let m = TubeModel::default();
        let a = TubeSolid::new(&m, &tube([0.0, 0.0, 1.0], [1.0, 0.0, 0.0]));
        // Parallel, seal ends at opposite sides, 22 mm apart: the widest facing pair (foot
        // 10.3 mm beside seal 11.5 mm) leaves 0.2 mm.
        let b = TubeSolid::new(&m, &tube([0.0, 0.022, 1.0], [-1.0, 0.0, 0.0]));
        assert!(!a.overlaps(&b, 0.0));
        // The same 21 mm apart: seal beside body (8.55 mm) clears by 0.95 mm, foot beside seal
        // overlaps by 21.8 - 21 = 0.8 mm.
        let b = TubeSolid::new(&m, &tube([0.0, 0.021, 1.0], [-1.0, 0.0, 0.0]));
        assert!(a.overlaps(&b, 0.0) && a.overlaps(&b, 0.0007) && !a.overlaps(&b, 0.0009));
        // Parallel and alike, 10 mm apart: the seals (radius 11.5 mm) overlap by 13 mm.
        let c = TubeSolid::new(&m, &tube([0.0, 0.010, 1.0], [1.0, 0.0, 0.0]));
        assert!(a.overlaps(&c, 0.0129) && !a.overlaps(&c, 0.0131));
        // Crossing at the centre at 90 degrees (however thin, the two still cross); one lying
        // across the other 17.5 mm higher (bodies 0.4 mm apart) does not.
        let e = TubeSolid::new(&m, &tube([0.0, 0.0, 1.0], [0.0, 0.0, 1.0]));
        assert!(a.overlaps(&e, 0.003) && a.overlaps(&e, 0.015));
        let f = TubeSolid::new(&m, &tube([0.0, -0.0175, 1.0], [0.0, 0.0, 1.0]));
        assert!(!a.overlaps(&f, 0.0) && a.overlaps(&TubeSolid::new(&m, &tube([0.0, -0.0165, 1.0], [0.0, 0.0, 1.0])), 0.0));
        let verdict = overlapping_tubes(&m, &[tube([0.0, 0.0, 1.0], [1.0, 0.0, 0.0]), tube([0.0, 0.010, 1.0], [1.0, 0.0, 0.0]), tube([0.0, 0.04, 1.0], [1.0, 0.0, 0.0])], 0.003);
        assert_eq!(verdict, vec![None, Some(0), None]);
    }
}
