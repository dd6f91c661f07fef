//! The gripper: two fingers and a palm as boxes in the grasp frame, read from `data/gripper.toml`.
//!
//! Grasp frame: origin on the tube axis, +x along the axis, +z the approach direction (toward
//! the tube), +y the direction in which the fingers close; metres. The fingers stand at
//! `y = ±(opening/2 + thickness/2)` with their tips `tip_depth` past the axis along +z; the palm
//! lies on top of them, spanning both.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use parry3d_f64::shape::Cuboid;
use serde::{Deserialize, Serialize};
use std::path::Path;
use tubeloc_core::CoreError;

/// The default gripper text, embedded from `data/gripper.toml` (nothing reads the source tree
/// at run time).
pub const DEFAULT_GRIPPER_TOML: &str = include_str!("../../data/gripper.toml");

/// One finger's box, metres.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FingerSize {
    /// Size along the tube axis (grasp x), metres.
    pub width: f64,
    /// Size along the closing direction (grasp y), metres.
    pub thickness: f64,
    /// Size along the approach (grasp z), tip to palm, metres.
    pub length: f64,
}

/// The palm's box, metres; across the closing direction it spans both fingers.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PalmSize {
    /// Size along the tube axis (grasp x), metres.
    pub width: f64,
    /// Size along the approach (grasp z), metres.
    pub thickness: f64,
}

/// How the gripper meets the tube, metres.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GraspGeometry {
    /// Gap between the fingers' inner faces while approaching (open), metres.
    pub opening: f64,
    /// How far the fingertips reach past the tube axis along the approach, metres.
    pub tip_depth: f64,
    /// Length of the last straight approach segment that must be free, metres.
    pub approach: f64,
}

/// A parallel-jaw gripper: two finger boxes and a palm box (`data/gripper.toml`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GripperModel {
    /// Model name.
    pub name: String,
    /// Each finger's size.
    pub finger: FingerSize,
    /// The palm's size.
    pub palm: PalmSize,
    /// Opening, tip depth and approach length.
    pub grasp: GraspGeometry,
}

/// A box of the gripper placed in the grasp frame: `pose` maps box coordinates (centred, axes
/// along the grasp frame's) into the grasp frame; `shape` has the half extents, metres.
#[derive(Clone, Debug)]
pub struct GripperPart {
    /// What the box is (`finger_left`, `finger_right`, `palm`).
    pub name: &'static str,
    /// Box centre in the grasp frame (the box's axes are the grasp frame's).
    pub pose: Isometry3<f64>,
    /// The box, half extents in metres.
    pub shape: Cuboid,
}

impl Default for GripperModel {
    fn default() -> Self {
        GripperModel::from_toml_str(DEFAULT_GRIPPER_TOML, Path::new("data/gripper.toml")).expect("embedded gripper model is valid")
    }
}

impl GripperModel {
    /// Parses and validates a gripper from TOML text; `origin` names the source in errors.
    /// Unknown and missing fields are refused by name.
    pub fn from_toml_str(text: &str, origin: &Path) -> Result<Self, CoreError> {
        tubeloc_core::files::parse_toml_checked(text, origin, GripperModel::validate)
    }

    /// Reads a gripper from a TOML file.
    pub fn load(path: &Path) -> Result<Self, CoreError> {
        tubeloc_core::files::read_toml_checked(path, GripperModel::validate)
    }

    /// Checks that every size is a finite positive number of metres (`tip_depth` may be 0);
    /// the error names the field (`finger.width`, ...).
    pub fn validate(&self) -> Result<(), CoreError> {
        let sizes = [
            ("finger.width", self.finger.width),
            ("finger.thickness", self.finger.thickness),
            ("finger.length", self.finger.length),
            ("palm.width", self.palm.width),
            ("palm.thickness", self.palm.thickness),
            ("grasp.opening", self.grasp.opening),
            ("grasp.approach", self.grasp.approach),
        ];
        for (field, v) in sizes {
            if !(v.is_finite() && v > 0.0) {
                return Err(CoreError::invalid(field, format!("must be a positive number of metres, got {v}")));
            }
        }
        let t = self.grasp.tip_depth;
        if !(t.is_finite() && t >= 0.0 && t < self.finger.length) {
            return Err(CoreError::invalid("grasp.tip_depth", format!("must be at least 0 and less than finger.length ({} m), got {t}", self.finger.length)));
        }
        Ok(())
    }

    /// The fingers and the palm at the grasp, in the grasp frame (fingers open).
    pub fn parts(&self) -> [GripperPart; 3] {
        self.parts_swept(0.0)
    }

    /// The fingers and the palm swept along the last `sweep` metres of the approach: each box
    /// extended toward -z (where the gripper came from) by `sweep`. A box translated along one
    /// of its own axes sweeps exactly the longer box, so this is the exact swept volume.
    pub fn parts_swept(&self, sweep: f64) -> [GripperPart; 3] {
        let f = &self.finger;
        let g = &self.grasp;
        let part = |name, centre: Vector3<f64>, half: Vector3<f64>| GripperPart {
            name,
            pose: Isometry3::from_parts(Translation3::from(centre - Vector3::z() * (sweep / 2.0)), UnitQuaternion::identity()),
            shape: Cuboid::new(half + Vector3::z() * (sweep / 2.0)),
        };
        let y = g.opening / 2.0 + f.thickness / 2.0;
        let fz = g.tip_depth - f.length / 2.0;
        let finger_half = Vector3::new(f.width / 2.0, f.thickness / 2.0, f.length / 2.0);
        let palm_z = g.tip_depth - f.length - self.palm.thickness / 2.0;
        [
            part("finger_left", Vector3::new(0.0, -y, fz), finger_half),
            part("finger_right", Vector3::new(0.0, y, fz), finger_half),
            part("palm", Vector3::new(0.0, 0.0, palm_z), Vector3::new(self.palm.width / 2.0, g.opening / 2.0 + f.thickness, self.palm.thickness / 2.0)),
        ]
    }

    /// Radius of a sphere about the grasp origin that holds the whole gripper (not swept),
    /// metres.
    pub fn reach(&self) -> f64 {
        self.parts().iter().map(|p| p.pose.translation.vector.norm() + p.shape.half_extents.norm()).fold(0.0, f64::max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_parts_sit_where_the_file_says() {
        let g = GripperModel::default();
        let [l, r, palm] = g.parts();
        // Finger inner faces 20 mm either side of the axis, tips 3 mm past it.
        assert!((r.pose.translation.y - r.shape.half_extents.y - 0.020).abs() < 1e-12);
        assert!((l.pose.translation.y + l.shape.half_extents.y + 0.020).abs() < 1e-12);
        assert!((r.pose.translation.z + r.shape.half_extents.z - 0.003).abs() < 1e-12);
        // Palm on top of the fingers.
        assert!((palm.pose.translation.z + palm.shape.half_extents.z - (r.pose.translation.z - r.shape.half_extents.z)).abs() < 1e-12);
        // Swept: same tip, top raised by the sweep.
        let [_, rs, _] = g.parts_swept(0.05);
        assert!((rs.pose.translation.z + rs.shape.half_extents.z - 0.003).abs() < 1e-12);
        assert!((rs.pose.translation.z - rs.shape.half_extents.z - (r.pose.translation.z - r.shape.half_extents.z - 0.05)).abs() < 1e-12);
    }
}
