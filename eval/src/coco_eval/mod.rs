//! COCO detection/segmentation evaluation with the semantics of pycocotools' `COCOeval`
//! (`evaluate`, `accumulate`, `summarize`), in every detail that changes a number:
//!
//! - results are read as `loadRes` reads them: ids `1 + index`, `iscrowd = 0`; if the first
//!   result has a `bbox`, every result's area is `w * h` and a missing mask is the box polygon,
//!   otherwise areas come from the masks and missing boxes from the masks' extents;
//! - per (image, category), detections are stably sorted by descending score and capped at 100;
//!   ground truth flagged `iscrowd` is ignored and matches any number of detections with
//!   IoU `|d ∩ g| / |d|`; ground truth outside an area range (by its `area` field) is ignored;
//! - greedy matching at each of the ten IoU thresholds, 101-point interpolated precision,
//!   -1 for undefined entries, categories evaluated separately (`useCats = 1`).
//!
//! Deviations (only where pycocotools fails): an empty results list gives zero AP/AR instead of
//! an exception; polygon or uncompressed-RLE result masks are accepted; duplicate annotation ids
//! are refused. Results with a category absent from the ground truth are ignored, as there.

mod accumulate;
pub mod bootstrap;
mod matching;
pub mod params;
mod prepare;
pub mod summary;

pub use params::{iou_thresholds, recall_thresholds, IouType, AREA_LABELS, AREA_RNGS, MAX_DETS};
pub use summary::{pairwise_sum, StatSpec, STATS};

use params::{NUM_IOU_THRS, NUM_REC_THRS};
use rayon::prelude::*;
use serde_json::{json, Value};
use tubeloc_core::{CocoDataset, CocoResult, CoreError};

/// An evaluation error; entry errors name the list entry (`results[12] (image_id 4)`).
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// A ground-truth or result entry cannot be evaluated.
    #[error("{entry}: {message}")]
    Entry {
        /// Which entry, e.g. `annotations[3] (id 17)`.
        entry: String,
        /// What is wrong.
        message: String,
    },
    /// An error from the core types (file reading, RLE decoding).
    #[error(transparent)]
    Core(#[from] CoreError),
}

impl EvalError {
    pub(crate) fn entry(entry: impl Into<String>, message: impl Into<String>) -> Self {
        EvalError::Entry { entry: entry.into(), message: message.into() }
    }
}

/// A prepared COCO evaluation: masks decoded and IoUs computed once, so that several
/// evaluations (all images, per-attribute subsets) reuse them.
pub struct CocoEvaluator {
    iou_type: IouType,
    prep: prepare::Prepared,
}

impl CocoEvaluator {
    /// Prepares ground truth `gt` and detections `dt` (several shards may simply be
    /// concatenated) for `iou_type`. Fails on unknown image ids, duplicate annotation ids,
    /// missing or malformed masks, naming the entry.
    pub fn new(gt: &CocoDataset, dt: &[CocoResult], iou_type: IouType) -> Result<Self, EvalError> {
        Ok(CocoEvaluator { iou_type, prep: prepare::prepare(gt, dt, iou_type)? })
    }

    /// Sorted ground-truth image ids.
    pub fn image_ids(&self) -> &[u64] {
        &self.prep.img_ids
    }

    /// Every detection's outcome at IoU 0.5 (area "all", at most 100 detections per image,
    /// COCO's greedy matching): `(image_id, score, true positive)`. Detections matched to
    /// ignored (crowd) ground truth are left out. This is what a score's calibration is fitted
    /// on ([`crate::calibration`]).
    pub fn outcomes_at_iou50(&self) -> Vec<(u64, f64, bool)> {
        let p = &self.prep;
        let k_n = p.cat_ids.len();
        let iou_thrs = iou_thresholds();
        let all = AREA_RNGS[0];
        let mut out = Vec::new();
        for (i, &img) in p.img_ids.iter().enumerate() {
            for k in 0..k_n {
                let Some(e) = matching::evaluate_cell(&p.cells[i * k_n + k], all, &iou_thrs, &|_| false) else { continue };
                for (d, &score) in e.dt_scores.iter().enumerate() {
                    if !e.dt_ignore[d] {
                        out.push((img, score, e.dt_matched[d] != 0));
                    }
                }
            }
        }
        out
    }

