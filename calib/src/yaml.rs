//! Rig files in OpenCV FileStorage YAML (`%YAML:1.0`), written and read back.
//!
//! Layout (one block per camera `i`, rig frame = the tubeloc rig frame):
//!
//! ```text
//! %YAML:1.0
//! ---
//! camera_count: 2
//! stereo_pairs: [ "L20", "R20" ]          # flattened (left, right) names
//! cam0_name: "L20"
//! cam0_image_width: 1368
//! cam0_image_height: 912
//! cam0_camera_matrix: !!opencv-matrix      # K, 3x3
//!    rows: 3
//!    cols: 3
//!    dt: d
//!    data: [ fx, 0., cx, 0., fy, cy, 0., 0., 1. ]
//! cam0_distortion_coefficients: !!opencv-matrix   # 1x5: k1 k2 p1 p2 k3
//! cam0_R: !!opencv-matrix                  # 3x3, x_cam = R·x_rig + T (OpenCV's R, T)
//! cam0_T: !!opencv-matrix                  # 3x1, metres
//! ```
//!
//! The reader accepts this subset of YAML: `key: scalar`, `key: [flow, sequence]` and
//! `key: !!opencv-matrix` mappings (rows, cols, dt, data possibly over several lines), comments
//! and the header lines. Errors name the file, the line and the field.

use crate::error::CalibError;
use nalgebra::{Matrix3, Vector3};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;
use tubeloc_core::{CameraModel, Distortion, Pose, Rig, RigCamera};

/// A parsed value of the supported subset.
#[derive(Clone, Debug, PartialEq)]
pub enum YamlValue {
    /// A scalar (quotes removed).
    Scalar(String),
    /// A flow sequence of scalars.
    Seq(Vec<String>),
    /// An `!!opencv-matrix`.
    Matrix {
        /// Rows.
        rows: usize,
        /// Columns.
        cols: usize,
        /// Element type (`d`, `f`, `i`, ...).
        dt: String,
        /// Row-major data.
        data: Vec<f64>,
    },
}

fn fmt_num(v: f64) -> String {
    if v.is_nan() {
        ".Nan".into()
    } else if v.is_infinite() {
        if v > 0.0 {
            ".Inf".into()
        } else {
            "-.Inf".into()
        }
    } else {
        format!("{v:.17e}")
    }
}

fn write_matrix(out: &mut String, key: &str, rows: usize, cols: usize, data: &[f64]) {
    let _ = writeln!(out, "{key}: !!opencv-matrix\n   rows: {rows}\n   cols: {cols}\n   dt: d");
    let items: Vec<String> = data.iter().map(|v| fmt_num(*v)).collect();
    let _ = writeln!(out, "   data: [ {} ]", items.join(",\n       "));
}

/// The rig as OpenCV FileStorage YAML text.
pub fn rig_to_yaml(rig: &Rig) -> String {
    let mut s = String::from("%YAML:1.0\n---\n");
    let _ = writeln!(s, "camera_count: {}", rig.cameras.len());
    let pairs: Vec<String> = rig.stereo_pairs.iter().flat_map(|(l, r)| [format!("\"{l}\""), format!("\"{r}\"")]).collect();
    let _ = writeln!(s, "stereo_pairs: [ {} ]", pairs.join(", "));
    for (i, c) in rig.cameras.iter().enumerate() {
        let m = &c.model;
        let d = &m.distortion;
        let _ = writeln!(s, "cam{i}_name: \"{}\"", c.name.replace('"', "'"));
        let _ = writeln!(s, "cam{i}_image_width: {}\ncam{i}_image_height: {}", m.width, m.height);
        write_matrix(&mut s, &format!("cam{i}_camera_matrix"), 3, 3, &[m.fx, 0.0, m.cx, 0.0, m.fy, m.cy, 0.0, 0.0, 1.0]);
        write_matrix(&mut s, &format!("cam{i}_distortion_coefficients"), 1, 5, &[d.k1, d.k2, d.p1, d.p2, d.k3]);
        let t_cam_rig = c.t_rig_cam.inverse();
        let r = t_cam_rig.rotation();
        let t = t_cam_rig.translation();
        write_matrix(&mut s, &format!("cam{i}_R"), 3, 3, &[r[(0, 0)], r[(0, 1)], r[(0, 2)], r[(1, 0)], r[(1, 1)], r[(1, 2)], r[(2, 0)], r[(2, 1)], r[(2, 2)]]);
        write_matrix(&mut s, &format!("cam{i}_T"), 3, 1, &[t.x, t.y, t.z]);
    }
    s
}

