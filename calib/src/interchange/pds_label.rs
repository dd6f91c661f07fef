//! A rover camera from the PDS3 label of its image (a detached `.LBL`, or the label at the head
//! of an `.IMG`): the camera model of `GEOMETRIC_CAMERA_MODEL_PARMS` linearized
//! ([`super::cahv`]), placed in the rover frame the model is given in, and the ground under it.
//!
//! The ground is level in the site frame: `ORIGIN_ROTATION_QUATERNION` of
//! `ROVER_COORD_SYSTEM_PARMS` (scalar first) takes rover-frame vectors into the site frame
//! (x north, y east, z down), and the camera stands `-(R_site_from_rover C)_z` above the rover
//! frame's origin, which for MSL's `ROVER_NAV_FRAME` is on the ground under the rover. Without
//! that group the rover frame is taken as level. These are the conventions of
//! `cahv_to_pinhole.py` of the real rover data; the figures agree with its list to 1e-9.
//!
//! CAHVOR's radial terms are dropped (under 1 px over a Navcam frame: record 0059). A CAHVORE
//! (fisheye) model's camera is its linear part, which describes the image only once resampled
//! ([`super::linearize`]): [`label_camera`] refuses it, [`resampled_label_camera`] gives it with
//! its model. A skew over [`super::pds::MAX_SKEW_PX`] is refused.

use super::cahv::{Cahv, Cahvor};
use super::cahvore::Cahvore;
use super::odl::{OdlGroup, OdlLabel};
use super::pds::{PdsCamera, PdsPinhole};
use crate::error::CalibError;
use nalgebra::{Matrix3, Quaternion, UnitQuaternion, Vector3};
use std::path::Path;

/// The camera model of a label: CAHV, or CAHVOR with its distortion.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LabelModel {
    /// A CAHV model.
    Cahv(Cahv),
    /// A CAHVOR model.
    Cahvor(Cahvor),
    /// A CAHVORE model.
    Cahvore(Cahvore),
}

impl LabelModel {
    /// The linear (CAHV) part.
    pub fn cahv(&self) -> &Cahv {
        match self {
            LabelModel::Cahv(m) => m,
            LabelModel::Cahvor(m) => &m.cahv,
            LabelModel::Cahvore(m) => &m.cahvor.cahv,
        }
    }
}

/// The camera model of a parsed label (`GEOMETRIC_CAMERA_MODEL_PARMS`, MER's
/// `GEOMETRIC_CAMERA_MODEL`); `Err` names the keyword and its line.
pub fn label_model(label: &OdlLabel) -> Result<LabelModel, String> {
    let g = label.group("GEOMETRIC_CAMERA_MODEL_PARMS").or_else(|| label.group("GEOMETRIC_CAMERA_MODEL")).ok_or("no GEOMETRIC_CAMERA_MODEL_PARMS group: the label carries no camera model")?;
    let kind = g.text("MODEL_TYPE").ok_or("no MODEL_TYPE in GEOMETRIC_CAMERA_MODEL_PARMS")?;
    let vec3 = |k: usize| -> Result<Vector3<f64>, String> { g.numbers(&format!("MODEL_COMPONENT_{k}"), 3).map(|v| Vector3::new(v[0], v[1], v[2])) };
    let cahv = || -> Result<Cahv, String> { Ok(Cahv { c: vec3(1)?, a: vec3(2)?, h: vec3(3)?, v: vec3(4)? }) };
    let cahvor = || -> Result<Cahvor, String> {
        let r = vec3(6)?;
        Ok(Cahvor { cahv: cahv()?, o: vec3(5)?.try_normalize(1e-12).ok_or("MODEL_COMPONENT_5 (O) is zero")?, r: [r.x, r.y, r.z] })
    };
    match kind {
        "CAHV" => Ok(LabelModel::Cahv(cahv()?)),
        "CAHVOR" => Ok(LabelModel::Cahvor(cahvor()?)),
        "CAHVORE" => {
            let e = vec3(7)?;
            let parm = g.get("MODEL_COMPONENT_9").map(|_| g.number("MODEL_COMPONENT_9")).transpose()?;
            let linearity = Cahvore::linearity_of(g.number("MODEL_COMPONENT_8")?, parm).map_err(|m| format!("CAHVORE MODEL_COMPONENT_8/9: {m}"))?;
            Ok(LabelModel::Cahvore(Cahvore { cahvor: cahvor()?, e: [e.x, e.y, e.z], linearity }))
        }
        other => Err(format!("MODEL_TYPE {other:?}: not CAHV, CAHVOR or CAHVORE")),
    }
}