    /// Evaluates all images.
    pub fn evaluate(&self) -> EvalResult {
        self.evaluate_with(&|_| true, &|_| false)
    }

    /// Evaluates the images for which `keep_image(image_id)` holds (pycocotools with
    /// `params.imgIds` set to them), additionally ignoring ground truth for which
    /// `ignore_gt(annotation_index)` holds (like an area range: detections matched to it are
    /// ignored too). `annotation_index` indexes `CocoDataset::annotations`.
    pub fn evaluate_with(&self, keep_image: &(dyn Fn(u64) -> bool + Sync), ignore_gt: &(dyn Fn(usize) -> bool + Sync)) -> EvalResult {
        let p = &self.prep;
        let k_n = p.cat_ids.len();
        let a_n = AREA_RNGS.len();
        let iou_thrs = iou_thresholds();
        let rec_thrs = recall_thresholds();
        let images: Vec<usize> = (0..p.img_ids.len()).filter(|&i| keep_image(p.img_ids[i])).collect();
        // evals[s][k * A + a] for the s-th selected image.
        let evals: Vec<Vec<Option<matching::ImgEval>>> = images
            .par_iter()
            .map(|&i| {
                let mut out = Vec::with_capacity(k_n * a_n);
                for k in 0..k_n {
                    for rng in AREA_RNGS.iter() {
                        out.push(matching::evaluate_cell(&p.cells[i * k_n + k], *rng, &iou_thrs, ignore_gt));
                    }
                }
                out
            })
            .collect();

        let (m_n, r_n, t_n) = (MAX_DETS.len(), NUM_REC_THRS, NUM_IOU_THRS);
        let combos: Vec<(usize, usize, usize)> = (0..k_n).flat_map(|k| (0..a_n).flat_map(move |a| (0..m_n).map(move |m| (k, a, m)))).collect();
        let slices: Vec<_> = combos
            .par_iter()
            .map(|&(k, a, m)| {
                let e: Vec<&matching::ImgEval> = evals.iter().filter_map(|v| v[k * a_n + a].as_ref()).collect();
                accumulate::accumulate_slice(&e, MAX_DETS[m], &rec_thrs)
            })
            .collect();
        let mut precision = vec![-1.0; t_n * r_n * k_n * a_n * m_n];
        let mut recall = vec![-1.0; t_n * k_n * a_n * m_n];
        for (&(k, a, m), slice) in combos.iter().zip(slices) {
            let Some((pr, rc)) = slice else { continue };
            for t in 0..t_n {
                recall[((t * k_n + k) * a_n + a) * m_n + m] = rc[t];
                for r in 0..r_n {
                    precision[(((t * r_n + r) * k_n + k) * a_n + a) * m_n + m] = pr[t][r];
                }
            }
        }
        let mut res = EvalResult { iou_type: self.iou_type, iou_thrs: iou_thrs.to_vec(), rec_thrs: rec_thrs.to_vec(), cat_ids: p.cat_ids.clone(), num_images: images.len(), stats: [0.0; 12], precision, recall };
        for (i, s) in STATS.iter().enumerate() {
            res.stats[i] = summary::stat(&res, s);
        }
        res
    }
}

