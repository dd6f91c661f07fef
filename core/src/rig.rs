//! `Rig`: a set of calibrated cameras with their extrinsics in a common rig frame.
//!
//! JSON form (tubeloc rig file):
//! `{"cameras": [{"name": "A", "model": {..CameraModel..}, "T_rig_cam": {..Pose..}}, ..],
//!   "stereo_pairs": [["A", "B"], ..]}`.

use crate::{camera::CameraModel, error::CoreError, pose::Pose};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// One camera of a rig: its intrinsics and the pose of the camera in the rig frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RigCamera {
    /// Unique camera name, e.g. `"L20"`.
    pub name: String,
    /// Intrinsics and distortion.
    pub model: CameraModel,
    /// Pose of the camera in the rig frame (maps camera points into the rig frame).
    #[serde(rename = "T_rig_cam")]
    pub t_rig_cam: Pose,
}

/// A multi-camera rig; `stereo_pairs` lists (left, right) camera names.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Rig {
    /// Cameras of the rig.
    pub cameras: Vec<RigCamera>,
    /// Stereo pairs as (left name, right name).
    #[serde(default)]
    pub stereo_pairs: Vec<(String, String)>,
}

impl Rig {
    /// The camera called `name`.
    pub fn camera(&self, name: &str) -> Option<&RigCamera> {
        self.cameras.iter().find(|c| c.name == name)
    }

    /// `T_left_right` of a pair of cameras by name.
    pub fn relative_pose(&self, left: &str, right: &str) -> Result<Pose, CoreError> {
        let l = self.camera(left).ok_or_else(|| CoreError::invalid("rig", format!("no camera named {left:?}")))?;
        let r = self.camera(right).ok_or_else(|| CoreError::invalid("rig", format!("no camera named {right:?}")))?;
        Ok(l.t_rig_cam.inverse() * r.t_rig_cam)
    }

    /// Distance between the optical centres of two cameras (metres).
    pub fn baseline(&self, left: &str, right: &str) -> Result<f64, CoreError> {
        Ok(self.relative_pose(left, right)?.translation().norm())
    }

    /// Checks camera names are unique, intrinsics valid and pairs refer to known cameras.
    pub fn validate(&self) -> Result<(), CoreError> {
        if self.cameras.is_empty() {
            return Err(CoreError::invalid("rig", "no cameras"));
        }
        for (i, c) in self.cameras.iter().enumerate() {
            c.model.validate().map_err(|e| CoreError::invalid(format!("cameras[{i}] ({})", c.name), e.to_string()))?;
            if self.cameras[..i].iter().any(|o| o.name == c.name) {
                return Err(CoreError::invalid("rig", format!("camera name {:?} appears twice", c.name)));
            }
        }
        for (l, r) in &self.stereo_pairs {
            self.relative_pose(l, r)?;
        }
        Ok(())
    }

    /// Reads and validates a rig JSON file; errors name the file.
    pub fn load_json(path: &Path) -> Result<Rig, CoreError> {
        let text = std::fs::read(path).map_err(|e| CoreError::io(path, e))?;
        Self::from_json_text(&text, path)
    }

    /// Parses and validates rig JSON text; `origin` names the source in errors.
    pub fn from_json_text(text: &[u8], origin: &Path) -> Result<Rig, CoreError> {
        let rig: Rig = crate::files::parse_json(text, origin)?;
        rig.validate().map_err(|e| CoreError::parse(origin, e.to_string()))?;
        Ok(rig)
    }

    /// Writes the rig as JSON, atomically.
    pub fn save_json(&self, path: &Path) -> Result<(), CoreError> {
        crate::files::write_json(path, self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Rotation3, Vector3};

    #[test]
    fn baseline_and_json_round_trip() {
        let model = CameraModel::from_hfov(640, 480, 77.0);
        let rig = Rig {
            cameras: vec![RigCamera { name: "L".into(), model: model.clone(), t_rig_cam: Pose::identity() }, RigCamera { name: "R".into(), model, t_rig_cam: Pose::from_parts(Rotation3::identity(), Vector3::new(0.2, 0.0, 0.0)) }],
            stereo_pairs: vec![("L".into(), "R".into())],
        };
        assert!((rig.baseline("L", "R").unwrap() - 0.2).abs() < 1e-12);
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("rig.json");
        rig.save_json(&p).unwrap();
        assert_eq!(Rig::load_json(&p).unwrap().cameras.len(), 2);
        let mut bad = rig.clone();
        bad.stereo_pairs.push(("L".into(), "X".into()));
        bad.save_json(&p).unwrap();
        let err = Rig::load_json(&p).unwrap_err().to_string();
        assert!(err.contains("rig.json") && err.contains("\"X\""), "{err}");
    }
}
