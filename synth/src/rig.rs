//! The paper's camera rig and capture stops.
//!
//! Four cameras (5472×3648, 77° horizontal field of view) on a horizontal bar form two stereo
//! pairs with baselines 20 cm (`L20`, `R20`) and 40 cm (`L40`, `R40`). The rig frame is an
//! OpenCV camera frame at the bar centre (x right, y down, z forward); all cameras share its
//! orientation and sit at `x = ±0.10` and `x = ±0.20` m. The tripod stands at one of `n` stops
//! on a circle around the scene centre, at 1 m or 2 m, and the rig looks at the centre.

use nalgebra::{Point3, Rotation3, Vector3};
use tubeloc_core::{CameraModel, CoreError, Pose, Rig, RigCamera};

/// Native image width of the paper's cameras, pixels.
pub const NATIVE_WIDTH: u32 = 5472;
/// Native image height, pixels.
pub const NATIVE_HEIGHT: u32 = 3648;
/// Horizontal field of view, degrees.
pub const HFOV_DEG: f64 = 77.0;
/// Radius of the circle of tripod stops, metres.
pub const STOP_RADIUS_M: f64 = 1.8;
/// Tripod heights, metres (HazCam-like and NavCam-like).
pub const HEIGHTS_M: [f64; 2] = [1.0, 2.0];

/// The four-camera rig of the paper at native resolution.
pub fn paper_rig() -> Rig {
    let model = CameraModel::from_hfov(NATIVE_WIDTH, NATIVE_HEIGHT, HFOV_DEG);
    let cam = |name: &str, x: f64| RigCamera { name: name.into(), model: model.clone(), t_rig_cam: Pose::from_parts(Rotation3::identity(), Vector3::new(x, 0.0, 0.0)) };
    Rig { cameras: vec![cam("L40", -0.20), cam("L20", -0.10), cam("R20", 0.10), cam("R40", 0.20)], stereo_pairs: vec![("L20".into(), "R20".into()), ("L40".into(), "R40".into())] }
}

/// `T_world_rig` of the tripod at stop `stop` of `n_stops` (angle `2π·stop/n + offset`), at
/// `height` metres above the ground level `ground_z`, on a circle of `radius` metres around
/// `centre`, looking at the centre on the ground.
pub fn stop_pose(centre: &Point3<f64>, radius: f64, height: f64, stop: usize, n_stops: usize, offset_rad: f64) -> Result<Pose, CoreError> {
    let a = 2.0 * std::f64::consts::PI * stop as f64 / n_stops.max(1) as f64 + offset_rad;
    let eye = Point3::new(centre.x + radius * a.cos(), centre.y + radius * a.sin(), centre.z + height);
    Pose::look_at(&eye, centre, &Vector3::z())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rig_has_paper_baselines_and_fov() {
        let rig = paper_rig();
        rig.validate().unwrap();
        assert!((rig.baseline("L20", "R20").unwrap() - 0.20).abs() < 1e-12);
        assert!((rig.baseline("L40", "R40").unwrap() - 0.40).abs() < 1e-12);
        assert!((rig.cameras[0].model.hfov_deg() - 77.0).abs() < 1e-9);
        let p = stop_pose(&Point3::origin(), 1.8, 1.0, 3, 8, 0.0).unwrap();
        let c = p.inverse().transform_point(&Point3::origin());
        assert!(c.x.abs() < 1e-9 && c.y.abs() < 1e-9 && (c.z - (1.8f64 * 1.8 + 1.0).sqrt()).abs() < 1e-9);
    }
}
