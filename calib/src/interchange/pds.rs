//! Rover cameras from their PDS camera models, linearized: the JSON list that
//! `cahv_to_pinhole.py` writes (`with_cameras/cameras.json` of the real rover data), one entry
//! per image.
//!
//! Each CAHV / CAHVOR entry becomes a rig camera named after its image's file name, placed in
//! the rover's frame of that image (`ROVER_NAV_FRAME` for MSL: x forward, y right, z down, origin
//! at ground level), and the ground under it: the plane `camera_height_m` below the camera,
//! level in the site frame (`R_cam_from_site`, site z down):
//!
//! ```text
//! T_rover_cam = [R_cam_from_ref^T | camera_center_ref_m]
//! ground (camera frame): n = R_cam_from_site (0, 0, -1),  n · X = -camera_height_m
//! ```
//!
//! [`read_pds_cameras`] also reads the PDS3 label of one image ([`super::pds_label`]).
//! [`read_rig_cameras`] reads a list or a label once, with the fisheye entries below, as
//! `tubeloc locate --rig` takes it.
//!
//! CAHVORE (fisheye) entries are left out of the pinhole cameras: a pinhole does not describe
//! their images. [`fisheye_cameras`] reads each one from the PDS3 label the entry names
//! (`label_file`), with the model its image is resampled from. The pinhole's skew (under 1 px
//! for the MSL and MER cameras) is dropped; an entry with more is refused.

use super::cahvore::Cahvore;
use crate::error::CalibError;
use nalgebra::{Matrix3, Vector3};
use serde_json::Value;
use std::path::Path;
use tubeloc_core::{CameraModel, GroundPlane, Pose, Rig, RigCamera};

/// Largest pinhole skew (px) dropped without changing a projection by more than about a pixel
/// across the frame.
pub const MAX_SKEW_PX: f64 = 1.0;

/// One camera from a PDS camera model (an entry of a PDS camera list, or a PDS3 label): the
/// rig camera and the ground plane under it.
#[derive(Clone, Debug)]
pub struct PdsCamera {
    /// The camera, in the rover frame of its image; named after its image's file name (a list
    /// entry) or its `PRODUCT_ID` (a label).
    pub camera: RigCamera,
    /// The local ground in this camera's frame (`n · X = d`, n up, metres).
    pub ground: GroundPlane,
    /// The image's sol (`sol`), when the entry gives one.
    pub sol: Option<i64>,
    /// The file name of the image the camera took, when its source names it (a list entry's
    /// `image`); `None` for a PDS3 label, which describes the image it is given with.
    pub image: Option<String>,
}

/// The linearized pinhole of a PDS camera model and where it stands: the parts of a
/// [`PdsCamera`] before checking.
#[derive(Clone, Debug)]
pub struct PdsPinhole {
    /// Image size (px).
    pub size: (u32, u32),
    /// `fx, fy, cx, cy` (px, the centre of the first pixel at (0, 0)).
    pub intrinsics: [f64; 4],
    /// `K12` (px), dropped when at most [`MAX_SKEW_PX`].
    pub skew: f64,
    /// Rotation taking rover-frame vectors into the camera frame.
    pub r_cam_from_ref: Matrix3<f64>,
    /// Camera centre in the rover frame (m).
    pub centre: Vector3<f64>,
    /// Rotation taking site-frame (local level, z down) vectors into the camera frame.
    pub r_cam_from_site: Matrix3<f64>,
    /// Height of the camera above its ground (m, along the site's vertical).
    pub height_m: f64,
}

impl PdsCamera {
    /// The camera `name` and its ground from a linearized model; `Err` names the quantity at
    /// fault.
    pub fn from_pinhole(name: &str, p: &PdsPinhole, sol: Option<i64>, image: Option<String>) -> Result<Self, String> {
        if p.skew.is_nan() || p.skew.abs() > MAX_SKEW_PX {
            return Err(format!("skew {} px: more than {MAX_SKEW_PX} px, which a pinhole without skew cannot carry", p.skew));
        }
        let [fx, fy, cx, cy] = p.intrinsics;
        let model = CameraModel { width: p.size.0, height: p.size.1, fx, fy, cx, cy, distortion: Default::default() };
        model.validate().map_err(|err| err.to_string())?;
        let t_rig_cam = Pose::try_from_matrix(&p.r_cam_from_ref.transpose(), p.centre).map_err(|err| format!("`R_cam_from_ref`: {err}"))?;
        if p.height_m.is_nan() || p.height_m <= 0.0 {
            return Err(format!("camera height (`camera_height_m`) {} m must be > 0: the camera is not above its ground", p.height_m));
        }
        let up = p.r_cam_from_site * Vector3::new(0.0, 0.0, -1.0);
        let ground = GroundPlane::new(up, -p.height_m * up.norm()).map_err(|err| format!("`R_cam_from_site`: {err}"))?;
        Ok(PdsCamera { camera: RigCamera { name: name.to_string(), model, t_rig_cam }, ground, sol, image })
    }
}

