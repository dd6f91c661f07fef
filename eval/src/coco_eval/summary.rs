//! The 12-number summary and its text, as pycocotools' `COCOeval.summarize` prints it.

use super::params::{iou_thresholds, AREA_LABELS, MAX_DETS};
use super::EvalResult;

/// One line of the summary: AP or AR, an IoU threshold (None = 0.50:0.95), area and maxDets.
#[derive(Clone, Copy, Debug)]
pub struct StatSpec {
    /// True for average precision, false for average recall.
    pub ap: bool,
    /// Index into the IoU thresholds, or None for the mean over all ten.
    pub iou_index: Option<usize>,
    /// Index into the area ranges (0 all, 1 small, 2 medium, 3 large).
    pub area_index: usize,
    /// Index into `MAX_DETS` (0: 1, 1: 10, 2: 100).
    pub max_det_index: usize,
    /// Short name used in JSON: `AP`, `AP50`, ..., `AR_large`.
    pub name: &'static str,
}

const fn spec(ap: bool, iou_index: Option<usize>, area_index: usize, max_det_index: usize, name: &'static str) -> StatSpec {
    StatSpec { ap, iou_index, area_index, max_det_index, name }
}

/// The 12 statistics in pycocotools' order (`_summarizeDets`).
pub const STATS: [StatSpec; 12] = [
    spec(true, None, 0, 2, "AP"),
    spec(true, Some(0), 0, 2, "AP50"),
    spec(true, Some(5), 0, 2, "AP75"),
    spec(true, None, 1, 2, "AP_small"),
    spec(true, None, 2, 2, "AP_medium"),
    spec(true, None, 3, 2, "AP_large"),
    spec(false, None, 0, 0, "AR1"),
    spec(false, None, 0, 1, "AR10"),
    spec(false, None, 0, 2, "AR100"),
    spec(false, None, 1, 2, "AR_small"),
    spec(false, None, 2, 2, "AR_medium"),
    spec(false, None, 3, 2, "AR_large"),
];

/// Computes one statistic: the mean of the defined (> -1) entries of the precision (or recall)
/// slice, or -1 when none is defined. The sum is numpy's pairwise summation, so the value is
/// bit-identical to `np.mean(s[s > -1])`.
pub(crate) fn stat(res: &EvalResult, s: &StatSpec) -> f64 {
    let t_range: Vec<usize> = match s.iou_index {
        Some(t) => vec![t],
        None => (0..res.iou_thrs.len()).collect(),
    };
    let k_n = res.cat_ids.len();
    let mut vals = Vec::new();
    for &t in &t_range {
        if s.ap {
            for r in 0..res.rec_thrs.len() {
                for k in 0..k_n {
                    vals.push(res.precision_at(t, r, k, s.area_index, s.max_det_index));
                }
            }
        } else {
            for k in 0..k_n {
                vals.push(res.recall_at(t, k, s.area_index, s.max_det_index));
            }
        }
    }
    vals.retain(|&v| v > -1.0);
    if vals.is_empty() {
        -1.0
    } else {
        pairwise_sum(&vals) / vals.len() as f64
    }
}

/// numpy's pairwise summation of float64 (`pairwise_sum` in `loops_utils.h`): blocks of at
/// most 128 summed with 8 accumulators, larger arrays split in halves rounded to 8.
pub fn pairwise_sum(a: &[f64]) -> f64 {
    let n = a.len();
    if n < 8 {
        a.iter().fold(0.0, |s, &v| s + v)
    } else if n <= 128 {
        let mut r = [0.0; 8];
        r.copy_from_slice(&a[..8]);
        let mut i = 8;
        while i < n - n % 8 {
            for j in 0..8 {
                r[j] += a[i + j];
            }
            i += 8;
        }
        let mut res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        while i < n {
            res += a[i];
            i += 1;
        }
        res
    } else {
        let mut n2 = n / 2;
        n2 -= n2 % 8;
        pairwise_sum(&a[..n2]) + pairwise_sum(&a[n2..])
    }
}

/// One summary line, formatted exactly as pycocotools:
/// `' {:<18} {} @[ IoU={:<9} | area={:>6s} | maxDets={:>3d} ] = {:0.3f}'`.
pub(crate) fn line(s: &StatSpec, value: f64) -> String {
    let thrs = iou_thresholds();
    let title = if s.ap { "Average Precision" } else { "Average Recall" };
    let kind = if s.ap { "(AP)" } else { "(AR)" };
    let iou = match s.iou_index {
        Some(t) => format!("{:.2}", thrs[t]),
        None => format!("{:.2}:{:.2}", thrs[0], thrs[thrs.len() - 1]),
    };
    format!(" {:<18} {} @[ IoU={:<9} | area={:>6} | maxDets={:>3} ] = {:.3}", title, kind, iou, AREA_LABELS[s.area_index], MAX_DETS[s.max_det_index], value)
}
