//! `tubeloc.coco_eval`: COCO detection metrics, the numbers pycocotools gives.

use crate::error::{context_to_py, to_py};
use numpy::PyArray1;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;
use tubeloc_core::CocoDataset;
use tubeloc_eval::coco_eval::{CocoEvaluator, IouType};

/// coco_eval(gt_json_path, results_json_path, iou_type="segm") -> dict
///
/// COCO evaluation of detections (a COCO results JSON file) against a COCO dataset JSON file,
/// as `tubeloc eval` runs it: a dict with `stats` (numpy array of the 12 numbers of
/// pycocotools' `COCOeval.stats`: AP, AP50, AP75, AP small/medium/large, AR1, AR10, AR100, AR
/// small/medium/large) and `summary` (the 12 lines pycocotools prints). iou_type: "segm"
/// (mask IoU) or "bbox".
#[pyfunction]
#[pyo3(signature = (gt_json_path, results_json_path, iou_type = "segm"))]
pub fn coco_eval<'py>(py: Python<'py>, gt_json_path: PathBuf, results_json_path: PathBuf, iou_type: &str) -> PyResult<Bound<'py, PyDict>> {
    let iou: IouType = iou_type.parse().map_err(to_py)?;
    let result = py.detach(|| -> PyResult<_> {
        let gt = CocoDataset::load(&gt_json_path).map_err(|e| context_to_py(format!("loading ground truth {}", gt_json_path.display()), &e))?;
        let dt = tubeloc_core::coco::load_results(&results_json_path, &gt).map_err(|e| context_to_py(format!("loading results {}", results_json_path.display()), &e))?;
        let evaluator = CocoEvaluator::new(&gt, &dt, iou).map_err(|e| context_to_py("preparing the evaluation", &e))?;
        Ok(evaluator.evaluate())
    })?;
    let out = PyDict::new(py);
    out.set_item("stats", PyArray1::from_slice(py, &result.stats))?;
    out.set_item("summary", result.summary_text())?;
    out.set_item("iou_type", iou.name())?;
    Ok(out)
}