/// Writes the rig as OpenCV YAML, atomically.
pub fn save_rig_yaml(rig: &Rig, path: &Path) -> Result<(), CalibError> {
    Ok(tubeloc_core::files::write_atomic(path, rig_to_yaml(rig).as_bytes())?)
}

fn unquote(s: &str) -> String {
    let s = s.trim();
    if s.len() >= 2 && ((s.starts_with('"') && s.ends_with('"')) || (s.starts_with('\'') && s.ends_with('\''))) {
        s[1..s.len() - 1].to_string()
    } else {
        s.to_string()
    }
}

fn parse_num(s: &str) -> Option<f64> {
    match s.trim() {
        ".Nan" | ".NaN" | ".nan" => Some(f64::NAN),
        ".Inf" | "+.Inf" | ".inf" => Some(f64::INFINITY),
        "-.Inf" | "-.inf" => Some(f64::NEG_INFINITY),
        t => t.parse::<f64>().ok(),
    }
}

fn strip_comment(line: &str) -> &str {
    let mut in_q = false;
    for (i, ch) in line.char_indices() {
        match ch {
            '"' => in_q = !in_q,
            '#' if !in_q => return &line[..i],
            _ => {}
        }
    }
    line
}

/// Parses the supported YAML subset into top-level keys; `path` names the file in errors.
pub fn parse_yaml(text: &str, path: &Path) -> Result<BTreeMap<String, YamlValue>, CalibError> {
    let err = |line: usize, msg: String| CalibError::parse(path, format!("line {line}: {msg}"));
    let lines: Vec<&str> = text.lines().collect();
    let mut map = BTreeMap::new();
    let mut i = 0;
    let mut saw_header = false;
    while i < lines.len() {
        let raw = lines[i];
        let ln = i + 1;
        i += 1;
        if raw.starts_with("%YAML") {
            saw_header = true;
            continue;
        }
        let line = strip_comment(raw);
        if line.trim().is_empty() || line.trim() == "---" {
            continue;
        }
        if line.starts_with(' ') || line.starts_with('\t') {
            return Err(err(ln, format!("unexpected indented line {:?}", line.trim())));
        }
        let (key, value) = line.split_once(':').ok_or_else(|| err(ln, format!("expected `key: value`, got {:?}", line.trim())))?;
        let key = key.trim().to_string();
        let value = value.trim();
        if key.is_empty() {
            return Err(err(ln, "empty key".into()));
        }
        let parsed = if value.starts_with("!!opencv-matrix") {
            let (mut rows, mut cols, mut dt, mut data) = (None, None, None, None::<Vec<f64>>);
            while i < lines.len() && (lines[i].starts_with(' ') || lines[i].starts_with('\t')) {
                let sl = strip_comment(lines[i]).trim().to_string();
                let sln = i + 1;
                i += 1;
                if sl.is_empty() {
                    continue;
                }
                let (k, v) = sl.split_once(':').ok_or_else(|| err(sln, format!("{key}: expected `field: value`")))?;
                let v = v.trim();
                match k.trim() {
                    "rows" => rows = Some(v.parse::<usize>().map_err(|_| err(sln, format!("{key}.rows: not an integer: {v:?}")))?),
                    "cols" => cols = Some(v.parse::<usize>().map_err(|_| err(sln, format!("{key}.cols: not an integer: {v:?}")))?),
                    "dt" => dt = Some(unquote(v)),
                    "data" => {
                        let mut buf = v.to_string();
                        while !buf.contains(']') {
                            if i >= lines.len() {
                                return Err(err(sln, format!("{key}.data: unterminated `[`")));
                            }
                            buf.push(' ');
                            buf.push_str(strip_comment(lines[i]));
                            i += 1;
                        }
                        let inner = buf.trim().strip_prefix('[').and_then(|b| b.trim_end().strip_suffix(']')).ok_or_else(|| err(sln, format!("{key}.data: expected `[ ... ]`")))?;
                        let vals = inner.split(',').filter(|t| !t.trim().is_empty()).map(|t| parse_num(t).ok_or_else(|| err(sln, format!("{key}.data: not a number: {:?}", t.trim())))).collect::<Result<Vec<f64>, _>>()?;
                        data = Some(vals);
                    }
                    other => return Err(err(sln, format!("{key}: unknown matrix field {other:?}"))),
                }
            }
            let rows = rows.ok_or_else(|| err(ln, format!("{key}: missing rows")))?;
            let cols = cols.ok_or_else(|| err(ln, format!("{key}: missing cols")))?;
            let data = data.ok_or_else(|| err(ln, format!("{key}: missing data")))?;
            if rows.checked_mul(cols) != Some(data.len()) {
                return Err(err(ln, format!("{key}: {} values for a {rows}x{cols} matrix", data.len())));
            }
            YamlValue::Matrix { rows, cols, dt: dt.unwrap_or_else(|| "d".into()), data }
        } else if let Some(inner) = value.strip_prefix('[') {
            let inner = inner.trim_end().strip_suffix(']').ok_or_else(|| err(ln, format!("{key}: unterminated `[`")))?;
            YamlValue::Seq(inner.split(',').map(unquote).filter(|s| !s.is_empty()).collect())
        } else {
            YamlValue::Scalar(unquote(value))
        };
        if map.insert(key.clone(), parsed).is_some() {
            return Err(err(ln, format!("{key}: duplicate key")));
        }
    }
    if !saw_header {
        return Err(CalibError::parse(path, "missing `%YAML:1.0` header"));
    }
    Ok(map)
}

