//! AP50 and AR with bootstrap intervals over groups of images ([`crate::bootstrap`]): each
//! image's matching (area "all", at most 100 detections) is computed once, and each resample
//! accumulates the images of the groups it drew, an image drawn twice counting twice, exactly
//! as [`CocoEvaluator::evaluate`] accumulates a set of images (`stats[1]`, `stats[8]`).

use super::accumulate::accumulate_slice;
use super::matching::{evaluate_cell, ImgEval};
use super::params::{iou_thresholds, recall_thresholds, AREA_RNGS, NUM_REC_THRS};
use super::summary::pairwise_sum;
use super::CocoEvaluator;
use crate::bootstrap::{groups_by_key, BootstrapSpec, Interval};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// AP at IoU 0.5 and AR (IoU 0.50:0.95, 100 detections), each with its interval.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ApArIntervals {
    /// COCO AP50 (`stats[1]`).
    pub ap50: Interval,
    /// COCO AR at 100 detections (`stats[8]`).
    pub ar: Interval,
}

/// The category cells of one image (one entry per category; `None`: neither truth nor detection).
type ImageCells = Vec<Option<ImgEval>>;

/// AP50 and AR of the images `chosen` (indices into `cells`, repeats allowed), averaged over the
/// categories with ground truth as pycocotools' summary does; NaN when none has any.
fn ap50_ar(cells: &[ImageCells], chosen: &[usize], categories: usize, rec_thrs: &[f64; NUM_REC_THRS]) -> (f64, f64) {
    let per_category: Vec<(f64, f64)> = (0..categories)
        .filter_map(|k| {
            let evals: Vec<&ImgEval> = chosen.iter().filter_map(|&i| cells[i][k].as_ref()).collect();
            let (precision, recall) = accumulate_slice(&evals, 100, rec_thrs)?;
            // Summed as the summary sums (numpy's pairwise sum), so one category gives its stats to the bit.
            Some((pairwise_sum(&precision[0]) / NUM_REC_THRS as f64, pairwise_sum(&recall) / recall.len() as f64))
        })
        .collect();
    if per_category.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let n = per_category.len() as f64;
    (per_category.iter().map(|c| c.0).sum::<f64>() / n, per_category.iter().map(|c| c.1).sum::<f64>() / n)
}

