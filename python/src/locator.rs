//! `tubeloc.Locator`, `detect` and `refine`: the pipeline of `tubeloc locate`, `tubeloc
//! detect` and `tubeloc refine` on numpy images, built with the CLI's defaults.

use crate::error::{chain_to_py, context_to_py, to_py};
use crate::image_array::image_of;
use crate::poses::PyTube;
use crate::rig::rig_of;
use nalgebra::Vector3;
use pyo3::prelude::*;
use std::path::PathBuf;
use std::sync::{Mutex, RwLock};
use tubeloc_core::{GroundPlane, Rig, TubeDetection};
use tubeloc_pipeline::{shipped, CameraSelection, ExternalDetections, LocateInput, Locator, LocatorSettings, Timings, TubeDetector};

/// The locator's options as the CLI's flags (`tubeloc locate --detector ... --model ...`).
struct Options<'a> {
    detector: &'a str,
    model: Option<PathBuf>,
    templates: Option<PathBuf>,
    calibration: Option<PathBuf>,
    min_probability: Option<f64>,
    min_highlight_level: Option<f64>,
    min_pose_evidence: Option<f64>,
    max_limb_continuation: Option<f64>,
    range_m: &'a str,
}

/// The detector of `tubeloc locate --detector NAME` with the options.
fn detector_of(o: &Options) -> PyResult<Box<dyn TubeDetector>> {
    Ok(match o.detector {
        "learned" => Box::new(shipped::learned_detector(o.model.as_deref(), o.range_m).map_err(|e| chain_to_py(&e))?),
        "line2d" => Box::new(shipped::line2d_detector(o.templates.as_deref(), Some("shipped")).map_err(|e| chain_to_py(&e))?),
        "fused" => Box::new(shipped::fused_detector(o.templates.as_deref(), o.model.as_deref(), o.range_m).map_err(|e| chain_to_py(&e))?),
        "external" => return Err(to_py("detector \"external\": detections made elsewhere are refined with tubeloc.refine(image, detections, rig)")),
        other => return Err(to_py(format!("detector {other:?}: expected \"learned\", \"line2d\" or \"fused\""))),
    })
}

/// The settings of `tubeloc locate` with the options: the defaults, the score calibration
/// (given, or the learned model's), the acceptance threshold, the pose-evidence floor.
fn settings_of(o: &Options) -> PyResult<LocatorSettings> {
    let floor = o.min_pose_evidence.unwrap_or(tubeloc_pipeline::settings::DEFAULT_MIN_POSE_EVIDENCE);
    let mut settings = shipped::locate_settings(o.detector, o.calibration.as_deref(), o.model.as_deref(), floor).map_err(|e| chain_to_py(&e))?;
    if let Some(p) = o.min_probability {
        if !(0.0..=1.0).contains(&p) {
            return Err(to_py(format!("min_probability {p}: expected a probability in [0, 1]")));
        }
        settings.calibration.threshold = p;
    }
    if let Some(v) = o.min_highlight_level {
        if !(0.0..=255.0).contains(&v) {
            return Err(to_py(format!("min_highlight_level {v}: expected a grey level in [0, 255]")));
        }
        settings.min_highlight_level = v;
    }
    match o.max_limb_continuation {
        None => {}
        Some(0.0) => settings.max_limb_continuation = None,
        Some(c) if c.is_finite() && c > 0.0 => settings.max_limb_continuation = Some(c),
        Some(c) => return Err(to_py(format!("max_limb_continuation {c}: expected a positive number, or 0 for no such check"))),
    }
    Ok(settings)
}

/// A ground plane argument: a string "nx,ny,nz,d" or four numbers (camera frame, `n·X = d`, n
/// up, metres), parsed as `--ground` is.
fn ground_of(obj: Option<&Bound<'_, PyAny>>) -> PyResult<Option<GroundPlane>> {
    let Some(obj) = obj.filter(|o| !o.is_none()) else { return Ok(None) };
    let text = match obj.extract::<String>() {
        Ok(s) => s,
        Err(_) => {
            let v: Vec<f64> = obj.extract().map_err(|_| to_py("ground: expected \"nx,ny,nz,d\" or four numbers"))?;
            v.iter().map(f64::to_string).collect::<Vec<_>>().join(",")
        }
    };
    text.parse::<GroundPlane>().map(Some).map_err(|e| chain_to_py(&e))
}

