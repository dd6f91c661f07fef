//! Calibration interchange: the rig in the formats the rest of a robot's stack reads, and one
//! reader for every `--rig` argument.
//!
//! - tubeloc JSON ([`tubeloc_core::Rig::load_json`]) and OpenCV FileStorage YAML
//!   ([`crate::yaml`]): the whole rig, read and written.
//! - [`kalibr`]: a kalibr `camchain.yaml`, read and written (refused for cameras with `k3 != 0`).
//! - [`ros`]: ROS `camera_info` YAML, one file per camera with each stereo pair's rectification;
//!   written, and read as one camera.
//! - [`pds`]: rover cameras from their PDS camera models (`cahv_to_pinhole.py`'s JSON list),
//!   read: one camera per image, in the rover frame, with the ground under it; and
//!   [`pds_label`]: the PDS3 label of one image (its CAHV / CAHVOR model, [`cahv`], read from
//!   the label's ODL, [`odl`]), read the same way; [`detached_label`] finds the label of an
//!   image saved in another format (a raw-gallery JPEG).
//!
//! [`read_rig`] tells the formats apart by content, not by file name.

pub mod cahv;
pub mod cahvore;
pub mod detached_label;
pub mod kalibr;
pub mod linearize;
pub mod pds;
pub mod pds_label;
pub mod ros;
pub mod yaml_fields;

/// PDS3 labels (ODL), shared with the image readers: [`tubeloc_core::odl`].
pub use tubeloc_core::odl;

use crate::error::CalibError;
use std::path::Path;
use tubeloc_core::{Pose, Rig, RigCamera};

/// A rig file format recognised by [`read_rig`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RigFormat {
    /// tubeloc rig JSON (first character `{`).
    TubelocJson,
    /// OpenCV FileStorage YAML (first line `%YAML:1.0`).
    OpencvYaml,
    /// kalibr camchain (a YAML mapping with `cam0`).
    KalibrCamchain,
    /// ROS `camera_info` (a YAML mapping with `camera_matrix`): a one-camera rig.
    RosCameraInfo,
    /// A JSON list of PDS cameras (first character `[`, [`pds`]): one camera per image.
    PdsCameras,
    /// A PDS3 label (first keyword `PDS_VERSION_ID`, [`pds_label`]): a one-camera rig in the
    /// rover frame.
    Pds3Label,
}

impl RigFormat {
    /// Human name of the format, as used in error messages.
    pub fn name(self) -> &'static str {
        match self {
            RigFormat::TubelocJson => "tubeloc JSON",
            RigFormat::OpencvYaml => "OpenCV FileStorage YAML",
            RigFormat::KalibrCamchain => "kalibr camchain",
            RigFormat::RosCameraInfo => "ROS camera_info",
            RigFormat::PdsCameras => "PDS camera list",
            RigFormat::Pds3Label => "PDS3 label",
        }
    }
}

/// The format of a rig file's text, from its content: `Err` says, for each format tried, why the
/// text is not in it.
pub fn detect_rig_format(text: &str) -> Result<RigFormat, String> {
    let body = text.trim_start_matches('\u{feff}');
    let first = body.lines().map(str::trim).find(|l| !l.is_empty() && !l.starts_with('#')).unwrap_or("");
    if first.starts_with('{') {
        return Ok(RigFormat::TubelocJson);
    }
    if first.starts_with('[') {
        return Ok(RigFormat::PdsCameras);
    }
    if odl::looks_like_pds3_label(first.as_bytes()) {
        return Ok(RigFormat::Pds3Label);
    }
    if first.starts_with("%YAML:") {
        return Ok(RigFormat::OpencvYaml);
    }
    let why_yaml = match yaml_rust2::YamlLoader::load_from_str(body) {
        Ok(docs) => match docs.first() {
            Some(d) if !d["cam0"].is_badvalue() => return Ok(RigFormat::KalibrCamchain),
            Some(d) if !d["camera_matrix"].is_badvalue() => return Ok(RigFormat::RosCameraInfo),
            Some(yaml_rust2::Yaml::Hash(_)) => "a YAML mapping without `cam0` (kalibr) or `camera_matrix` (ROS)".to_string(),
            Some(_) => "YAML whose top level is not a mapping".to_string(),
            None => "empty".to_string(),
        },
        Err(e) => format!("not YAML ({e})"),
    };
    Err(format!("not a rig file in a known format; tried tubeloc JSON (does not start with `{{`), a PDS camera list (does not start with `[`), a PDS3 label (does not start with `PDS_VERSION_ID`), OpenCV FileStorage YAML (no `%YAML:1.0` first line), kalibr camchain and ROS camera_info ({why_yaml})"))
}