/// Whether `text` is a JSON list (the first character that is not white space is `[`).
pub fn looks_like_pds_cameras(text: &str) -> bool {
    text.trim_start_matches('\u{feff}').trim_start().starts_with('[')
}

/// Reads every pinhole camera of a `cahv_to_pinhole.py` list (`path` names the file in errors);
/// empty when every entry is a CAHVORE (fisheye) model ([`fisheye_cameras`] reads those).
pub fn pds_cameras(text: &str, path: &Path) -> Result<Vec<PdsCamera>, CalibError> {
    pinhole_cameras(&parse_list(text, path)?, path)
}

/// The entries of a PDS camera list (`text`, read from `path`).
fn parse_list(text: &str, path: &Path) -> Result<Vec<Value>, CalibError> {
    serde_json::from_str(text).map_err(|e| CalibError::parse(path, format!("not a JSON list of PDS cameras: {e}")))
}

/// [`pds_cameras`] of a parsed list.
fn pinhole_cameras(list: &[Value], path: &Path) -> Result<Vec<PdsCamera>, CalibError> {
    let mut out: Vec<PdsCamera> = Vec::with_capacity(list.len());
    for (k, e) in list.iter().enumerate() {
        let fail = |m: String| CalibError::parse(path, format!("entry {k}: {m}"));
        if is_fisheye(e) {
            continue;
        }
        let cam = entry(e).map_err(fail)?;
        if out.iter().any(|c| c.camera.name == cam.camera.name) {
            return Err(fail(format!("a second camera for image {:?}", cam.camera.name)));
        }
        out.push(cam);
    }
    // A list of fisheyes only has no pinhole camera, yet `tubeloc locate` reads its entries'
    // labels ([`fisheye_cameras`]).
    if out.is_empty() && !list.iter().any(is_fisheye) {
        return Err(CalibError::parse(path, "no CAHV or CAHVOR camera in the list"));
    }
    Ok(out)
}

/// The cameras of the file `path` when it is a PDS camera list, or the one camera of a PDS3
/// label (a detached `.LBL`, or an `.IMG` with its label at the head; [`super::pds_label`]);
/// `Ok(None)` when it is some other file (e.g. a tubeloc camera or rig JSON).
pub fn read_pds_cameras(path: &Path) -> Result<Option<Vec<PdsCamera>>, CalibError> {
    if let Some(c) = super::pds_label::read_label_camera(path)? {
        return Ok(Some(vec![c]));
    }
    read_list(path)?.map(|list| pinhole_cameras(&list, path)).transpose()
}

/// The entries of the file `path` when it is a PDS camera list (UTF-8 text whose first
/// character is `[`), `Ok(None)` when it is other UTF-8 text.
fn read_list(path: &Path) -> Result<Option<Vec<Value>>, CalibError> {
    let bytes = std::fs::read(path).map_err(|e| tubeloc_core::CoreError::io(path, e))?;
    let text = String::from_utf8(bytes).map_err(|_| CalibError::parse(path, "neither UTF-8 text nor a PDS3 label"))?;
    if !looks_like_pds_cameras(&text) {
        return Ok(None);
    }
    parse_list(&text, path).map(Some)
}

/// Every camera of a PDS camera list or of a PDS3 label, as `tubeloc locate --rig` takes
/// them ([`read_rig_cameras`]).
#[derive(Clone, Debug, Default)]
pub struct PdsRigCameras {
    /// The label's camera, or the list's pinhole cameras followed by the linear cameras of its
    /// CAHVORE (fisheye) entries read from their labels ([`fisheye_cameras`]).
    pub cameras: Vec<PdsCamera>,
    /// The CAHVORE model each fisheye camera's image is resampled from, by camera name.
    pub fisheye_models: std::collections::BTreeMap<String, Cahvore>,
    /// Why a list's CAHVORE entry gives no camera, by its image's file name.
    pub errors: std::collections::BTreeMap<String, String>,
}