/// An up direction argument (three numbers, camera frame), checked and normalized as `--up` is.
fn up_of(up: Option<Vec<f64>>) -> PyResult<Option<Vector3<f64>>> {
    let Some(v) = up else { return Ok(None) };
    let s = v.iter().map(f64::to_string).collect::<Vec<_>>().join(",");
    if v.len() != 3 || v.iter().any(|x| !x.is_finite()) {
        return Err(to_py(format!("up {s:?}: expected three finite numbers ux,uy,uz")));
    }
    let n = Vector3::new(v[0], v[1], v[2]);
    if n.norm() < 1e-9 {
        return Err(to_py(format!("up {s:?}: the vector is zero")));
    }
    Ok(Some(n.normalize()))
}

/// The camera selection of `--camera-name` and `--pair`.
fn selection_of(camera: Option<String>, pair: Option<(String, String)>) -> CameraSelection {
    CameraSelection { camera, pair }
}

/// Where the rig came from, for the CLI's "RIG: message" errors.
fn rig_origin(obj: &Bound<'_, PyAny>) -> String {
    obj.extract::<PathBuf>().map(|p| p.display().to_string()).unwrap_or_else(|_| "rig".into())
}

fn build(rig: &Rig, origin: &str, selection: &CameraSelection, detector: Box<dyn TubeDetector>, settings: LocatorSettings) -> PyResult<Locator> {
    Locator::new(rig, selection, detector, settings).map_err(|e| context_to_py(origin, &e))
}

/// Detections as a list of dicts in the JSON form of `tubeloc detect`'s output.
fn detections_to_py<'py>(py: Python<'py>, dets: &[TubeDetection]) -> PyResult<Bound<'py, PyAny>> {
    let text = serde_json::to_string(dets).map_err(to_py)?;
    py.import("json")?.call_method1("loads", (text,))
}

/// Detections from a list of dicts (COCO results with tubeloc's seed fields), read and checked
/// as `tubeloc refine --detections` reads its file.
fn detections_from_py(py: Python<'_>, obj: &Bound<'_, PyAny>) -> PyResult<Vec<TubeDetection>> {
    let text: String = py.import("json")?.call_method1("dumps", (obj,)).map_err(|e| to_py(format!("detections: not JSON-serializable: {e}")))?.extract()?;
    tubeloc_core::detection::parse_coco_results(text.as_bytes(), std::path::Path::new("detections")).map_err(|e| chain_to_py(&e))
}

/// Finds sample tubes in images of one rig camera (or stereo pair): detect, (stereo,) refine,
/// the stages after the fit, duplicate merging and grasp frames -- `tubeloc locate`'s pipeline.
///
/// Locator(rig, detector="learned", model=None, templates=None, camera=None, pair=None,
///         calibration=None, min_probability=None, range_m="1:4", min_highlight_level=None,
///         min_pose_evidence=None, max_limb_continuation=None)
///
/// rig: a tubeloc.Rig or the path of a rig file. detector: "learned" (model: weights file,
/// default the shipped model), "line2d" (templates: a .tlt library, default the default library
/// built in memory) or "fused" (the learned detections and Line2D's pose-verified ones, by pose
/// evidence; templates and model). camera:
/// the rig camera of the (left) images; pair: (left, right) camera names. calibration: score
/// calibration JSON (default: the learned model's); min_probability: acceptance threshold
/// (default: the calibration's). range_m: distances of the tubes "NEAR:FAR" metres, or "off".
/// min_highlight_level: no tube is located in an underexposed frame, whose highlights (99th
/// percentile of its 8-bit grey levels) lie below this (default 48, as `tubeloc locate
/// --min-highlight-level`; 0: off). min_pose_evidence: a learned detection's tube is handed
/// over only where the probability that its pose is a tube (the model's pose evidence: score
/// and the fit's evidence) reaches this (default 0.3, as `tubeloc locate --min-pose-evidence`;
/// 0: off); below it the tube is rejected as "weak_pose_evidence". max_limb_continuation: a
/// tube is handed over only where the edges along its limbs go on past its ends by at most
/// this much, against along its body (a rim or a layer of rock goes on, a tube ends; default
/// 0.6, as `tubeloc locate --max-limb-continuation`; 0: off); beyond it the tube is rejected as
/// "limbs_continue".
#[pyclass(name = "Locator", module = "tubeloc", frozen)]
pub struct PyLocator {
    /// Read-locked by every call, write-locked by `select_camera`.
    locator: RwLock<Locator>,
    min_probability: f64,
    /// Stage timings of the last `locate` call, measured inside the Rust pipeline.
    last_timings: Mutex<Option<Timings>>,
}

