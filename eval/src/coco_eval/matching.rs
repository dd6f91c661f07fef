//! Greedy matching of one (image, category) cell for one area range: pycocotools'
//! `COCOeval.evaluateImg`.

use super::params::NUM_IOU_THRS;
use super::prepare::Cell;

/// Matching outcome of one cell (pycocotools' `evalImgs` entry).
#[derive(Clone, Debug)]
pub(crate) struct ImgEval {
    /// Scores of the detections, descending (at most 100).
    pub dt_scores: Vec<f64>,
    /// `dt_matched[t * D + d]`: id of the matched ground truth, 0 when unmatched.
    pub dt_matched: Vec<u64>,
    /// `dt_ignore[t * D + d]`: matched to an ignored ground truth, or unmatched and outside the
    /// area range.
    pub dt_ignore: Vec<bool>,
    /// Number of ground-truth objects that are not ignored (`gtIgnore == 0`).
    pub num_gt: usize,
}

/// Evaluates one cell. `area_rng` is inclusive; `extra_ignore(ann_index)` marks additional
/// ground truth as ignored (attribute breakdowns). Returns `None` when the cell has neither
/// ground truth nor detections.
pub(crate) fn evaluate_cell(cell: &Cell, area_rng: [f64; 2], iou_thrs: &[f64; NUM_IOU_THRS], extra_ignore: &dyn Fn(usize) -> bool) -> Option<ImgEval> {
    let (g_n, d_n) = (cell.gts.len(), cell.dts.len());
    if g_n == 0 && d_n == 0 {
        return None;
    }
    // `_ignore`: crowd (pycocotools' `ignore = iscrowd`), outside the area range, or filtered.
    let ignore: Vec<bool> = cell.gts.iter().map(|g| g.crowd || g.area < area_rng[0] || g.area > area_rng[1] || extra_ignore(g.ann_index)).collect();
    // Stable sort: non-ignored first, each group in file order.
    let gt_order: Vec<usize> = (0..g_n).filter(|&g| !ignore[g]).chain((0..g_n).filter(|&g| ignore[g])).collect();
    let gt_ig: Vec<bool> = gt_order.iter().map(|&g| ignore[g]).collect();
    let crowd: Vec<bool> = gt_order.iter().map(|&g| cell.gts[g].crowd).collect();

    let mut dt_matched = vec![0u64; NUM_IOU_THRS * d_n];
    let mut dt_ignore = vec![false; NUM_IOU_THRS * d_n];
    if !cell.ious.is_empty() {
        let mut gt_matched = vec![false; g_n];
        for (t, &thr) in iou_thrs.iter().enumerate() {
            gt_matched.iter_mut().for_each(|m| *m = false);
            for d in 0..d_n {
                let mut best_iou = thr.min(1.0 - 1e-10);
                let mut m: Option<usize> = None;
                for gi in 0..g_n {
                    // Already matched and not a crowd: skip.
                    if gt_matched[gi] && !crowd[gi] {
                        continue;
                    }
                    // Matched a regular object already and reached the ignored ones: stop.
                    if let Some(mm) = m {
                        if !gt_ig[mm] && gt_ig[gi] {
                            break;
                        }
                    }
                    let iou = cell.ious[d * g_n + gt_order[gi]];
                    if iou < best_iou {
                        continue;
                    }
                    best_iou = iou;
                    m = Some(gi);
                }
                if let Some(mm) = m {
                    dt_ignore[t * d_n + d] = gt_ig[mm];
                    dt_matched[t * d_n + d] = cell.gts[gt_order[mm]].id;
                    // pycocotools stores the detection id here, always >= 1: "matched".
                    gt_matched[mm] = true;
                }
            }
        }
    }
    // Unmatched detections outside the area range are ignored.
    for (d, dt) in cell.dts.iter().enumerate() {
        if dt.area < area_rng[0] || dt.area > area_rng[1] {
            for t in 0..NUM_IOU_THRS {
                if dt_matched[t * d_n + d] == 0 {
                    dt_ignore[t * d_n + d] = true;
                }
            }
        }
    }
    Some(ImgEval { dt_scores: cell.dts.iter().map(|d| d.score).collect(), dt_matched, dt_ignore, num_gt: gt_ig.iter().filter(|&&i| !i).count() })
}