/// The cameras of the file `path` when it is a PDS3 label (a fisheye's too, with its model) or
/// a PDS camera list (with its fisheye entries' cameras read from their labels), `Ok(None)`
/// when it is some other file; the file is read once (a label's head only).
pub fn read_rig_cameras(path: &Path) -> Result<Option<PdsRigCameras>, CalibError> {
    let head = tubeloc_core::odl::read_head(path).map_err(|e| tubeloc_core::CoreError::io(path, e))?;
    let mut out = PdsRigCameras::default();
    if tubeloc_core::odl::looks_like_pds3_label(&head) {
        let (camera, fisheye) = super::pds_label::resampled_label_camera(&head, path)?;
        out.fisheye_models.extend(fisheye.map(|m| (camera.camera.name.clone(), m)));
        out.cameras.push(camera);
        return Ok(Some(out));
    }
    let Some(list) = read_list(path)? else { return Ok(None) };
    out.cameras = pinhole_cameras(&list, path)?;
    for (name, camera) in fisheye_cameras_of(list, path) {
        match camera {
            Ok((c, model)) => {
                out.fisheye_models.insert(c.camera.name.clone(), model);
                out.cameras.push(c);
            }
            Err(e) => {
                out.errors.insert(name, e);
            }
        }
    }
    Ok(Some(out))
}

/// The camera of `cameras` (read from `path`) that took `image`: the one named after the
/// image's file, or the camera of a PDS3 label (which describes the image it is given with);
/// the error names both files.
pub fn camera_of_image<'a>(cameras: &'a [PdsCamera], path: &Path, image: &Path) -> Result<&'a PdsCamera, CalibError> {
    let name = image.file_name().and_then(|n| n.to_str()).unwrap_or_default();
    if let Some(c) = cameras.iter().find(|c| c.image.as_deref() == Some(name)) {
        return Ok(c);
    }
    match cameras {
        [label] if label.image.is_none() => Ok(label),
        _ if fisheye_entries(path).iter().any(|n| n == name) => Err(CalibError::parse(
            path,
            format!("the entry for the image file {name:?} is a CAHVORE (fisheye) model, whose image a pinhole describes only once resampled: `tubeloc locate` resamples it (this list as --rig, when the entry's `label_file` can be read, or the image's PDS3 label as --rig); give other commands the resampled image and a camera JSON"),
        )),
        _ => Err(CalibError::parse(path, format!("no camera for the image file {name:?} (a PDS camera list names each camera after its image)"))),
    }
}

/// Whether a list entry is a CAHVORE (fisheye) model, which [`pds_cameras`] leaves out.
fn is_fisheye(e: &Value) -> bool {
    e.get("model_type").and_then(Value::as_str) == Some("CAHVORE")
}

/// The CAHVORE (fisheye) entries of the PDS camera list at `path`, with their image file
/// names; empty when the file is not such a list.
fn fisheye_list_entries(path: &Path) -> Vec<(String, Value)> {
    fisheye_entries_of(list_or_empty(path))
}

/// The entries of the JSON list at `path`; empty when it cannot be read as one.
fn list_or_empty(path: &Path) -> Vec<Value> {
    std::fs::read_to_string(path).ok().and_then(|t| serde_json::from_str(&t).ok()).unwrap_or_default()
}

/// The CAHVORE (fisheye) entries of a parsed list, with their image file names.
fn fisheye_entries_of(list: Vec<Value>) -> Vec<(String, Value)> {
    list.into_iter().filter(is_fisheye).filter_map(|e| Some((Path::new(e.get("image")?.as_str()?).file_name()?.to_str()?.to_string(), e))).collect()
}

/// The image file names of the CAHVORE (fisheye) entries of the PDS camera list at `path`.
fn fisheye_entries(path: &Path) -> Vec<String> {
    fisheye_list_entries(path).into_iter().map(|(name, _)| name).collect()
}

/// A fisheye's camera (its model's linear part, with its ground) and the CAHVORE model its
/// image is resampled from.
pub type FisheyeCamera = (PdsCamera, Cahvore);

/// The CAHVORE (fisheye) entries of the PDS camera list at `path`, each read from the PDS3
/// label its `label_file` names (relative to the list's folder, as `cahv_to_pinhole.py` writes
/// it), since the list's pinhole describes such an image only once resampled: by the image's
/// file name, the label's camera (the model's linear part, named after that file, with the
/// list entry's sol) and the model the image is resampled from
/// ([`super::linearize::LinearResampling`]), or why the entry gives none. Empty when the
/// file is not such a list.
pub fn fisheye_cameras(path: &Path) -> Vec<(String, Result<FisheyeCamera, String>)> {
    fisheye_cameras_of(list_or_empty(path), path)
}