#[pymethods]
impl PyLocator {
    #[new]
    #[pyo3(signature = (rig, detector = "learned", model = None, templates = None, camera = None, pair = None, calibration = None, min_probability = None, range_m = "1:4", min_highlight_level = None, min_pose_evidence = None, max_limb_continuation = None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        rig: &Bound<'_, PyAny>,
        detector: &str,
        model: Option<PathBuf>,
        templates: Option<PathBuf>,
        camera: Option<String>,
        pair: Option<(String, String)>,
        calibration: Option<PathBuf>,
        min_probability: Option<f64>,
        range_m: &str,
        min_highlight_level: Option<f64>,
        min_pose_evidence: Option<f64>,
        max_limb_continuation: Option<f64>,
    ) -> PyResult<Self> {
        let origin = rig_origin(rig);
        let rig = rig_of(rig)?;
        let o = Options { detector, model, templates, calibration, min_probability, min_highlight_level, min_pose_evidence, max_limb_continuation, range_m };
        let (locator, min_probability) = py.detach(|| -> PyResult<(Locator, f64)> {
            let det = detector_of(&o)?;
            let settings = settings_of(&o)?;
            let threshold = settings.calibration.threshold;
            Ok((build(&rig, &origin, &selection_of(camera, pair), det, settings)?, threshold))
        })?;
        Ok(PyLocator { locator: RwLock::new(locator), min_probability, last_timings: Mutex::new(None) })
    }

    /// locate(left, right=None, ground=None, up=None, ignore_mask=None) -> list[Tube]
    ///
    /// The tubes in `left` (a numpy image of the locator's camera; with `right`, the right
    /// image of the pair adds stereo): located tubes best score first, then the rejected
    /// detections (`status` says why), as in `tubeloc locate`'s poses file. ground: the ground
    /// plane "nx,ny,nz,d" or four numbers (camera frame, n·X = d, n up, metres); up: the up
    /// direction (three numbers, camera frame) for the grasp when there is no ground.
    /// ignore_mask: where no tube is handed over (rover hardware in view): a uint8 or uint16
    /// array of `left`'s size, in its pixels, non-zero where ignored (`read_image` reads a
    /// mask file; for a fisheye product, draw it on the image `read_product` returns); a tube
    /// whose centre falls there gets status `in_ignored_region`. A frame whose tubes are
    /// too narrow for the detector at their expected range (a coarse or binned image, a
    /// distant view) raises a `UserWarning` saying so, as `tubeloc locate` prints it.
    #[pyo3(signature = (left, right = None, ground = None, up = None, ignore_mask = None))]
    fn locate<'py>(&self, py: Python<'py>, left: &Bound<'py, PyAny>, right: Option<&Bound<'py, PyAny>>, ground: Option<&Bound<'py, PyAny>>, up: Option<Vec<f64>>, ignore_mask: Option<&Bound<'py, PyAny>>) -> PyResult<Vec<PyTube>> {
        let image = image_of(left, "left")?;
        let right = right.filter(|r| !r.is_none()).map(|r| image_of(r, "right")).transpose()?;
        let ignore = ignore_mask.filter(|m| !m.is_none()).map(|m| image_of(m, "ignore_mask").map(|i| tubeloc_pipeline::ignore_mask_of(&i))).transpose()?;
        let input = LocateInput { image: &image, right: right.as_ref(), ground: ground_of(ground)?, up: up_of(up)?, ignore: ignore.as_ref() };
        let found = py.detach(|| self.read().locate(&input)).map_err(|e| chain_to_py(&e))?;
        *self.last_timings.lock().unwrap_or_else(|e| e.into_inner()) = Some(found.timings.clone());
        for w in &found.warnings {
            let msg = std::ffi::CString::new(w.as_str()).unwrap_or_default();
            PyErr::warn(py, &py.get_type::<pyo3::exceptions::PyUserWarning>(), &msg, 1)?;
        }
        Ok(found.tubes.iter().map(|t| PyTube::from_located(py, t, "located")).chain(found.rejected.iter().map(|r| PyTube::from_located(py, &r.tube, r.reason.name()))).collect())
    }

    /// detect(image, ground=None) -> list[dict]
    ///
    /// The locator's detections in `image` (COCO results with tubeloc's seed fields, as
    /// `tubeloc detect` writes them; image id 0).
    #[pyo3(signature = (image, ground = None))]
    fn detect<'py>(&self, py: Python<'py>, image: &Bound<'py, PyAny>, ground: Option<&Bound<'py, PyAny>>) -> PyResult<Bound<'py, PyAny>> {
        let image = image_of(image, "image")?;
        let ground = ground_of(ground)?;
        let dets = py.detach(|| self.read().detect(&image, ground.as_ref())).map_err(|e| chain_to_py(&e))?;
        detections_to_py(py, &dets)
    }

    /// refine(image, detections, right=None, ground=None) -> list[Tube]
    ///
    /// One pose per detection, in order (no merging, no grasp frames), refined with the
    /// locator's settings.
    #[pyo3(signature = (image, detections, right = None, ground = None))]
    fn refine<'py>(&self, py: Python<'py>, image: &Bound<'py, PyAny>, detections: &Bound<'py, PyAny>, right: Option<&Bound<'py, PyAny>>, ground: Option<&Bound<'py, PyAny>>) -> PyResult<Vec<PyTube>> {
        refine_with(py, &self.read(), image, detections, right, ground)
    }

    /// select_camera(name)
    ///
    /// Takes the next images with rig camera `name` (e.g. the next frame's camera of a PDS
    /// camera list, whose ground `read_pds_grounds` gives); the detector stays loaded.
    fn select_camera(&self, py: Python<'_>, name: &str) -> PyResult<()> {
        py.detach(|| self.locator.write().unwrap_or_else(|e| e.into_inner()).select_camera(name)).map_err(|e| chain_to_py(&e))
    }

    /// The rig camera the (left) images come from.
    #[getter]
    fn camera(&self) -> String {
        self.read().camera().name.clone()
    }

    /// The detector's name (`learned`, `line2d`, `fused`).
    #[getter]
    fn detector(&self) -> String {
        self.read().detector().name().to_string()
    }

    /// Wall times of the last `locate` call's stages, measured inside the pipeline (seconds;
    /// `fit_ms`: each detection's fit, milliseconds), or None before the first call:
    /// {"detect_s", "refine_s", "total_s", "fit_ms"}.
    #[getter]
    fn last_timings<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        let t = self.last_timings.lock().unwrap_or_else(|e| e.into_inner()).clone();
        t.map(|t| py.import("json")?.call_method1("loads", (serde_json::to_string(&t).map_err(to_py)?,))).transpose()
    }

    /// The probability threshold tubes are accepted at.
    #[getter]
    fn min_probability(&self) -> f64 {
        self.min_probability
    }

    fn __repr__(&self) -> String {
        format!("tubeloc.Locator(camera={:?}, detector={:?}, min_probability={})", self.camera(), self.detector(), self.min_probability)
    }
}

