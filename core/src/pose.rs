//! `Pose`: a rigid transform in SE(3) (rotation + translation in metres).
//!
//! A pose named `T_a_b` maps points of frame `b` into frame `a`: `p_a = T_a_b * p_b`.
//! Composition follows the names: `T_a_c = T_a_b * T_b_c`.
//!
//! JSON form: `{"rotation": [[r00, r01, r02], [r10, ..], [r20, ..]], "translation": [x, y, z]}`,
//! rotation row-major. On reading, the matrix is checked to be a rotation (orthonormal,
//! determinant +1, to 1e-6) and re-orthonormalized.

use crate::error::CoreError;
use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// A rigid transform in SE(3) on nalgebra's `Isometry3<f64>`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose(pub Isometry3<f64>);

impl Default for Pose {
    fn default() -> Self {
        Pose::identity()
    }
}

impl Pose {
    /// The identity transform.
    pub fn identity() -> Self {
        Pose(Isometry3::identity())
    }

    /// A pose from a rotation and a translation (metres).
    pub fn from_parts(rotation: Rotation3<f64>, translation: Vector3<f64>) -> Self {
        Pose(Isometry3::from_parts(Translation3::from(translation), UnitQuaternion::from_rotation_matrix(&rotation)))
    }

    /// A pose from a 3x3 matrix that must be a rotation (orthonormal, det +1 within `1e-6`).
    pub fn try_from_matrix(r: &Matrix3<f64>, t: Vector3<f64>) -> Result<Self, CoreError> {
        if r.iter().chain(t.iter()).any(|v| !v.is_finite()) {
            return Err(CoreError::invalid("pose", "non-finite value"));
        }
        let orth = (r.transpose() * r - Matrix3::identity()).abs().max();
        if orth > 1e-6 || (r.determinant() - 1.0).abs() > 1e-6 {
            return Err(CoreError::invalid("pose", format!("rotation is not orthonormal with det +1 (error {orth:.2e}, det {:.6})", r.determinant())));
        }
        // Iterate to machine precision (an update below 1e-15 rad): a rotation read back from
        // a file is then the written one to ~1e-16, not 1e-12.
        let rot = Rotation3::from_matrix_eps(r, 1e-15, 100, Rotation3::identity());
        Ok(Pose::from_parts(rot, t))
    }

    /// Rotation matrix part.
    pub fn rotation(&self) -> Matrix3<f64> {
        self.0.rotation.to_rotation_matrix().into_inner()
    }

    /// Translation part (metres).
    pub fn translation(&self) -> Vector3<f64> {
        self.0.translation.vector
    }

    /// The inverse transform: `T_b_a` from `T_a_b`.
    pub fn inverse(&self) -> Pose {
        Pose(self.0.inverse())
    }

    /// Composition `self * other` (`T_a_b * T_b_c = T_a_c`).
    pub fn compose(&self, other: &Pose) -> Pose {
        Pose(self.0 * other.0)
    }

    /// Maps a point of the source frame into the target frame.
    pub fn transform_point(&self, p: &Point3<f64>) -> Point3<f64> {
        self.0.transform_point(p)
    }

    /// Rotates a direction (no translation).
    pub fn transform_vector(&self, v: &Vector3<f64>) -> Vector3<f64> {
        self.0.transform_vector(v)
    }

    /// `T_world_cam` of an OpenCV camera at `eye` looking at `target`, with image "up" as close
    /// as possible to `up` (camera y points down, so camera -y is aligned with `up`).
    /// Fails when `eye == target` or the view direction is parallel to `up`.
    pub fn look_at(eye: &Point3<f64>, target: &Point3<f64>, up: &Vector3<f64>) -> Result<Pose, CoreError> {
        let z = target - eye;
        if z.norm() < 1e-12 {
            return Err(CoreError::invalid("look_at", "eye and target coincide"));
        }
        let z = z.normalize();
        let x = z.cross(up);
        if x.norm() < 1e-9 {
            return Err(CoreError::invalid("look_at", "view direction is parallel to up"));
        }
        let x = x.normalize();
        let y = z.cross(&x);
        let r = Matrix3::from_columns(&[x, y, z]);
        Ok(Pose::from_parts(Rotation3::from_matrix_unchecked(r), eye.coords))
    }

