//! kalibr camera-chain files (`camchain.yaml`): pinhole cameras with `radtan` distortion.
//!
//! ```text
//! cam0:
//!   camera_model: pinhole
//!   intrinsics: [fu, fv, pu, pv]              # pixels: fx, fy, cx, cy
//!   distortion_model: radtan
//!   distortion_coeffs: [k1, k2, r1, r2]       # r1, r2 = OpenCV's p1, p2
//!   resolution: [width, height]
//!   rostopic: /L40/image_raw
//!   camera_name: "L40"                        # tubeloc extension
//!   cam_overlaps: [3]                          # the camera's stereo partners
//!   tubeloc_T_cn_rig: [[...4...], ... 4 rows]  # tubeloc extension: rig -> cam0
//!   tubeloc_stereo_pairs: [[1, 2], [0, 3]]     # tubeloc extension: (left, right) indices
//! cam1:
//!   T_cn_cnm1: [[r00, r01, r02, t0], ..., [0, 0, 0, 1]]   # maps cam0 points into cam1, metres
//!   ...
//! ```
//!
//! kalibr's radtan model is OpenCV's with `k3 = 0`, with the same pixel convention (centres at
//! integer coordinates), so the conversion is exact for cameras with `k3 = 0`; a camera with
//! `k3 != 0` is refused with an error naming `k3` rather than written with it dropped.
//! kalibr reads only the fields it knows, so the `tubeloc_` extensions and `camera_name` (the
//! rig frame, the stereo pairs and the names) ride along without disturbing it. Reading a file
//! without them, the rig frame is cam0's, cameras are named after their rostopic (`/NAME/…`) or
//! `camN`, and each `cam_overlaps` entry `(i, j)`, `i < j`, becomes the stereo pair `(cam i,
//! cam j)`.

use super::yaml_fields::{as_number, load_mapping, numbers_of, yaml_float_seq, yaml_string, Fields};
use crate::error::CalibError;
use nalgebra::{Matrix3, Matrix4, Vector3};
use std::fmt::Write as _;
use std::path::Path;
use tubeloc_core::{CameraModel, Distortion, Pose, Rig, RigCamera};
use yaml_rust2::Yaml;

fn pose_rows(p: &Pose) -> Vec<[f64; 4]> {
    let r = p.rotation();
    let t = p.translation();
    (0..3).map(|i| [r[(i, 0)], r[(i, 1)], r[(i, 2)], t[i]]).chain(std::iter::once([0.0, 0.0, 0.0, 1.0])).collect()
}

fn write_pose(s: &mut String, key: &str, p: &Pose) {
    let _ = writeln!(s, "  {key}:");
    for row in pose_rows(p) {
        let _ = writeln!(s, "  - {}", yaml_float_seq(&row));
    }
}

