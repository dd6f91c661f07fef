//! `tubeloc.Rig`, `read_rig` and `write_rig`: rig files as Python objects. A file is tubeloc
//! JSON (the format `tubeloc --rig` reads), or OpenCV FileStorage YAML when its name ends in
//! `.yaml` or `.yml` (the second file `tubeloc calib rig` writes).

use crate::error::{chain_to_py, context_to_py, to_py};
use pyo3::prelude::*;
use std::path::{Path, PathBuf};
use tubeloc_core::Rig;

/// A camera rig: calibrated cameras (intrinsics, distortion, pose in the rig frame) and the
/// stereo pairs among them. Read one with `read_rig(path)`.
#[pyclass(name = "Rig", module = "tubeloc", frozen)]
#[derive(Clone)]
pub struct PyRig {
    /// The rig.
    pub rig: Rig,
}

#[pymethods]
impl PyRig {
    /// The rig from its JSON text (the format of `tubeloc calib rig`'s rig file).
    #[staticmethod]
    fn from_json(text: &str) -> PyResult<Self> {
        let rig: Rig = serde_json::from_str(text).map_err(|e| to_py(format!("rig JSON: {e}")))?;
        rig.validate().map_err(|e| chain_to_py(&e))?;
        Ok(PyRig { rig })
    }

    /// The rig as JSON text (the rig file's format).
    fn to_json(&self) -> PyResult<String> {
        serde_json::to_string_pretty(&self.rig).map_err(to_py)
    }

    /// The names of the cameras, in the file's order.
    #[getter]
    fn camera_names(&self) -> Vec<String> {
        self.rig.cameras.iter().map(|c| c.name.clone()).collect()
    }

    /// The stereo pairs as (left, right) camera names.
    #[getter]
    fn stereo_pairs(&self) -> Vec<(String, String)> {
        self.rig.stereo_pairs.clone()
    }

    /// Image size (width, height) in pixels of the camera `name`.
    fn image_size(&self, name: &str) -> PyResult<(u32, u32)> {
        let c = self.rig.camera(name).ok_or_else(|| to_py(format!("the rig has no camera named {name:?}")))?;
        Ok((c.model.width, c.model.height))
    }

    fn __eq__(&self, other: &Self) -> bool {
        self.rig == other.rig
    }

    fn __repr__(&self) -> String {
        format!("tubeloc.Rig(cameras={:?}, stereo_pairs={:?})", self.camera_names(), self.rig.stereo_pairs)
    }
}

/// The rig of an argument: a `Rig`, or the path of a rig file (read as `tubeloc --rig` reads
/// it; errors start with "rig: PATH:" as the CLI's).
pub fn rig_of(obj: &Bound<'_, PyAny>) -> PyResult<Rig> {
    if let Ok(r) = obj.cast::<PyRig>() {
        return Ok(r.get().rig.clone());
    }
    let path: PathBuf = obj.extract().map_err(|_| to_py(format!("rig: expected a tubeloc.Rig or the path of a rig file, got {}", obj.get_type().name().map(|n| n.to_string()).unwrap_or_default())))?;
    load(&path)
}

/// Whether `path` names an OpenCV YAML file (`.yaml`, `.yml`).
fn is_yaml(path: &Path) -> bool {
    path.extension().and_then(|e| e.to_str()).is_some_and(|e| e.eq_ignore_ascii_case("yaml") || e.eq_ignore_ascii_case("yml"))
}

/// Reads the rig file at `path` as `tubeloc --rig` does (tubeloc JSON, OpenCV YAML, a kalibr
/// camchain, one ROS `camera_info`, a PDS camera list or a PDS3 label, recognised by content); errors start
/// with "rig: PATH:" as the CLI's.
pub fn load(path: &Path) -> PyResult<Rig> {
    tubeloc_calib::read_rig(path).map_err(|e| context_to_py("rig", &e))
}

/// read_rig(path) -> Rig
///
/// Reads and checks a rig file: tubeloc JSON, OpenCV YAML, a kalibr camchain, one ROS
/// `camera_info`, a PDS camera list (`cahv_to_pinhole.py`'s JSON: one camera per image,
/// named after its file, in the rover frame), or the PDS3 label of one image (`.LBL`, or an
/// `.IMG` with its label: its CAHV/CAHVOR camera, named after its PRODUCT_ID, in the rover
/// frame), recognised by content.
#[pyfunction]
pub fn read_rig(path: PathBuf) -> PyResult<PyRig> {
    Ok(PyRig { rig: load(&path)? })
}