/// [`fisheye_cameras`] of a parsed list read from `path`.
fn fisheye_cameras_of(list: Vec<Value>, path: &Path) -> Vec<(String, Result<FisheyeCamera, String>)> {
    let folder = path.parent().unwrap_or(Path::new("."));
    let mut out = Vec::new();
    for (name, e) in fisheye_entries_of(list) {
        let camera = match e.get("label_file").and_then(Value::as_str) {
            None => Err(format!("{}: the CAHVORE (fisheye) entry for {name:?} names no `label_file`: give the image's PDS3 label as the rig", path.display())),
            Some(label) => match super::pds_label::read_resampled_label_camera(&folder.join(label)) {
                Ok(Some((mut c, Some(model)))) => {
                    (c.camera.name, c.image, c.sol) = (name.clone(), Some(name.clone()), e.get("sol").and_then(Value::as_i64).or(c.sol));
                    Ok((c, model))
                }
                Ok(Some((_, None))) => Err(format!("{}: the entry for {name:?} is a CAHVORE model but its label {} is not", path.display(), folder.join(label).display())),
                Ok(None) => Err(format!("{}: the label of the CAHVORE entry for {name:?}, {}, is not a PDS3 label", path.display(), folder.join(label).display())),
                Err(err) => Err(format!("{}: the CAHVORE entry for {name:?}: {err}", path.display())),
            },
        };
        out.push((name, camera));
    }
    out
}

/// The rig of a PDS camera list: its cameras, no stereo pair.
pub fn rig_from_pds(text: &str, path: &Path) -> Result<Rig, CalibError> {
    let cameras = pds_cameras(text, path)?;
    if cameras.is_empty() {
        return Err(CalibError::parse(path, "every camera of the list is a CAHVORE (fisheye) model, whose images a pinhole describes only once resampled: `tubeloc locate` takes the list as --rig and resamples them"));
    }
    Ok(rig_of(&cameras))
}

/// The rig of PDS cameras: the cameras, no stereo pair.
pub fn rig_of(cameras: &[PdsCamera]) -> Rig {
    Rig { cameras: cameras.iter().map(|c| c.camera.clone()).collect(), stereo_pairs: Vec::new() }
}