/// True for a valid ROS graph-name component (`[A-Za-z][A-Za-z0-9_]*`).
fn is_ros_name(name: &str) -> bool {
    let mut c = name.chars();
    c.next().is_some_and(|f| f.is_ascii_alphabetic()) && c.all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// The rig as kalibr camchain text. Errors name the camera and the term when a camera has
/// `k3 != 0` (kalibr's radtan has no k3).
pub fn rig_to_camchain(rig: &Rig) -> Result<String, CalibError> {
    rig.validate()?;
    for c in &rig.cameras {
        if c.model.distortion.k3 != 0.0 {
            return Err(CalibError::invalid(
                format!("camera {:?}", c.name),
                format!("k3 = {} cannot be written to a kalibr camchain: its radtan model has k1 k2 r1 r2 only (calibrate with --fix-k3, or use the OpenCV YAML or ROS camera_info files, which carry k3)", c.model.distortion.k3),
            ));
        }
    }
    let index = |n: &str| rig.cameras.iter().position(|c| c.name == n).expect("validated");
    let pairs: Vec<(usize, usize)> = rig.stereo_pairs.iter().map(|(l, r)| (index(l), index(r))).collect();
    let mut s = String::from(
        "# kalibr camera chain written by tubeloc: pinhole cameras, radtan distortion (OpenCV's with k3 = 0),\n\
         # pixel centres at integer coordinates; T_cn_cnm1 maps points of camera n-1 into camera n (metres).\n\
         # camera_name, tubeloc_T_cn_rig (rig frame -> cam0) and tubeloc_stereo_pairs ((left, right) camera\n\
         # indices) are tubeloc extensions that kalibr does not read.\n",
    );
    for (i, c) in rig.cameras.iter().enumerate() {
        let m = &c.model;
        let d = &m.distortion;
        let _ = writeln!(s, "cam{i}:");
        if i > 0 {
            write_pose(&mut s, "T_cn_cnm1", &(c.t_rig_cam.inverse() * rig.cameras[i - 1].t_rig_cam));
        }
        let _ = writeln!(s, "  camera_model: pinhole\n  intrinsics: {}", yaml_float_seq(&[m.fx, m.fy, m.cx, m.cy]));
        let _ = writeln!(s, "  distortion_model: radtan\n  distortion_coeffs: {}", yaml_float_seq(&[d.k1, d.k2, d.p1, d.p2]));
        let _ = writeln!(s, "  resolution: [{}, {}]", m.width, m.height);
        let topic = if is_ros_name(&c.name) { c.name.clone() } else { format!("cam{i}") };
        let _ = writeln!(s, "  rostopic: /{topic}/image_raw\n  camera_name: {}", yaml_string(&c.name));
        let mut overlaps: Vec<usize> = pairs
            .iter()
            .filter_map(|&(l, r)| {
                if l == i {
                    Some(r)
                } else if r == i {
                    Some(l)
                } else {
                    None
                }
            })
            .collect();
        overlaps.sort_unstable();
        overlaps.dedup();
        let _ = writeln!(s, "  cam_overlaps: [{}]", overlaps.iter().map(|v| v.to_string()).collect::<Vec<_>>().join(", "));
        if i == 0 {
            write_pose(&mut s, "tubeloc_T_cn_rig", &c.t_rig_cam.inverse());
            let _ = writeln!(s, "  tubeloc_stereo_pairs: [{}]", pairs.iter().map(|(l, r)| format!("[{l}, {r}]")).collect::<Vec<_>>().join(", "));
        }
    }
    Ok(s)
}

/// Writes the rig as a kalibr camchain, atomically.
pub fn save_camchain(rig: &Rig, path: &Path) -> Result<(), CalibError> {
    let text = rig_to_camchain(rig)?;
    Ok(tubeloc_core::files::write_atomic(path, text.as_bytes())?)
}

/// Reads a 4x4 rigid transform field (rows of 4 numbers, last row `[0 0 0 1]`).
fn read_pose(f: &Fields, key: &str) -> Result<Pose, CalibError> {
    let rows = f.get(key)?.as_vec().ok_or_else(|| f.error(key, "expected a 4x4 matrix (a sequence of 4 rows)"))?;
    if rows.len() != 4 {
        return Err(f.error(key, format!("expected a 4x4 matrix, got {} rows", rows.len())));
    }
    let mut m = Matrix4::zeros();
    for (i, row) in rows.iter().enumerate() {
        let items = row.as_vec().ok_or_else(|| f.error(key, format!("row {i} is not a sequence")))?;
        let v = numbers_of(items, Some(4)).map_err(|e| f.error(key, format!("row {i}: {e}")))?;
        for (j, x) in v.into_iter().enumerate() {
            m[(i, j)] = x;
        }
    }
    let last = m.row(3);
    if (last - nalgebra::RowVector4::new(0.0, 0.0, 0.0, 1.0)).abs().max() > 1e-9 {
        return Err(f.error(key, format!("the last row must be [0, 0, 0, 1], got {:?}", [last[0], last[1], last[2], last[3]])));
    }
    let r: Matrix3<f64> = m.fixed_view::<3, 3>(0, 0).into_owned();
    Pose::try_from_matrix(&r, Vector3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)])).map_err(|e| f.error(key, e))
}

/// A camera name from a rostopic: `/L20/image_raw` -> `L20`, `/stereo/left/image_raw` ->
/// `stereo_left`; `None` when nothing is left.
fn name_from_topic(topic: &str) -> Option<String> {
    let mut parts: Vec<&str> = topic.split('/').filter(|p| !p.is_empty()).collect();
    if parts.last().is_some_and(|p| p.starts_with("image")) {
        parts.pop();
    }
    (!parts.is_empty()).then(|| parts.join("_"))
}