/// The outcome of an evaluation: pycocotools' `eval['precision']`, `eval['recall']` and `stats`.
#[derive(Clone, Debug, PartialEq)]
pub struct EvalResult {
    /// IoU type evaluated.
    pub iou_type: IouType,
    /// The ten IoU thresholds 0.50, 0.55, ..., 0.95.
    pub iou_thrs: Vec<f64>,
    /// The 101 recall thresholds 0.00, 0.01, ..., 1.00.
    pub rec_thrs: Vec<f64>,
    /// Sorted category ids (axis K).
    pub cat_ids: Vec<u64>,
    /// Number of images evaluated.
    pub num_images: usize,
    /// The 12 summary numbers in pycocotools' order (see [`STATS`]); -1 when undefined.
    pub stats: [f64; 12],
    /// Precision, shape T x R x K x A x M (IoU, recall threshold, category, area, maxDets),
    /// row-major like numpy; -1 where there is no ground truth.
    pub precision: Vec<f64>,
    /// Recall, shape T x K x A x M; -1 where there is no ground truth.
    pub recall: Vec<f64>,
}

impl EvalResult {
    /// `precision[t, r, k, a, m]`.
    pub fn precision_at(&self, t: usize, r: usize, k: usize, a: usize, m: usize) -> f64 {
        let (rn, kn, an, mn) = (self.rec_thrs.len(), self.cat_ids.len(), AREA_RNGS.len(), MAX_DETS.len());
        self.precision[(((t * rn + r) * kn + k) * an + a) * mn + m]
    }

    /// `recall[t, k, a, m]`.
    pub fn recall_at(&self, t: usize, k: usize, a: usize, m: usize) -> f64 {
        let (kn, an, mn) = (self.cat_ids.len(), AREA_RNGS.len(), MAX_DETS.len());
        self.recall[((t * kn + k) * an + a) * mn + m]
    }

    /// The 101-point interpolated PR curve at IoU threshold index `t` (0 = 0.50, 9 = 0.95) for
    /// area "all" and 100 detections: precision at recall `0.00, 0.01, ..., 1.00`, averaged over
    /// the categories where it is defined (-1 where no category has ground truth).
    pub fn pr_curve(&self, t: usize) -> [f64; 101] {
        let mut out = [-1.0; 101];
        for (r, v) in out.iter_mut().enumerate() {
            let vals: Vec<f64> = (0..self.cat_ids.len()).map(|k| self.precision_at(t, r, k, 0, 2)).filter(|&p| p > -1.0).collect();
            if !vals.is_empty() {
                *v = vals.iter().sum::<f64>() / vals.len() as f64;
            }
        }
        out
    }

    /// Recall at IoU threshold index `t`, area "all", 100 detections, averaged over categories
    /// with ground truth (-1 if none).
    pub fn recall_all(&self, t: usize) -> f64 {
        let vals: Vec<f64> = (0..self.cat_ids.len()).map(|k| self.recall_at(t, k, 0, 2)).filter(|&v| v > -1.0).collect();
        if vals.is_empty() {
            -1.0
        } else {
            vals.iter().sum::<f64>() / vals.len() as f64
        }
    }

    /// The summary exactly as pycocotools' `summarize()` prints it: 12 lines, each ending in `\n`.
    pub fn summary_text(&self) -> String {
        STATS.iter().zip(self.stats).map(|(s, v)| summary::line(s, v) + "\n").collect()
    }

    /// `metrics.json`: the 12 numbers with names, the PR curves (one per IoU threshold, area
    /// all, maxDets 100) and the recall per IoU threshold.
    pub fn to_json(&self) -> Value {
        let stats: Vec<Value> = STATS.iter().zip(self.stats).map(|(s, v)| json!({"name": s.name, "value": v, "line": summary::line(s, v).trim_start()})).collect();
        json!({
            "iou_type": self.iou_type.name(),
            "num_images": self.num_images,
            "category_ids": self.cat_ids,
            "stats": stats,
            "pr_curves": {
                "area": "all", "max_dets": 100,
                "iou_thresholds": self.iou_thrs,
                "recall_thresholds": self.rec_thrs,
                "precision": (0..self.iou_thrs.len()).map(|t| self.pr_curve(t).to_vec()).collect::<Vec<_>>(),
                "recall": (0..self.iou_thrs.len()).map(|t| self.recall_all(t)).collect::<Vec<_>>(),
            },
        })
    }
}