impl PyLocator {
    fn read(&self) -> std::sync::RwLockReadGuard<'_, Locator> {
        self.locator.read().unwrap_or_else(|e| e.into_inner())
    }
}

fn refine_with<'py>(py: Python<'py>, locator: &Locator, image: &Bound<'py, PyAny>, detections: &Bound<'py, PyAny>, right: Option<&Bound<'py, PyAny>>, ground: Option<&Bound<'py, PyAny>>) -> PyResult<Vec<PyTube>> {
    let image = image_of(image, "image")?;
    let right = right.filter(|r| !r.is_none()).map(|r| image_of(r, "right")).transpose()?;
    let dets = detections_from_py(py, detections)?;
    let input = LocateInput { image: &image, right: right.as_ref(), ground: ground_of(ground)?, up: None, ignore: None };
    let (poses, _) = py.detach(|| locator.refine(&input, &dets)).map_err(|e| chain_to_py(&e))?;
    Ok(poses.iter().map(|p| PyTube::from_pose(py, p)).collect())
}

/// detect(image, rig, detector="learned", model=None, templates=None, camera=None,
///        ground=None, range_m="1:4") -> list[dict]
///
/// Tubes detected in `image` (a numpy image of the rig camera `camera`, default the rig's
/// first pair's left camera or first camera) as COCO results with tubeloc's seed fields (the
/// entries `tubeloc detect` writes; image id 0).
#[pyfunction]
#[pyo3(signature = (image, rig, detector = "learned", model = None, templates = None, camera = None, ground = None, range_m = "1:4"))]
#[allow(clippy::too_many_arguments)]
pub fn detect<'py>(
    py: Python<'py>,
    image: &Bound<'py, PyAny>,
    rig: &Bound<'py, PyAny>,
    detector: &str,
    model: Option<PathBuf>,
    templates: Option<PathBuf>,
    camera: Option<String>,
    ground: Option<&Bound<'py, PyAny>>,
    range_m: &str,
) -> PyResult<Bound<'py, PyAny>> {
    let origin = rig_origin(rig);
    let rig = rig_of(rig)?;
    let o = Options { detector, model, templates, calibration: None, min_probability: None, min_highlight_level: None, min_pose_evidence: None, max_limb_continuation: None, range_m };
    let det = py.detach(|| detector_of(&o))?;
    let locator = build(&rig, &origin, &selection_of(camera, None), det, LocatorSettings::default())?;
    let image = image_of(image, "image")?;
    let ground = ground_of(ground)?;
    let dets = py.detach(|| locator.detect(&image, ground.as_ref())).map_err(|e| chain_to_py(&e))?;
    detections_to_py(py, &dets)
}

