//! One pose per physical tube: several detections of one tube (Line2D fires more than once on
//! a tube) converge to the same refined pose, and the arm planner wants each tube once.

use tubeloc_core::{TubeAxisPose, TubeModel};

/// Drops converged poses that describe a tube already located with a higher score: the centre
/// lies within one tube radius of the kept pose's axis segment and the axes agree within 15°
/// (several detections of one tube converge to the same pose). `poses` must be sorted best
/// first; returns how many were dropped.
pub fn merge_duplicates(poses: &mut Vec<TubeAxisPose>, tube: &TubeModel) -> usize {
    let (half, radius) = (tube.length / 2.0, tube.max_radius());
    let mut kept: Vec<TubeAxisPose> = Vec::with_capacity(poses.len());
    let before = poses.len();
    for p in poses.drain(..) {
        let dup = p.converged
            && kept.iter().filter(|k| k.converged).any(|k| {
                let d = p.centre - k.centre;
                let along = d.dot(&k.axis).clamp(-half, half);
                (d - k.axis * along).norm() < radius && tubeloc_core::tube_pose::axis_angle(&p.axis, &k.axis) < 15f64.to_radians()
            });
        if !dup {
            kept.push(p);
        }
    }
    *poses = kept;
    before - poses.len()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn pose(score: f64, centre: [f64; 3], axis: [f64; 3]) -> TubeAxisPose {
        TubeAxisPose::new(0, score, Vector3::from(centre), Vector3::from(axis), 0.5).unwrap()
    }

    #[test]
    fn repeats_of_one_tube_merge_and_distinct_tubes_stay() {
        let tube = TubeModel::default();
        let mut poses = vec![
            pose(0.9, [0.0, 0.0, 2.0], [1.0, 0.0, 0.0]),
            // Same tube: 30 mm along its axis, 2 mm off it, 3 deg turned, flipped.
            pose(0.8, [0.03, 0.002, 2.0], [-1.0, 0.05, 0.0]),
            // Side by side, 40 mm away across the axis: another tube.
            pose(0.7, [0.0, 0.04, 2.0], [1.0, 0.0, 0.0]),
            // Crossing the first one at 90 deg: another tube.
            pose(0.6, [0.0, 0.0, 2.0], [0.0, 1.0, 0.0]),
        ];
        let mut failed = pose(0.5, [0.0, 0.0, 2.0], [1.0, 0.0, 0.0]);
        failed.converged = false;
        poses.push(failed);
        assert_eq!(merge_duplicates(&mut poses, &tube), 1);
        let scores: Vec<f64> = poses.iter().map(|p| p.score).collect();
        assert_eq!(scores, vec![0.9, 0.7, 0.6, 0.5], "failed fits are kept, not merged");
    }
}