/// Builds a rig from camchain text; errors name `path` and the field (`cam1.T_cn_cnm1: ...`).
pub fn rig_from_camchain(text: &str, path: &Path) -> Result<Rig, CalibError> {
    let doc = load_mapping(text, path)?;
    let top = Fields::top(&doc, path);
    let n = (0..).take_while(|i| top.has(&format!("cam{i}"))).count();
    if n == 0 {
        return Err(top.error("cam0", "missing (a kalibr camchain lists cameras cam0, cam1, ...)"));
    }
    let mut cameras: Vec<RigCamera> = Vec::with_capacity(n);
    let mut overlaps = Vec::new();
    let mut extension_pairs = None;
    let mut t_cam0_rig = Pose::identity();
    for i in 0..n {
        let f = top.mapping(&format!("cam{i}"))?;
        let model_name = f.string("camera_model")?;
        if model_name != "pinhole" {
            return Err(f.error("camera_model", format!("{model_name:?} is not supported: tubeloc's camera model is pinhole")));
        }
        let k = f.numbers("intrinsics", Some(4))?;
        let dist_model = f.string("distortion_model")?;
        let d = match dist_model.as_str() {
            "radtan" => f.numbers("distortion_coeffs", Some(4))?,
            "none" => vec![0.0; 4],
            other => return Err(f.error("distortion_model", format!("{other:?} is not supported: tubeloc's lens model is radtan (k1 k2 r1 r2)"))),
        };
        let res = f.get("resolution")?.as_vec().filter(|v| v.len() == 2).ok_or_else(|| f.error("resolution", "expected [width, height]"))?;
        let size = |v: &Yaml| v.as_i64().filter(|x| *x > 0 && *x <= u32::MAX as i64).map(|x| x as u32);
        let (width, height) = match (size(&res[0]), size(&res[1])) {
            (Some(w), Some(h)) => (w, h),
            _ => return Err(f.error("resolution", "expected two positive integers [width, height]")),
        };
        let model = CameraModel { width, height, fx: k[0], fy: k[1], cx: k[2], cy: k[3], distortion: Distortion { k1: d[0], k2: d[1], p1: d[2], p2: d[3], k3: 0.0 } };
        model.validate().map_err(|e| f.error("intrinsics", e))?;
        let name = if f.has("camera_name") {
            f.string("camera_name")?
        } else {
            let derived = if f.has("rostopic") { name_from_topic(&f.string("rostopic")?) } else { None };
            derived.filter(|d| !cameras.iter().any(|c| c.name == *d)).unwrap_or_else(|| format!("cam{i}"))
        };
        let t_rig_cam = if i == 0 {
            if f.has("tubeloc_T_cn_rig") {
                t_cam0_rig = read_pose(&f, "tubeloc_T_cn_rig")?;
            }
            t_cam0_rig.inverse()
        } else {
            cameras[i - 1].t_rig_cam * read_pose(&f, "T_cn_cnm1")?.inverse()
        };
        if f.has("cam_overlaps") {
            let items = f.get("cam_overlaps")?.as_vec().ok_or_else(|| f.error("cam_overlaps", "expected a sequence of camera indices"))?;
            for v in items {
                match v.as_i64() {
                    Some(j) if j >= 0 && (j as usize) < n && j as usize != i => overlaps.push((i.min(j as usize), i.max(j as usize))),
                    _ => return Err(f.error("cam_overlaps", format!("{v:?} is not the index of another camera (0..{n})"))),
                }
            }
        }
        if i == 0 && f.has("tubeloc_stereo_pairs") {
            let items = f.get("tubeloc_stereo_pairs")?.as_vec().ok_or_else(|| f.error("tubeloc_stereo_pairs", "expected a sequence of [left, right] index pairs"))?;
            let mut pairs = Vec::with_capacity(items.len());
            for p in items {
                let ij = p.as_vec().map(|v| v.iter().map(|x| as_number(x).filter(|x| x.fract() == 0.0 && *x >= 0.0 && (*x as usize) < n).map(|x| x as usize)).collect::<Option<Vec<_>>>());
                match ij {
                    Some(Some(v)) if v.len() == 2 && v[0] != v[1] => pairs.push((v[0], v[1])),
                    _ => return Err(f.error("tubeloc_stereo_pairs", format!("{p:?} is not a [left, right] pair of camera indices (0..{n})"))),
                }
            }
            extension_pairs = Some(pairs);
        }
        cameras.push(RigCamera { name, model, t_rig_cam });
    }
    let pairs = match extension_pairs {
        Some(p) => p,
        None => {
            overlaps.sort_unstable();
            overlaps.dedup();
            overlaps
        }
    };
    let stereo_pairs = pairs.into_iter().map(|(l, r)| (cameras[l].name.clone(), cameras[r].name.clone())).collect();
    let rig = Rig { cameras, stereo_pairs };
    rig.validate().map_err(|e| CalibError::parse(path, e.to_string()))?;
    Ok(rig)
}

/// Reads a rig from a kalibr camchain file.
pub fn load_camchain(path: &Path) -> Result<Rig, CalibError> {
    let text = std::fs::read_to_string(path).map_err(|e| tubeloc_core::CoreError::io(path, e))?;
    rig_from_camchain(&text, path)
}
