//! The tag mount: tags rigidly attached to a tube, read from `data/tag_mount.toml`.
//!
//! Tag frame (AprilTag convention): origin at the tag centre, x right and y down as printed,
//! z into the tag; `size_m` is the edge of the black square. Each tag's pose in the tube frame
//! is `T_tube_tag` (rotation row-major, translation in metres).

use crate::detect::TagFamily;
use crate::error::CalibError;
use nalgebra::{Matrix3, Point3, Vector3};
use serde::Deserialize;
use std::path::Path;
use tubeloc_core::Pose;

/// One mounted tag.
#[derive(Clone, Debug, PartialEq)]
pub struct MountedTag {
    /// Tag id.
    pub id: u32,
    /// Edge of the black square, metres.
    pub size_m: f64,
    /// Pose of the tag in the tube frame.
    pub t_tube_tag: Pose,
}

impl MountedTag {
    /// Corners in the tube frame, in the detector's order.
    pub fn corners_tube(&self) -> [Point3<f64>; 4] {
        tag_corners(self.size_m).map(|p| self.t_tube_tag.transform_point(&p))
    }
}

/// Corners of a tag of edge `size_m` in its own frame, detector order:
/// `(-s/2, s/2, 0), (s/2, s/2, 0), (s/2, -s/2, 0), (-s/2, -s/2, 0)`.
pub fn tag_corners(size_m: f64) -> [Point3<f64>; 4] {
    let s = size_m / 2.0;
    [Point3::new(-s, s, 0.0), Point3::new(s, s, 0.0), Point3::new(s, -s, 0.0), Point3::new(-s, -s, 0.0)]
}

/// A tag mount.
#[derive(Clone, Debug, PartialEq)]
pub struct TagMount {
    /// Family of the tags.
    pub family: TagFamily,
    /// The tags (distinct ids).
    pub tags: Vec<MountedTag>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct MountToml {
    family: Option<String>,
    tags: Vec<TagToml>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TagToml {
    id: u32,
    size_m: f64,
    rotation: [[f64; 3]; 3],
    translation_m: [f64; 3],
}

impl TagMount {
    /// The tag with this id.
    pub fn tag(&self, id: u32) -> Option<&MountedTag> {
        self.tags.iter().find(|t| t.id == id)
    }

    /// Parses the TOML text; `path` only names the source in errors.
    pub fn from_toml(text: &str, path: &Path) -> Result<Self, CalibError> {
        let m: MountToml = toml::from_str(text).map_err(|e| CalibError::parse(path, e.to_string()))?;
        let family = TagFamily::from_name(m.family.as_deref().unwrap_or("tag36h11")).map_err(|e| CalibError::parse(path, format!("family: {e}")))?;
        if m.tags.is_empty() {
            return Err(CalibError::parse(path, "tags: at least one tag is needed"));
        }
        let mut tags = Vec::new();
        for (i, t) in m.tags.iter().enumerate() {
            if !(t.size_m > 0.0 && t.size_m.is_finite()) {
                return Err(CalibError::parse(path, format!("tags[{i}].size_m must be positive, got {}", t.size_m)));
            }
            if tags.iter().any(|o: &MountedTag| o.id == t.id) {
                return Err(CalibError::parse(path, format!("tags[{i}].id {} appears twice", t.id)));
            }
            let r = Matrix3::from_fn(|a, b| t.rotation[a][b]);
            let pose = Pose::try_from_matrix(&r, Vector3::from(t.translation_m)).map_err(|e| CalibError::parse(path, format!("tags[{i}].rotation: {e}")))?;
            tags.push(MountedTag { id: t.id, size_m: t.size_m, t_tube_tag: pose });
        }
        Ok(TagMount { family, tags })
    }

    /// Reads a mount file.
    pub fn load(path: &Path) -> Result<Self, CalibError> {
        let text = std::fs::read_to_string(path).map_err(|e| tubeloc_core::CoreError::io(path, e))?;
        Self::from_toml(&text, path)
    }

    /// The shipped mount, `data/tag_mount.toml`.
    pub fn default_mount() -> Self {
        Self::from_toml(DEFAULT_MOUNT_TOML, Path::new("data/tag_mount.toml")).expect("data/tag_mount.toml is valid (checked by tests)")
    }
}

/// Text of `data/tag_mount.toml`.
pub const DEFAULT_MOUNT_TOML: &str = include_str!("../../data/tag_mount.toml");