/// One entry's camera and ground; `Err` names the field at fault.
fn entry(e: &Value) -> Result<PdsCamera, String> {
    let num = |key: &str| e.get(key).and_then(Value::as_f64).filter(|v| v.is_finite()).ok_or_else(|| format!("missing or non-finite `{key}`"));
    let vec3 = |v: &Value| -> Option<Vector3<f64>> {
        let a = v.as_array().filter(|a| a.len() == 3)?;
        Some(Vector3::new(a[0].as_f64()?, a[1].as_f64()?, a[2].as_f64()?))
    };
    let mat3 = |key: &str| -> Result<Matrix3<f64>, String> {
        let rows = e.get(key).and_then(Value::as_array).filter(|r| r.len() == 3).ok_or_else(|| format!("missing `{key}` (3x3)"))?;
        let rows: Vec<Vector3<f64>> = rows.iter().map(vec3).collect::<Option<_>>().ok_or_else(|| format!("`{key}` is not 3x3 numbers"))?;
        Ok(Matrix3::from_rows(&[rows[0].transpose(), rows[1].transpose(), rows[2].transpose()]))
    };
    let image = e.get("image").and_then(Value::as_str).ok_or("missing `image`")?;
    let name = Path::new(image).file_name().and_then(|n| n.to_str()).filter(|n| !n.is_empty()).ok_or_else(|| format!("`image` {image:?} has no file name"))?;
    let size = |key: &str| -> Result<u32, String> {
        let v = num(key)?;
        (v >= 1.0 && v.fract() == 0.0 && v <= u32::MAX as f64).then_some(v as u32).ok_or_else(|| format!("`{key}` {v} is not a positive whole number of pixels"))
    };
    let pinhole = PdsPinhole {
        size: (size("image_width")?, size("image_height")?),
        intrinsics: [num("fx")?, num("fy")?, num("cx")?, num("cy")?],
        skew: e.get("skew").and_then(Value::as_f64).unwrap_or(0.0),
        r_cam_from_ref: mat3("R_cam_from_ref")?,
        centre: e.get("camera_center_ref_m").and_then(vec3).ok_or("missing `camera_center_ref_m` (3 numbers)")?,
        r_cam_from_site: mat3("R_cam_from_site")?,
        height_m: num("camera_height_m")?,
    };
    PdsCamera::from_pinhole(name, &pinhole, e.get("sol").and_then(Value::as_i64), Some(name.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;
    use serde_json::json;

    /// A level camera 2 m above the ground looking along the rover's +x, pitched down 30 deg.
    fn navcam_entry() -> Value {
        let (s, c) = (30f64.to_radians().sin(), 30f64.to_radians().cos());
        // Rover/site frame: x forward, y right, z down. Camera: x right, y down, z forward.
        let r_cam_from_ref = [[0.0, 1.0, 0.0], [-s, 0.0, c], [c, 0.0, s]];
        json!({"image": "images/NLB_1.jpg", "model_type": "CAHVOR", "image_width": 1024, "image_height": 1024,
               "fx": 1222.0, "fy": 1221.0, "cx": 511.5, "cy": 510.0, "skew": -0.13,
               "R_cam_from_ref": r_cam_from_ref, "camera_center_ref_m": [0.8, 0.4, -2.0],
               "R_cam_from_site": r_cam_from_ref, "camera_height_m": 2.0})
    }

    #[test]
    fn a_ground_point_projects_where_the_rover_frame_puts_it_and_lies_on_the_ground() {
        let text = json!([navcam_entry(), {"image": "images/fisheye.png", "model_type": "CAHVORE"}]).to_string();
        let cams = pds_cameras(&text, Path::new("cameras.json")).unwrap();
        assert_eq!(cams.len(), 1, "the CAHVORE entry is left out");
        let c = &cams[0];
        assert_eq!((c.camera.name.as_str(), c.sol), ("NLB_1.jpg", None));
        // A point on the ground (z = 0, rover frame) 3 m ahead of the camera, in the camera
        // frame: on the ground plane, and in front of the camera.
        let p_rover = Point3::new(0.8 + 3.0, 0.4, 0.0);
        let p_cam = c.camera.t_rig_cam.inverse().transform_point(&p_rover);
        assert!(p_cam.z > 0.0, "{p_cam}");
        assert!(c.ground.height_of(&p_cam.coords).abs() < 1e-9, "{}", c.ground.height_of(&p_cam.coords));
        // The camera is 2 m above its ground.
        assert!((c.ground.height_of(&Vector3::zeros()) - 2.0).abs() < 1e-9);
        assert!(looks_like_pds_cameras(&text));
    }

    /// An image whose list entry is a fisheye is refused, saying so and pointing at its label;
    /// an image the list does not name is refused as before.
    #[test]
    fn an_image_of_a_fisheye_entry_is_refused_naming_the_model_and_the_label() {
        let dir = std::env::temp_dir().join(format!("tubeloc_pds_fisheye_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("cameras.json");
        std::fs::write(&path, json!([navcam_entry(), {"image": "images/fisheye.png", "model_type": "CAHVORE"}]).to_string()).unwrap();
        let cams = read_pds_cameras(&path).unwrap().unwrap();
        let err = camera_of_image(&cams, &path, Path::new("x/fisheye.png")).unwrap_err().to_string();
        assert!(err.contains("cameras.json") && err.contains("fisheye.png") && err.contains("CAHVORE") && err.contains("PDS3 label"), "{err}");
        let err = camera_of_image(&cams, &path, Path::new("other.png")).unwrap_err().to_string();
        assert!(err.contains("no camera for the image file \"other.png\""), "{err}");
        assert_eq!(camera_of_image(&cams, &path, Path::new("NLB_1.jpg")).unwrap().camera.name, "NLB_1.jpg");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn a_bad_entry_is_refused_with_its_index_and_field() {
        let path = Path::new("cams.json");
        let mut e = navcam_entry();
        e["skew"] = json!(3.0);
        let err = pds_cameras(&json!([navcam_entry(), e]).to_string(), path).unwrap_err().to_string();
        assert!(err.contains("cams.json") && err.contains("entry 1") && err.contains("skew"), "{err}");
        let mut e = navcam_entry();
        e.as_object_mut().unwrap().remove("camera_height_m");
        let err = pds_cameras(&json!([e]).to_string(), path).unwrap_err().to_string();
        assert!(err.contains("entry 0") && err.contains("camera_height_m"), "{err}");
        let err = pds_cameras(&json!([navcam_entry(), navcam_entry()]).to_string(), path).unwrap_err().to_string();
        assert!(err.contains("second camera") && err.contains("NLB_1.jpg"), "{err}");
        let err = pds_cameras("[1, 2", path).unwrap_err().to_string();
        assert!(err.contains("not a JSON list"), "{err}");
        // Every prefix of a valid list is refused, naming the file, never a panic.
        let text = serde_json::to_string_pretty(&json!([navcam_entry()])).unwrap();
        for cut in 0..text.len() - 1 {
            let err = pds_cameras(&text[..cut], path).unwrap_err().to_string();
            assert!(err.contains("cams.json"), "cut {cut}: {err}");
        }
    }
}