/// Whether tubeloc JSON `text` is one camera model (an object with `fx` and no `cameras`).
fn is_camera_json(text: &str) -> bool {
    serde_json::from_str::<serde_json::Value>(text).is_ok_and(|v| v.get("fx").is_some() && v.get("cameras").is_none())
}

/// Reads a camera model for a `--camera` argument: tubeloc camera JSON
/// ([`tubeloc_core::CameraModel::load_json`]) or a PDS3 label (`.LBL`, or an `.IMG` with its
/// label: the linearized CAHV / CAHVOR pinhole, [`pds_label`]), recognised by content.
pub fn read_camera(path: &Path) -> Result<tubeloc_core::CameraModel, CalibError> {
    match pds_label::read_label_camera(path)? {
        Some(c) => Ok(c.camera.model),
        None => Ok(tubeloc_core::CameraModel::load_json(path)?),
    }
}

/// Reads a rig from tubeloc JSON (a rig, or one camera model: a one-camera rig, the camera
/// named `camera` at the rig origin), OpenCV FileStorage YAML, a kalibr camchain, or a single
/// ROS `camera_info` file (a one-camera rig with the camera at the rig origin), a PDS camera list
/// (one camera per image, in the rover frame; [`pds`]), or a PDS3 label (its camera, in the
/// rover frame; [`pds_label`]), recognised by content. Errors name the file, and the field
/// where one is wrong.
pub fn read_rig(path: &Path) -> Result<Rig, CalibError> {
    let bytes = std::fs::read(path).map_err(|e| tubeloc_core::CoreError::io(path, e))?;
    if odl::looks_like_pds3_label(&bytes) {
        // Read as bytes: an `.IMG` carries its image after the label.
        return Ok(pds::rig_of(&[pds_label::label_camera(&bytes, path)?]));
    }
    let text = String::from_utf8(bytes).map_err(|_| CalibError::parse(path, "neither UTF-8 text nor a PDS3 label"))?;
    match detect_rig_format(&text).map_err(|m| CalibError::parse(path, m))? {
        // A single camera (`tubeloc calib` output, `--camera` files): a one-camera rig.
        RigFormat::TubelocJson if is_camera_json(&text) => {
            let model = tubeloc_core::CameraModel::from_json_text(text.as_bytes(), path)?;
            Ok(Rig { cameras: vec![RigCamera { name: "camera".into(), model, t_rig_cam: Pose::identity() }], stereo_pairs: Vec::new() })
        }
        RigFormat::TubelocJson => Ok(Rig::from_json_text(text.as_bytes(), path)?),
        RigFormat::OpencvYaml => crate::yaml::rig_from_yaml(&text, path),
        RigFormat::KalibrCamchain => kalibr::rig_from_camchain(&text, path),
        RigFormat::PdsCameras => pds::rig_from_pds(&text, path),
        RigFormat::Pds3Label => Ok(pds::rig_of(&[pds_label::label_camera(text.as_bytes(), path)?])),
        RigFormat::RosCameraInfo => {
            let info = ros::CameraInfo::from_yaml(&text, path)?;
            let name = if info.name.is_empty() { "camera".to_string() } else { info.name };
            Ok(Rig { cameras: vec![RigCamera { name, model: info.model, t_rig_cam: Pose::identity() }], stereo_pairs: Vec::new() })
        }
    }
}