/// The rotation taking rover-frame vectors into the site frame, when the label gives the rover's
/// attitude.
pub fn site_from_rover(label: &OdlLabel) -> Result<Option<Matrix3<f64>>, String> {
    let Some(g) = label.group("ROVER_COORD_SYSTEM_PARMS").or_else(|| label.group("ROVER_COORDINATE_SYSTEM")) else { return Ok(None) };
    if g.get("ORIGIN_ROTATION_QUATERNION").is_none() {
        return Ok(None);
    }
    let q = g.numbers("ORIGIN_ROTATION_QUATERNION", 4)?;
    let q = Quaternion::new(q[0], q[1], q[2], q[3]);
    if !(0.5..2.0).contains(&q.norm()) {
        return Err(format!("ORIGIN_ROTATION_QUATERNION of {} has norm {}, not about 1", g.name, q.norm()));
    }
    Ok(Some(UnitQuaternion::from_quaternion(q).to_rotation_matrix().into_inner()))
}

/// The camera and ground of the file `path` when it starts with a PDS3 label (a `.LBL`, or an
/// `.IMG` whose samples follow its label and are not read), `Ok(None)` when it does not.
/// A CAHVORE (fisheye) label is refused, as by [`label_camera`].
pub fn read_label_camera(path: &Path) -> Result<Option<PdsCamera>, CalibError> {
    read_resampled_label_camera(path)?.map(|c| pinhole_only(c, path)).transpose()
}

/// The camera and ground of a PDS3 label (`bytes`, read from `path`), named after the label's
/// `PRODUCT_ID` (else the file name); every error names the file and, where one is at fault,
/// the keyword and line. A CAHVORE (fisheye) label is refused: its pinhole describes its image
/// only resampled ([`resampled_label_camera`]).
pub fn label_camera(bytes: &[u8], path: &Path) -> Result<PdsCamera, CalibError> {
    pinhole_only(resampled_label_camera(bytes, path)?, path)
}

/// The camera of a label (read from `path`) that is not a fisheye's linear part; `Err` for a
/// fisheye, naming `tubeloc locate`, which resamples it.
fn pinhole_only((camera, fisheye): (PdsCamera, Option<Cahvore>), path: &Path) -> Result<PdsCamera, CalibError> {
    match fisheye {
        None => Ok(camera),
        Some(_) => Err(CalibError::parse(
            path,
            "PDS3 label: MODEL_TYPE CAHVORE (a fisheye camera): a pinhole describes its image only once resampled, \
             which `tubeloc locate` does (--rig LABEL or --label-cameras); give other commands the resampled image and a camera JSON"
                .to_string(),
        )),
    }
}

/// [`read_label_camera`] that also takes CAHVORE labels: the camera, and the CAHVORE model its
/// image must be resampled from ([`super::linearize::LinearResampling`]) when the label has one.
pub fn read_resampled_label_camera(path: &Path) -> Result<Option<(PdsCamera, Option<Cahvore>)>, CalibError> {
    let head = tubeloc_core::odl::read_head(path).map_err(|e| tubeloc_core::CoreError::io(path, e))?;
    if !tubeloc_core::odl::looks_like_pds3_label(&head) {
        return Ok(None);
    }
    resampled_label_camera(&head, path).map(Some)
}