    /// Rotation angle (radians) and translation distance (metres) between two poses.
    pub fn distance(&self, other: &Pose) -> (f64, f64) {
        let d = self.inverse().compose(other);
        (d.0.rotation.angle(), (self.translation() - other.translation()).norm())
    }
}

impl std::ops::Mul for Pose {
    type Output = Pose;
    fn mul(self, rhs: Pose) -> Pose {
        self.compose(&rhs)
    }
}

#[derive(Serialize, Deserialize)]
struct PoseJson {
    rotation: [[f64; 3]; 3],
    translation: [f64; 3],
}

impl Serialize for Pose {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let r = self.rotation();
        let t = self.translation();
        PoseJson { rotation: [[r[(0, 0)], r[(0, 1)], r[(0, 2)]], [r[(1, 0)], r[(1, 1)], r[(1, 2)]], [r[(2, 0)], r[(2, 1)], r[(2, 2)]]], translation: [t.x, t.y, t.z] }.serialize(s)
    }
}

impl<'de> Deserialize<'de> for Pose {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let j = PoseJson::deserialize(d)?;
        let r = Matrix3::from_fn(|i, k| j.rotation[i][k]);
        let t = Vector3::from(j.translation);
        Pose::try_from_matrix(&r, t).map_err(serde::de::Error::custom)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Pose {
        Pose::from_parts(Rotation3::from_euler_angles(0.3, -0.8, 2.0), Vector3::new(0.4, -1.2, 3.0))
    }

    #[test]
    fn compose_with_inverse_is_identity() {
        let p = sample();
        let (a, d) = (p * p.inverse()).distance(&Pose::identity());
        assert!(a < 1e-12 && d < 1e-12);
        let q = Pose::from_parts(Rotation3::from_euler_angles(-1.0, 0.2, 0.1), Vector3::new(1.0, 0.0, -2.0));
        let x = Point3::new(0.1, 0.2, 0.3);
        let lhs = (p * q).transform_point(&x);
        let rhs = p.transform_point(&q.transform_point(&x));
        assert!((lhs - rhs).norm() < 1e-12);
    }

    #[test]
    fn json_round_trip_and_rejects_non_rotation() {
        let p = sample();
        let text = serde_json::to_string(&p).unwrap();
        let back: Pose = serde_json::from_str(&text).unwrap();
        let (a, d) = p.distance(&back);
        assert!(a < 1e-12 && d < 1e-12);
        // Written and read again, the rotation matrix is the same to rounding.
        let again: Pose = serde_json::from_str(&serde_json::to_string(&back).unwrap()).unwrap();
        assert!((again.rotation() - back.rotation()).abs().max() < 1e-15, "{}", (again.rotation() - back.rotation()).abs().max());
        let bad = r#"{"rotation": [[2,0,0],[0,1,0],[0,0,1]], "translation": [0,0,0]}"#;
        let err = serde_json::from_str::<Pose>(bad).unwrap_err().to_string();
        assert!(err.contains("orthonormal"), "{err}");
        let reflect = r#"{"rotation": [[-1,0,0],[0,1,0],[0,0,1]], "translation": [0,0,0]}"#;
        assert!(serde_json::from_str::<Pose>(reflect).is_err());
    }

    #[test]
    fn look_at_points_optical_axis_at_target() {
        let eye = Point3::new(2.0, 0.0, 1.0);
        let target = Point3::new(0.0, 0.0, 0.0);
        let t_world_cam = Pose::look_at(&eye, &target, &Vector3::z()).unwrap();
        let t_cam_world = t_world_cam.inverse();
        let pc = t_cam_world.transform_point(&target);
        assert!(pc.x.abs() < 1e-12 && pc.y.abs() < 1e-12 && pc.z > 0.0);
        // A point above the target appears higher in the image (smaller y).
        let above = t_cam_world.transform_point(&Point3::new(0.0, 0.0, 0.5));
        assert!(above.y < 0.0);
        assert!(Pose::look_at(&eye, &eye, &Vector3::z()).is_err());
    }
}