/// Builds a rig from YAML text written by [`rig_to_yaml`] (or OpenCV with the same keys).
pub fn rig_from_yaml(text: &str, path: &Path) -> Result<Rig, CalibError> {
    let map = parse_yaml(text, path)?;
    let perr = |field: &str, msg: &str| CalibError::parse(path, format!("{field}: {msg}"));
    let scalar = |k: &str| -> Result<&str, CalibError> {
        match map.get(k) {
            Some(YamlValue::Scalar(s)) => Ok(s.as_str()),
            Some(_) => Err(perr(k, "expected a scalar")),
            None => Err(perr(k, "missing")),
        }
    };
    let matrix = |k: &str, r: usize, c: usize| -> Result<&Vec<f64>, CalibError> {
        match map.get(k) {
            Some(YamlValue::Matrix { rows, cols, data, .. }) if *rows == r && *cols == c => Ok(data),
            Some(YamlValue::Matrix { rows, cols, .. }) => Err(perr(k, &format!("expected {r}x{c}, got {rows}x{cols}"))),
            Some(_) => Err(perr(k, "expected an !!opencv-matrix")),
            None => Err(perr(k, "missing")),
        }
    };
    let n: usize = scalar("camera_count")?.parse().map_err(|_| perr("camera_count", "not a non-negative integer"))?;
    if n == 0 || n > 1000 {
        return Err(perr("camera_count", "must be between 1 and 1000"));
    }
    let mut cameras = Vec::with_capacity(n);
    for i in 0..n {
        let f = |s: &str| format!("cam{i}_{s}");
        let name = scalar(&f("name"))?.to_string();
        let width: u32 = scalar(&f("image_width"))?.parse().map_err(|_| perr(&f("image_width"), "not an integer"))?;
        let height: u32 = scalar(&f("image_height"))?.parse().map_err(|_| perr(&f("image_height"), "not an integer"))?;
        let k = matrix(&f("camera_matrix"), 3, 3)?;
        let d = match map.get(&f("distortion_coefficients")) {
            Some(YamlValue::Matrix { rows, cols, data, .. }) if rows * cols >= 4 && (*rows == 1 || *cols == 1) => data.clone(),
            Some(_) => return Err(perr(&f("distortion_coefficients"), "expected a 1xN matrix with N >= 4")),
            None => return Err(perr(&f("distortion_coefficients"), "missing")),
        };
        let r = matrix(&f("R"), 3, 3)?;
        let t = matrix(&f("T"), 3, 1)?;
        let model = CameraModel { width, height, fx: k[0], fy: k[4], cx: k[2], cy: k[5], distortion: Distortion { k1: d[0], k2: d[1], p1: d[2], p2: d[3], k3: d.get(4).copied().unwrap_or(0.0) } };
        model.validate().map_err(|e| perr(&f("camera_matrix"), &e.to_string()))?;
        let t_cam_rig = Pose::try_from_matrix(&Matrix3::from_row_slice(r), Vector3::new(t[0], t[1], t[2])).map_err(|e| perr(&f("R"), &e.to_string()))?;
        cameras.push(RigCamera { name, model, t_rig_cam: t_cam_rig.inverse() });
    }
    let stereo_pairs = match map.get("stereo_pairs") {
        None => Vec::new(),
        Some(YamlValue::Seq(v)) if v.len() % 2 == 0 => v.chunks(2).map(|c| (c[0].clone(), c[1].clone())).collect(),
        Some(_) => return Err(perr("stereo_pairs", "expected a flow sequence of (left, right) name pairs")),
    };
    let rig = Rig { cameras, stereo_pairs };
    rig.validate().map_err(|e| CalibError::parse(path, e.to_string()))?;
    Ok(rig)
}