/// [`label_camera`] that also takes CAHVORE labels: the camera is the model's linear (CAHV)
/// part, returned with the model its image must be resampled from.
pub fn resampled_label_camera(bytes: &[u8], path: &Path) -> Result<(PdsCamera, Option<Cahvore>), CalibError> {
    let fail = |m: String| CalibError::parse(path, format!("PDS3 label: {m}"));
    let label = OdlLabel::parse(bytes).map_err(fail)?;
    let model = label_model(&label).map_err(fail)?;
    let lin = model.cahv().linearize().map_err(|m| fail(format!("camera model: {m}")))?;
    let image = label.group("IMAGE").ok_or_else(|| fail("no IMAGE object: the image size is not given".into()))?;
    let size = |g: &OdlGroup, key: &str| -> Result<u32, String> {
        let v = g.number(key)?;
        (v >= 1.0 && v.fract() == 0.0 && v <= u32::MAX as f64).then_some(v as u32).ok_or_else(|| format!("{key} = {v} in {} is not a positive whole number of pixels", g.name))
    };
    let (width, height) = (size(image, "LINE_SAMPLES").map_err(fail)?, size(image, "LINES").map_err(fail)?);
    let (r_cam_from_site, height_m) = match site_from_rover(&label).map_err(fail)? {
        Some(r_site_rover) => (lin.r_cam_from_ref * r_site_rover.transpose(), -(r_site_rover * lin.centre).z),
        None => (lin.r_cam_from_ref, -lin.centre.z),
    };
    let pinhole = PdsPinhole { size: (width, height), intrinsics: [lin.fx, lin.fy, lin.cx, lin.cy], skew: lin.skew, r_cam_from_ref: lin.r_cam_from_ref, centre: lin.centre, r_cam_from_site, height_m };
    let root = label.root();
    let name = root.text("PRODUCT_ID").or_else(|| root.text("IMAGE_ID")).filter(|n| !n.is_empty()).map(str::to_string);
    let name = name.unwrap_or_else(|| path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default());
    let sol = root.number("PLANET_DAY_NUMBER").ok().filter(|s| s.fract() == 0.0).map(|s| s as i64);
    let fisheye = match model {
        LabelModel::Cahvore(m) => Some(m),
        _ => None,
    };
    Ok((PdsCamera::from_pinhole(&name, &pinhole, sol, None).map_err(fail)?, fisheye))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn label(model_type: &str, extra: &str) -> String {
        format!(
            "PDS_VERSION_ID = PDS3\nPRODUCT_ID = \"NLA_1\"\nPLANET_DAY_NUMBER = 38\n{extra}\
GROUP = GEOMETRIC_CAMERA_MODEL_PARMS\n MODEL_TYPE = {model_type}\n MODEL_COMPONENT_1 = (0.8,0.3,-1.95)\n\
 MODEL_COMPONENT_2 = (1.0,0.0,0.0)\n MODEL_COMPONENT_3 = (512.0,1200.0,0.0)\n MODEL_COMPONENT_4 = (510.0,0.0,1200.0)\n\
 MODEL_COMPONENT_5 = (1.0,0.0,0.0)\n MODEL_COMPONENT_6 = (0.0,-0.005,0.02)\nEND_GROUP = GEOMETRIC_CAMERA_MODEL_PARMS\n\
OBJECT = IMAGE\n LINES = 1024\n LINE_SAMPLES = 1024\nEND_OBJECT = IMAGE\nEND\n"
        )
    }

    #[test]
    fn a_level_forward_camera_stands_at_its_height_over_its_ground() {
        // A = rover +x (forward), H: +y (right), V: +z (down): a camera looking straight ahead,
        // 1.95 m above the rover frame's origin; the rover level (no attitude group).
        let cam = label_camera(label("CAHVOR", "").as_bytes(), Path::new("x.LBL")).unwrap();
        assert_eq!((cam.camera.name.as_str(), cam.sol, cam.image.as_deref()), ("NLA_1", Some(38), None));
        let m = &cam.camera.model;
        assert_eq!((m.width, m.height, m.fx, m.fy, m.cx, m.cy), (1024, 1024, 1200.0, 1200.0, 512.0, 510.0));
        assert!((cam.ground.height_of(&Vector3::zeros()) - 1.95).abs() < 1e-12);
        // A rover 90 deg yawed (a rotation about the site's vertical) stands at the same height.
        let yawed = "GROUP = ROVER_COORD_SYSTEM_PARMS\n ORIGIN_ROTATION_QUATERNION = (0.7071068,0,0,0.7071068)\nEND_GROUP = ROVER_COORD_SYSTEM_PARMS\n";
        let cam = label_camera(label("CAHV", yawed).as_bytes(), Path::new("x.LBL")).unwrap();
        assert!((cam.ground.height_of(&Vector3::zeros()) - 1.95).abs() < 1e-6);
    }

    #[test]
    fn a_fisheye_label_gives_its_linear_part_and_its_model() {
        let text = label("CAHVORE", "").replace(" MODEL_COMPONENT_6", " MODEL_COMPONENT_7 = (0.001,0.002,0)\n MODEL_COMPONENT_8 = 3.0\n MODEL_COMPONENT_9 = 0.37\n MODEL_COMPONENT_6");
        let (cam, fisheye) = resampled_label_camera(text.as_bytes(), Path::new("x.LBL")).unwrap();
        let fisheye = fisheye.expect("a CAHVORE model");
        assert_eq!((fisheye.linearity, fisheye.e), (0.37, [0.001, 0.002, 0.0]));
        let plain = label_camera(label("CAHV", "").as_bytes(), Path::new("x.LBL")).unwrap();
        assert_eq!(cam.camera.model, plain.camera.model);
        assert_eq!(cam.camera.t_rig_cam, plain.camera.t_rig_cam);
        assert!(resampled_label_camera(label("CAHVOR", "").as_bytes(), Path::new("x.LBL")).unwrap().1.is_none());
    }

    #[test]
    fn labels_without_a_usable_pinhole_are_refused_naming_the_file_and_why() {
        let path = Path::new("dir/NLA_1.LBL");
        let err = |text: &str| label_camera(text.as_bytes(), path).unwrap_err().to_string();
        let e = err(&label("CAHVORE", ""));
        assert!(e.contains("dir/NLA_1.LBL") && e.contains("MODEL_COMPONENT_7"), "{e}");
        let e = err(&label("CAHVORE", "").replace(" MODEL_COMPONENT_6", " MODEL_COMPONENT_7 = (0.001,0,0)\n MODEL_COMPONENT_8 = 3.0\n MODEL_COMPONENT_6"));
        assert!(e.contains("MPARM"), "{e}");
        let e = err(&label("CAHVORE", "").replace(" MODEL_COMPONENT_6", " MODEL_COMPONENT_7 = (0.001,0,0)\n MODEL_COMPONENT_8 = 2\n MODEL_COMPONENT_6"));
        assert!(e.contains("dir/NLA_1.LBL") && e.contains("CAHVORE") && e.contains("tubeloc locate"), "{e}");
        let e = err(&label("CAHVOR", "").replace("MODEL_COMPONENT_3 = (512.0,1200.0,0.0)", "MODEL_COMPONENT_3 = (512.0,1200.0)"));
        assert!(e.contains("MODEL_COMPONENT_3") && e.contains("line 8"), "{e}");
        let e = err(&label("CAHV", "").replace("LINES = 1024", "LINES = 0"));
        assert!(e.contains("LINES = 0"), "{e}");
        let e = err(&label("CAHV", "").replace("GEOMETRIC_CAMERA_MODEL_PARMS", "OTHER"));
        assert!(e.contains("no GEOMETRIC_CAMERA_MODEL_PARMS"), "{e}");
        // Below the rover frame's origin: no ground under the camera.
        let e = err(&label("CAHV", "").replace("(0.8,0.3,-1.95)", "(0.8,0.3,0.5)"));
        assert!(e.contains("camera_height_m"), "{e}");
    }
}