/// refine(image, detections, rig, right=None, ground=None, camera=None, pair=None) -> list[Tube]
///
/// Refines detections (a list of dicts: COCO results with tubeloc's seed fields, as `detect`
/// returns or `tubeloc detect` writes) into tube poses in `image`'s camera frame, one per
/// detection, in order -- `tubeloc refine`'s work with its default settings. With `right`, the
/// rig's pair (`pair`, default its first) adds stereo.
#[pyfunction]
#[pyo3(signature = (image, detections, rig, right = None, ground = None, camera = None, pair = None))]
#[allow(clippy::too_many_arguments)]
pub fn refine<'py>(
    py: Python<'py>,
    image: &Bound<'py, PyAny>,
    detections: &Bound<'py, PyAny>,
    rig: &Bound<'py, PyAny>,
    right: Option<&Bound<'py, PyAny>>,
    ground: Option<&Bound<'py, PyAny>>,
    camera: Option<String>,
    pair: Option<(String, String)>,
) -> PyResult<Vec<PyTube>> {
    let origin = rig_origin(rig);
    let rig = rig_of(rig)?;
    let mut settings = LocatorSettings::default();
    settings.merge_duplicates = false;
    let locator = build(&rig, &origin, &selection_of(camera, pair), Box::new(ExternalDetections::new(Vec::new(), "detections")), settings)?;
    refine_with(py, &locator, image, detections, right, ground)
}
