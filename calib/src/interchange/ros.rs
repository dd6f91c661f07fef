//! ROS `camera_info` calibration files (the YAML of `camera_calibration_parsers`), one per camera.
//!
//! ```text
//! image_width: 5472
//! image_height: 3648
//! camera_name: "L20"
//! camera_matrix: {rows: 3, cols: 3, data: [fx, 0, cx, 0, fy, cy, 0, 0, 1]}     # K
//! distortion_model: "plumb_bob"
//! distortion_coefficients: {rows: 1, cols: 5, data: [k1, k2, p1, p2, k3]}     # D
//! rectification_matrix: {rows: 3, cols: 3, data: [...]}                       # R
//! projection_matrix: {rows: 3, cols: 4, data: [...]}                          # P
//! ```
//! (written in block style). `plumb_bob` is OpenCV's radial-tangential model, exactly tubeloc's
//! [`tubeloc_core::Distortion`]; pixel centres sit at integer coordinates in both. For a camera of
//! a stereo pair, `R` and `P` are the pair's rectification ([`PairRectification`]): `R1`/`P1` for
//! the left camera, `R2`/`P2` for the right one, whose `P[0][3] = -f·B` (B the baseline, metres).
//! A camera in no pair gets `R = I` and `P = [K | 0]`.

use super::yaml_fields::{load_mapping, numbers_of, yaml_float_seq, yaml_string, Fields};
use crate::error::CalibError;
use nalgebra::{Matrix3, Matrix3x4};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use tubeloc_core::{CameraModel, Distortion, PairRectification, Rig};

/// One ROS `camera_info` calibration: the camera and its rectification and projection matrices.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraInfo {
    /// `camera_name`.
    pub name: String,
    /// Image size, `K` and the `plumb_bob` distortion (pixels; pixel centres at integers).
    pub model: CameraModel,
    /// `R`: rotation from the camera frame into the rectified frame.
    pub rectification: Matrix3<f64>,
    /// `P`: projection of rectified-frame points (metres) to rectified pixels.
    pub projection: Matrix3x4<f64>,
}

impl CameraInfo {
    /// A camera in no stereo pair: `R = I`, `P = [K | 0]`.
    pub fn monocular(name: &str, model: &CameraModel) -> Self {
        let k = model.k_matrix();
        let mut p = Matrix3x4::zeros();
        p.fixed_view_mut::<3, 3>(0, 0).copy_from(&k);
        CameraInfo { name: name.to_string(), model: model.clone(), rectification: Matrix3::identity(), projection: p }
    }

    /// The file text; `comment` becomes `#` lines at the top.
    pub fn to_yaml(&self, comment: &str) -> String {
        let m = &self.model;
        let d = &m.distortion;
        let mut s = String::new();
        for line in comment.lines() {
            let _ = writeln!(s, "# {line}");
        }
        let _ = writeln!(s, "image_width: {}\nimage_height: {}\ncamera_name: {}", m.width, m.height, yaml_string(&self.name));
        let matrix = |s: &mut String, key: &str, rows: usize, cols: usize, data: &[f64]| {
            let _ = writeln!(s, "{key}:\n  rows: {rows}\n  cols: {cols}\n  data: {}", yaml_float_seq(data));
        };
        matrix(&mut s, "camera_matrix", 3, 3, m.k_matrix().transpose().as_slice());
        let _ = writeln!(s, "distortion_model: plumb_bob");
        matrix(&mut s, "distortion_coefficients", 1, 5, &[d.k1, d.k2, d.p1, d.p2, d.k3]);
        matrix(&mut s, "rectification_matrix", 3, 3, self.rectification.transpose().as_slice());
        matrix(&mut s, "projection_matrix", 3, 4, self.projection.transpose().as_slice());
        s
    }

    /// Parses a `camera_info` YAML file's text; errors name `path` and the field. Accepts the
    /// `plumb_bob` model with 4 or 5 coefficients (k3 = 0 when absent) and refuses any other.
    pub fn from_yaml(text: &str, path: &Path) -> Result<Self, CalibError> {
        let doc = load_mapping(text, path)?;
        let f = Fields::top(&doc, path);
        let width = f.positive_u32("image_width")?;
        let height = f.positive_u32("image_height")?;
        let name = if f.has("camera_name") { f.string("camera_name")? } else { String::new() };
        let matrix = |key: &str, rows: usize, cols: Option<usize>| -> Result<Vec<f64>, CalibError> {
            let m = f.mapping(key)?;
            let r = m.positive_u32("rows")? as usize;
            let c = m.positive_u32("cols")? as usize;
            if r != rows || cols.is_some_and(|cols| c != cols) {
                let want = cols.map_or(format!("{rows}xN"), |cols| format!("{rows}x{cols}"));
                return Err(f.error(key, format!("expected a {want} matrix, got {r}x{c}")));
            }
            let items = m.get("data")?.as_vec().ok_or_else(|| m.error("data", "expected a sequence of numbers"))?;
            numbers_of(items, Some(r * c)).map_err(|e| m.error("data", format!("{e} (a {r}x{c} matrix)")))
        };
        let k = matrix("camera_matrix", 3, Some(3))?;
        let model_name = if f.has("distortion_model") { f.string("distortion_model")? } else { "plumb_bob".into() };
        if model_name != "plumb_bob" {
            return Err(f.error("distortion_model", format!("{model_name:?} is not supported: tubeloc's camera model is plumb_bob (k1 k2 p1 p2 k3)")));
        }
        let d = matrix("distortion_coefficients", 1, None)?;
        if d.len() != 4 && d.len() != 5 {
            return Err(f.error("distortion_coefficients", format!("plumb_bob has 5 coefficients (k1 k2 p1 p2 k3), got {}", d.len())));
        }
        if k[1] != 0.0 || k[3] != 0.0 || k[6] != 0.0 || k[7] != 0.0 || k[8] != 1.0 {
            return Err(f.error("camera_matrix", "expected [fx 0 cx; 0 fy cy; 0 0 1] (no skew)"));
        }
        let r = matrix("rectification_matrix", 3, Some(3))?;
        let p = matrix("projection_matrix", 3, Some(4))?;
        let model = CameraModel { width, height, fx: k[0], fy: k[4], cx: k[2], cy: k[5], distortion: Distortion { k1: d[0], k2: d[1], p1: d[2], p2: d[3], k3: d.get(4).copied().unwrap_or(0.0) } };
        model.validate().map_err(|e| f.error("camera_matrix", e))?;
        Ok(CameraInfo { name, model, rectification: Matrix3::from_row_slice(&r), projection: Matrix3x4::from_row_slice(&p) })
    }

