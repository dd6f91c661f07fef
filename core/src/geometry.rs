//! Small geometric helpers shared by the crates.

use crate::pose::Pose;
use nalgebra::Vector3;

/// The ground plane `z_world = 0` in the camera frame of a camera at pose `T_world_cam`:
/// returns `(n, d)` with `n` the unit upward normal (world +z) in camera coordinates and `d`
/// the offset such that camera-frame points `X` on the ground satisfy `n · X = d` (metres).
///
/// With `X_w = R X + t`: `z_w = (Rᵀ ẑ) · X + t_z = 0`, so `n = Rᵀ ẑ` and `d = -t_z`; the
/// camera's height above the ground is `-d`.
pub fn ground_plane_in_camera(t_world_cam: &Pose) -> (Vector3<f64>, f64) {
    ground_plane_at_height(t_world_cam, 0.0)
}

/// The horizontal ground plane `z_world = h` (metres) in the camera frame of a camera at pose
/// `T_world_cam`: `(n, d)` as in [`ground_plane_in_camera`], with `d = h - t_z`.
pub fn ground_plane_at_height(t_world_cam: &Pose, h: f64) -> (Vector3<f64>, f64) {
    let n = t_world_cam.rotation().transpose() * Vector3::z();
    let norm = n.norm();
    (n / norm, (h - t_world_cam.translation().z) / norm)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;

    #[test]
    fn ground_points_satisfy_the_plane_and_the_camera_height_is_minus_d() {
        // Camera 1.5 m above the ground looking down and forward.
        let t = Pose::look_at(&Point3::new(0.3, -0.2, 1.5), &Point3::new(1.0, 2.0, 0.0), &Vector3::z()).unwrap();
        let (n, d) = ground_plane_in_camera(&t);
        assert!((n.norm() - 1.0).abs() < 1e-12);
        assert!((d + 1.5).abs() < 1e-12, "camera height 1.5 m gives d = -1.5, got {d}");
        let t_cam_world = t.inverse();
        for p in [Point3::new(1.0, 2.0, 0.0), Point3::new(-3.0, 0.5, 0.0), Point3::new(0.0, 7.0, 0.0)] {
            let x = t_cam_world.transform_point(&p);
            assert!((n.dot(&x.coords) - d).abs() < 1e-9, "{p:?}");
        }
        // A point 0.1 m above the ground is 0.1 m along the normal.
        let x = t_cam_world.transform_point(&Point3::new(1.0, 1.0, 0.1));
        assert!((n.dot(&x.coords) - d - 0.1).abs() < 1e-9);
        // The plane z = 0.02 holds the points 2 cm up, and lies 2 cm nearer the camera.
        let (n2, d2) = ground_plane_at_height(&t, 0.02);
        assert!((n2 - n).norm() < 1e-12 && (d2 - (d + 0.02)).abs() < 1e-12);
        let x = t_cam_world.transform_point(&Point3::new(-1.0, 3.0, 0.02));
        assert!((n2.dot(&x.coords) - d2).abs() < 1e-9);
    }
}