/// read_pds_grounds(path) -> dict[str, tuple[float, float, float, float]]
///
/// The ground under each camera of a PDS camera list (`cahv_to_pinhole.py`'s JSON) or of a
/// PDS3 label (a fisheye's too: its linear camera's), by camera name (the list's image file name, the label's PRODUCT_ID): (nx, ny, nz, d) in that camera's frame, n up, n·X = d,
/// metres, as `Locator.locate(ground=...)` takes it (what `tubeloc locate` uses by itself).
/// A list's fisheye (CAHVORE) entry has its camera read from the PDS3 label it names; one whose
/// label cannot be read is left out with a `UserWarning` naming the list, the image and why
/// (`tubeloc locate` fails that frame with the same message).
#[pyfunction]
pub fn read_pds_grounds(py: Python<'_>, path: PathBuf) -> PyResult<std::collections::BTreeMap<String, (f64, f64, f64, f64)>> {
    let read = tubeloc_calib::interchange::pds::read_rig_cameras(&path).map_err(|e| chain_to_py(&e))?;
    let read = read.ok_or_else(|| to_py(format!("{}: neither a PDS camera list (a JSON list) nor a PDS3 label", path.display())))?;
    // A list's fisheye (CAHVORE) entries come read from their labels: the ground is their
    // linear camera's; those whose label cannot be read are left out, with a warning.
    for why in read.errors.values() {
        let msg = std::ffi::CString::new(format!("{why} (left out of the grounds)")).unwrap_or_default();
        PyErr::warn(py, &py.get_type::<pyo3::exceptions::PyUserWarning>(), &msg, 1)?;
    }
    let cams = read.cameras;
    Ok(cams.into_iter().map(|c| (c.camera.name, (c.ground.normal.x, c.ground.normal.y, c.ground.normal.z, c.ground.offset))).collect())
}

/// assumed_view(view, width, height) -> tuple[Rig, tuple[float, float, float, float]]
///
/// For an image without a camera model: the one-camera rig (camera "assumed") and the ground
/// (nx, ny, nz, d) of an image of width x height pixels under the assumed view `view`, as
/// `tubeloc locate --assumed-view` takes it: "navcam" (45 degree horizontal field of view,
/// 1.9 m above level ground, looking 30 degrees down), "mast" (a 20 degree field), the other
/// rover cameras' views ("m100", "m2020-navcam", "mastcam-z-F" with F the zoom in mm,
/// "mer-navcam", "mer-pancam"; `view_of_product` names a frame's), or
/// "HFOV_DEG,HEIGHT_M,PITCH_DEG" (e.g. "90,2,25").
#[pyfunction]
pub fn assumed_view(view: &str, width: u32, height: u32) -> PyResult<(PyRig, (f64, f64, f64, f64))> {
    let (rig, g) = tubeloc_core::AssumedView::parse(view).and_then(|v| v.rig("assumed", width, height)).map_err(|e| chain_to_py(&e))?;
    Ok((PyRig { rig }, (g.normal.x, g.normal.y, g.normal.z, g.offset)))
}

/// view_of_product(file_name) -> str | None
///
/// The assumed view (a name `assumed_view` takes) of the mast camera a rover image product's
/// file name names, as `tubeloc locate --assumed-view auto` reads it: e.g. "m100" for
/// "0079MR0005910210103981E01.jpg" (Curiosity Mastcam right), "mastcam-z-110" for
/// "ZL0_0053_..._110085J01.png". None where the name names no camera, or one no mast view fits
/// (a Hazcam, an arm camera); `auto` then takes "navcam" for a grey frame, "mast" for a
/// colour one.
#[pyfunction]
pub fn view_of_product(file_name: &str) -> Option<String> {
    tubeloc_core::RoverCamera::of_product(file_name).filter(|c| c.view().is_some()).map(|c| c.name())
}

/// write_rig(rig, path)
///
/// Writes a rig file, atomically: tubeloc JSON, or OpenCV YAML for a name ending in .yaml/.yml.
#[pyfunction]
pub fn write_rig(rig: &PyRig, path: PathBuf) -> PyResult<()> {
    let context = format!("writing {}", path.display());
    if is_yaml(&path) {
        tubeloc_calib::save_rig_yaml(&rig.rig, &path).map_err(|e| context_to_py(context, &e))
    } else {
        rig.rig.save_json(&path).map_err(|e| context_to_py(context, &e))
    }
}
