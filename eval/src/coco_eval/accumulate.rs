//! Precision/recall accumulation over images: pycocotools' `COCOeval.accumulate`.
//!
//! For each (category k, area a, maxDets m) the detections of all images (each image's first
//! `maxDets`) are merged and stably sorted by descending score. With cumulative true and false
//! positive counts `tp_i`, `fp_i` (ignored detections dropped) and `n` non-ignored ground truth:
//! `recall_i = tp_i / n`, `precision_i = tp_i / (tp_i + fp_i + eps)` with `eps = 2^-52`;
//! precision is made monotone from the right (`p_{i-1} = max(p_{i-1}, p_i)`) and sampled at the
//! 101 recall thresholds `r` at the first `i` with `recall_i >= r` (`np.searchsorted`, left),
//! 0 beyond the last detection. Cells with no non-ignored ground truth stay -1.

use super::matching::ImgEval;
use super::params::{MAX_DETS, NUM_IOU_THRS, NUM_REC_THRS};

/// Accumulates one (k, a, m) slice. `evals` are the images' results in image-id order.
/// Returns `(precision[t][r], recall[t])`, or `None` when there is no non-ignored ground truth.
pub(crate) fn accumulate_slice(evals: &[&ImgEval], max_det: usize, rec_thrs: &[f64; NUM_REC_THRS]) -> Option<(Vec<[f64; NUM_REC_THRS]>, [f64; NUM_IOU_THRS])> {
    debug_assert!(MAX_DETS.contains(&max_det));
    let npig: usize = evals.iter().map(|e| e.num_gt).sum();
    if npig == 0 {
        return None;
    }
    // (score, image, detection), concatenated in image order then stably sorted.
    let mut dets: Vec<(f64, u32, u32)> = Vec::new();
    for (i, e) in evals.iter().enumerate() {
        for (d, &s) in e.dt_scores.iter().take(max_det).enumerate() {
            dets.push((s, i as u32, d as u32));
        }
    }
    dets.sort_by(|a, b| b.0.partial_cmp(&a.0).unwrap_or(std::cmp::Ordering::Equal));
    let nd = dets.len();
    let mut precision = vec![[0.0; NUM_REC_THRS]; NUM_IOU_THRS];
    let mut recall = [0.0; NUM_IOU_THRS];
    let mut rc = vec![0.0f64; nd];
    let mut pr = vec![0.0f64; nd];
    for t in 0..NUM_IOU_THRS {
        let (mut tp, mut fp) = (0u64, 0u64);
        for (n, &(_, i, d)) in dets.iter().enumerate() {
            let e = evals[i as usize];
            let dn = e.dt_scores.len();
            let idx = t * dn + d as usize;
            if !e.dt_ignore[idx] {
                if e.dt_matched[idx] != 0 {
                    tp += 1;
                } else {
                    fp += 1;
                }
            }
            let (tpf, fpf) = (tp as f64, fp as f64);
            rc[n] = tpf / npig as f64;
            pr[n] = tpf / (fpf + tpf + f64::EPSILON);
        }
        recall[t] = if nd > 0 { rc[nd - 1] } else { 0.0 };
        for i in (1..nd).rev() {
            if pr[i] > pr[i - 1] {
                pr[i - 1] = pr[i];
            }
        }
        for (r, &thr) in rec_thrs.iter().enumerate() {
            let pi = rc.partition_point(|&x| x < thr);
            precision[t][r] = if pi < nd { pr[pi] } else { 0.0 };
        }
    }
    Some((precision, recall))
}