    /// Reads a `camera_info` YAML file.
    pub fn load(path: &Path) -> Result<Self, CalibError> {
        let text = std::fs::read_to_string(path).map_err(|e| tubeloc_core::CoreError::io(path, e))?;
        Self::from_yaml(&text, path)
    }
}

/// One `camera_info` file of a rig export: file name, content and the stereo pair it rectifies.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraInfoFile {
    /// File name inside the export folder: `NAME.yaml`, or `NAME.LEFT-RIGHT.yaml` for a camera's
    /// second and later stereo pairs.
    pub file_name: String,
    /// The calibration.
    pub info: CameraInfo,
    /// The (left, right) pair whose rectification `R`, `P` carry; `None` for `R = I, P = [K|0]`.
    pub pair: Option<(String, String)>,
}

/// Checks that a camera name can be a file name and a ROS name component.
fn check_file_name(name: &str) -> Result<(), CalibError> {
    if name.is_empty() || name.starts_with('.') || !name.chars().all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.')) {
        return Err(CalibError::invalid("camera name", format!("{name:?} cannot name a ROS camera_info file (letters, digits, `_`, `-`, `.` only, not starting with `.`)")));
    }
    Ok(())
}

/// The `camera_info` files of a rig: each camera's `NAME.yaml` carries the rectification of the
/// first stereo pair it belongs to (or `R = I, P = [K|0]` in none); each further pair adds
/// `NAME.LEFT-RIGHT.yaml`. Refuses pairs whose images differ in size or that cannot be rectified.
pub fn rig_camera_infos(rig: &Rig) -> Result<Vec<CameraInfoFile>, CalibError> {
    rig.validate()?;
    let mut rects = Vec::with_capacity(rig.stereo_pairs.len());
    for (l, r) in &rig.stereo_pairs {
        let (lc, rc) = (rig.camera(l).expect("validated"), rig.camera(r).expect("validated"));
        if (lc.model.width, lc.model.height) != (rc.model.width, rc.model.height) {
            return Err(CalibError::invalid(format!("stereo pair {l},{r}"), format!("the images differ in size ({}x{} and {}x{}); a rectified pair shares one size", lc.model.width, lc.model.height, rc.model.width, rc.model.height)));
        }
        let rect = PairRectification::new(&lc.model, &rc.model, &rig.relative_pose(l, r)?).map_err(|e| CalibError::invalid(format!("stereo pair {l},{r}"), e.to_string()))?;
        rects.push(rect);
    }
    let mut files = Vec::new();
    for cam in &rig.cameras {
        check_file_name(&cam.name)?;
        let mut first = true;
        for ((l, r), rect) in rig.stereo_pairs.iter().zip(&rects) {
            let (rot, proj) = if *l == cam.name {
                (rect.r_left, rect.p1)
            } else if *r == cam.name {
                (rect.r_right, rect.p2)
            } else {
                continue;
            };
            let file_name = if first { format!("{}.yaml", cam.name) } else { format!("{}.{l}-{r}.yaml", cam.name) };
            first = false;
            files.push(CameraInfoFile { file_name, info: CameraInfo { name: cam.name.clone(), model: cam.model.clone(), rectification: rot, projection: proj }, pair: Some((l.clone(), r.clone())) });
        }
        if first {
            files.push(CameraInfoFile { file_name: format!("{}.yaml", cam.name), info: CameraInfo::monocular(&cam.name, &cam.model), pair: None });
        }
    }
    Ok(files)
}

/// Writes [`rig_camera_infos`] into `dir` (created if needed), each file atomically; returns
/// the paths written.
pub fn save_rig_camera_infos(rig: &Rig, dir: &Path) -> Result<Vec<PathBuf>, CalibError> {
    let files = rig_camera_infos(rig)?;
    std::fs::create_dir_all(dir).map_err(|e| tubeloc_core::CoreError::io(dir, e))?;
    let mut written = Vec::with_capacity(files.len());
    for f in &files {
        let role = match &f.pair {
            Some((l, r)) if *l == f.info.name => format!("R, P: rectification of stereo pair {l},{r}; this is the left camera (P[0][3] = 0)"),
            Some((l, r)) => format!("R, P: rectification of stereo pair {l},{r}; this is the right camera (P[0][3] = -f * baseline)"),
            None => "R = I, P = [K | 0]: the camera is in no stereo pair".to_string(),
        };
        let comment = format!("ROS camera_info calibration of camera {:?} written by tubeloc.\nplumb_bob = OpenCV radial-tangential (k1 k2 p1 p2 k3); pixel centres at integer coordinates.\n{role}", f.info.name);
        let path = dir.join(&f.file_name);
        tubeloc_core::files::write_atomic(&path, f.info.to_yaml(&comment).as_bytes())?;
        written.push(path);
    }
    Ok(written)
}