/// Reads a rig from an OpenCV YAML file.
pub fn load_rig_yaml(path: &Path) -> Result<Rig, CalibError> {
    let text = std::fs::read_to_string(path).map_err(|e| tubeloc_core::CoreError::io(path, e))?;
    rig_from_yaml(&text, path)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;

    fn rig() -> Rig {
        let m = CameraModel { distortion: Distortion { k1: -0.05, k2: 0.02, p1: 1e-4, p2: -2e-4, k3: 0.001 }, ..CameraModel::from_hfov(1368, 912, 77.0) };
        Rig {
            cameras: vec![
                RigCamera { name: "L20".into(), model: m.clone(), t_rig_cam: Pose::identity() },
                RigCamera { name: "R20".into(), model: m, t_rig_cam: Pose::from_parts(Rotation3::from_euler_angles(0.01, -0.02, 0.003), Vector3::new(0.2, 0.001, -0.002)) },
            ],
            stereo_pairs: vec![("L20".into(), "R20".into())],
        }
    }

    #[test]
    fn yaml_round_trip_is_exact() {
        let r = rig();
        let text = rig_to_yaml(&r);
        assert!(text.starts_with("%YAML:1.0\n---\n") && text.contains("!!opencv-matrix"));
        let back = rig_from_yaml(&text, Path::new("rig.yaml")).unwrap();
        assert_eq!(back.stereo_pairs, r.stereo_pairs);
        for (a, b) in r.cameras.iter().zip(&back.cameras) {
            assert_eq!(a.model, b.model);
            let (ang, d) = a.t_rig_cam.distance(&b.t_rig_cam);
            assert!(ang < 1e-12 && d < 1e-12);
        }
    }

    #[test]
    fn yaml_errors_name_file_line_and_field() {
        let text = rig_to_yaml(&rig());
        let bad = text.replace("cam1_T: !!opencv-matrix\n   rows: 3", "cam1_T: !!opencv-matrix\n   rows: 2");
        let e = rig_from_yaml(&bad, Path::new("x/rig.yaml")).unwrap_err().to_string();
        assert!(e.contains("rig.yaml") && e.contains("cam1_T"), "{e}");
        let e = rig_from_yaml(&text.replace("cam0_name: \"L20\"\n", ""), Path::new("rig.yaml")).unwrap_err().to_string();
        assert!(e.contains("cam0_name: missing"), "{e}");
        let e = rig_from_yaml(&text.replacen("data: [ ", "data: [ abc, ", 1), Path::new("rig.yaml")).unwrap_err().to_string();
        assert!(e.contains("line") && e.contains("not a number"), "{e}");
        assert!(rig_from_yaml("camera_count: 1\n", Path::new("r.yaml")).unwrap_err().to_string().contains("%YAML"));
        // Arbitrary junk never panics.
        for cut in (0..text.len()).step_by(37) {
            let _ = rig_from_yaml(&text[..cut], Path::new("r.yaml"));
        }
    }
}