impl CocoEvaluator {
    /// AP50 and AR of all images with intervals from a bootstrap over groups of images:
    /// `group_of(image_id)` names an image's group (e.g. its sol); images of one group are
    /// drawn together. The estimates equal [`CocoEvaluator::evaluate`]'s `stats[1]` and
    /// `stats[8]` (NaN where those are -1: no ground truth).
    pub fn intervals_by_group<K: Ord>(&self, group_of: &(dyn Fn(u64) -> K + Sync), spec: &BootstrapSpec) -> ApArIntervals {
        let p = &self.prep;
        let k_n = p.cat_ids.len();
        let (iou_thrs, rec_thrs) = (iou_thresholds(), recall_thresholds());
        let cells: Vec<ImageCells> = (0..p.img_ids.len()).into_par_iter().map(|i| (0..k_n).map(|k| evaluate_cell(&p.cells[i * k_n + k], AREA_RNGS[0], &iou_thrs, &|_| false)).collect()).collect();
        let groups = groups_by_key(p.img_ids.iter().map(|&id| group_of(id)));
        let all: Vec<usize> = (0..cells.len()).collect();
        let (ap50, ar) = ap50_ar(&cells, &all, k_n, &rec_thrs);
        let values: Vec<(f64, f64)> = spec
            .draws(groups.len())
            .into_par_iter()
            .map(|draw| {
                let chosen: Vec<usize> = draw.iter().flat_map(|&g| groups[g].iter().copied()).collect();
                ap50_ar(&cells, &chosen, k_n, &rec_thrs)
            })
            .collect();
        ApArIntervals { ap50: spec.interval(ap50, values.iter().map(|v| v.0).collect(), groups.len()), ar: spec.interval(ar, values.iter().map(|v| v.1).collect(), groups.len()) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::coco_eval::IouType;
    use tubeloc_core::{CocoDataset, CocoResult};

    /// `n` images of one tube each in sols of two images; detections miss the tube of every
    /// third image (from the first), hit the others' and score a false one on every third.
    fn set(n: u64) -> (CocoDataset, Vec<CocoResult>) {
        let images: Vec<_> = (1..=n).map(|i| serde_json::json!({"id": i, "width": 64, "height": 48, "file_name": format!("{i}.png"), "sol": i.div_ceil(2)})).collect();
        let anns: Vec<_> = (1..=n).map(|i| serde_json::json!({"id": i, "image_id": i, "category_id": 1, "area": 200, "bbox": [10, 10, 20, 10]})).collect();
        let gt: CocoDataset = serde_json::from_value(serde_json::json!({"images": images, "annotations": anns, "categories": [{"id": 1, "name": "tube"}]})).unwrap();
        let mut dt = Vec::new();
        for i in 1..=n {
            let x = if i % 3 == 1 { 40 } else { 11 };
            dt.push(serde_json::json!({"image_id": i, "category_id": 1, "score": 0.3 + 0.05 * (i % 7) as f64, "bbox": [x, 10, 20, 10]}));
            if i % 3 == 0 {
                dt.push(serde_json::json!({"image_id": i, "category_id": 1, "score": 0.9, "bbox": [0, 30, 10, 10]}));
            }
        }
        (gt, serde_json::from_value(serde_json::json!(dt)).unwrap())
    }

    #[test]
    fn estimates_are_cocos_and_intervals_cover_them() {
        let (gt, dt) = set(24);
        let ev = CocoEvaluator::new(&gt, &dt, IouType::Bbox).unwrap();
        let stats = ev.evaluate().stats;
        let sol = |id: u64| gt.images.iter().find(|im| im.id == id).and_then(|im| im.extra.get("sol")).and_then(|s| s.as_u64()).unwrap();
        let spec = BootstrapSpec::default();
        let i = ev.intervals_by_group(&sol, &spec);
        assert!((i.ap50.estimate - stats[1]).abs() < 1e-12, "{i:?} vs {}", stats[1]);
        assert!((i.ar.estimate - stats[8]).abs() < 1e-12, "{i:?} vs {}", stats[8]);
        assert_eq!(i.ap50.groups, 12);
        for v in [i.ap50, i.ar] {
            assert!(v.lo <= v.estimate && v.estimate <= v.hi && v.lo < v.hi, "{v:?}");
            assert!(v.lo >= 0.0 && v.hi <= 1.0, "{v:?}");
        }
        assert_eq!(ev.intervals_by_group(&sol, &spec), i, "same seed, same intervals");
        // One group: every resample is the whole set.
        let one = ev.intervals_by_group(&|_| 0, &spec);
        assert_eq!((one.ap50.lo, one.ap50.hi), (one.ap50.estimate, one.ap50.estimate));
        // Each image its own group: more groups, a narrower interval than by sol here.
        let each = ev.intervals_by_group(&|id| id, &spec);
        assert_eq!(each.ap50.groups, 24);
    }

    #[test]
    fn a_doubled_set_has_the_same_estimate() {
        // Accumulating an image twice (a group drawn twice) keeps precision and recall: AP50
        // of the set and of the set with every image repeated are equal.
        let (gt, dt) = set(10);
        let ev = CocoEvaluator::new(&gt, &dt, IouType::Bbox).unwrap();
        let p = &ev.prep;
        let (iou_thrs, rec_thrs) = (iou_thresholds(), recall_thresholds());
        let cells: Vec<ImageCells> = (0..p.img_ids.len()).map(|i| vec![evaluate_cell(&p.cells[i], AREA_RNGS[0], &iou_thrs, &|_| false)]).collect();
        let once: Vec<usize> = (0..10).collect();
        let twice: Vec<usize> = (0..10).flat_map(|i| [i, i]).collect();
        let (a, b) = (ap50_ar(&cells, &once, 1, &rec_thrs), ap50_ar(&cells, &twice, 1, &rec_thrs));
        assert!((a.0 - b.0).abs() < 1e-12 && (a.1 - b.1).abs() < 1e-12, "{a:?} {b:?}");
    }
}
