//! The ground as a plane in the camera frame, and its one command-line form.
//!
//! Sign convention (the only one in tubeloc): points `X` on the ground satisfy `n · X = d`,
//! with `n` a unit normal pointing up (away from the ground, toward the sky) in the camera
//! frame (OpenCV: x right, y down, z forward) and `d` in metres. A level camera 1.5 m above
//! flat ground has `n = (0, -1, 0)` and `d = -1.5`.

use crate::error::CoreError;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use std::str::FromStr;

/// The ground plane in the camera frame: points `X` with `normal · X = offset`; `normal` is a
/// unit vector pointing up, metres.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct GroundPlane {
    /// Unit upward normal, camera frame.
    pub normal: Vector3<f64>,
    /// Signed offset, metres: `normal · X = offset` on the ground.
    pub offset: f64,
}

impl GroundPlane {
    /// The plane `n · X = d` for any non-zero finite normal `n` (pointing up) and finite `d`
    /// (metres): `n` is normalized and `d` scaled with it. Fails for a zero or non-finite `n`
    /// or a non-finite `d`.
    pub fn new(normal: Vector3<f64>, offset: f64) -> Result<Self, CoreError> {
        if normal.iter().any(|v| !v.is_finite()) || !offset.is_finite() {
            return Err(CoreError::invalid("ground", "non-finite value"));
        }
        let norm = normal.norm();
        if norm < 1e-9 {
            return Err(CoreError::invalid("ground", "the normal is zero"));
        }
        Ok(GroundPlane { normal: normal / norm, offset: offset / norm })
    }

    /// The plane through `point` (camera frame, metres) with upward normal `normal`
    /// (normalized here).
    pub fn from_point_normal(point: &Vector3<f64>, normal: &Vector3<f64>) -> Self {
        let n = normal.normalize();
        GroundPlane { normal: n, offset: n.dot(point) }
    }

    /// Signed height of `point` (camera frame, metres) above the plane, metres.
    pub fn height_of(&self, point: &Vector3<f64>) -> f64 {
        self.normal.dot(point) - self.offset
    }
}

/// Parses `"nx,ny,nz,d"` (the `--ground` form): four finite numbers, a non-zero normal
/// (normalized, `d` scaled with it). Errors quote the whole argument.
impl FromStr for GroundPlane {
    type Err = CoreError;

    fn from_str(s: &str) -> Result<Self, CoreError> {
        let bad = |why: &str| CoreError::invalid("ground", format!("{s:?}: {why}; expected nx,ny,nz,d (n·X = d in the camera frame, n pointing up, metres)"));
        let parts: Vec<&str> = s.split(',').map(str::trim).collect();
        if parts.len() != 4 {
            return Err(bad(&format!("{} numbers", parts.len())));
        }
        let mut v = [0.0; 4];
        for (k, p) in parts.iter().enumerate() {
            v[k] = p.parse::<f64>().map_err(|_| bad(&format!("{p:?} is not a number")))?;
            if !v[k].is_finite() {
                return Err(bad(&format!("{p:?} is not finite")));
            }
        }
        let n = Vector3::new(v[0], v[1], v[2]);
        if n.norm() < 1e-9 {
            return Err(bad("the normal is zero"));
        }
        if v[3] >= 0.0 {
            // With n up, points of the ground below the camera have n·X < 0: d is minus the
            // camera's height. d >= 0 puts the camera on or under the ground.
            return Err(bad(&format!("d = {} puts the camera on or below the ground (with n pointing up, d is minus the camera's height above it; a plane written as n·X + d = 0 needs -d here)", v[3])));
        }
        GroundPlane::new(n, v[3]).map_err(|e| bad(&e.to_string()))
    }
}

impl std::fmt::Display for GroundPlane {
    /// `"nx,ny,nz,d"`, each number in Rust's shortest exact form (parses back to the same plane).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{},{},{},{}", self.normal.x, self.normal.y, self.normal.z, self.offset)
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_ground_above_the_camera_is_refused_with_a_hint() {
        let e = "0,-1,0,1.5".parse::<super::GroundPlane>().unwrap_err().to_string();
        assert!(e.contains("\"0,-1,0,1.5\"") && e.contains("n·X + d = 0"), "{e}");
        let g: super::GroundPlane = "0,-2,0,-3".parse().unwrap();
        assert!((g.offset + 1.5).abs() < 1e-12 && (g.normal.y + 1.0).abs() < 1e-12);
    }

    use super::*;

    #[test]
    fn parses_normalizes_and_scales_d() {
        let g: GroundPlane = "0,-2,0,-3".parse().unwrap();
        assert_eq!(g.normal, Vector3::new(0.0, -1.0, 0.0));
        assert_eq!(g.offset, -1.5);
        assert!((g.height_of(&Vector3::new(0.3, 1.5, 4.0))).abs() < 1e-12);
    }

    #[test]
    fn matches_the_former_cli_arithmetic() {
        // `tubeloc refine`'s former parser: n / |n|, d / |n|.
        let s = "0.01,-0.97,0.2,-1.234";
        let n = Vector3::new(0.01, -0.97, 0.2);
        let g: GroundPlane = s.parse().unwrap();
        assert_eq!(g.normal, n / n.norm());
        assert_eq!(g.offset, -1.234 / n.norm());
        let back: GroundPlane = g.to_string().parse().unwrap();
        assert_eq!(back.to_string().parse::<GroundPlane>().unwrap(), back);
    }

    #[test]
    fn refuses_bad_input_quoting_all_of_it() {
        for s in ["NaN,-1,0,1", "0,-1,0,inf", "0,0,0,1", "0,-1,0", "0,-1,0,1,2", "a,b,c,d", ""] {
            let e = s.parse::<GroundPlane>().unwrap_err().to_string();
            assert!(e.contains(&format!("{s:?}")), "{s}: {e}");
        }
    }
}
