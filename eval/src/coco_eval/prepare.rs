//! Gathers ground truth and detections per (image, category) cell and computes their IoUs,
//! as pycocotools' `COCO.loadRes`, `COCOeval._prepare` and `computeIoU` do.

use super::params::{IouType, MAX_DETS};
use super::EvalError;
use rayon::prelude::*;
use std::collections::HashMap;
use tubeloc_core::mask::bbox_iou;
use tubeloc_core::{CocoAnnotation, CocoDataset, CocoResult, Rle, Segmentation};

/// One ground-truth object of a cell.
#[derive(Clone, Debug)]
pub(crate) struct GtItem {
    /// Index in `CocoDataset::annotations` (for attribute breakdowns).
    pub ann_index: usize,
    /// Annotation id (0 behaves as "unmatched", as in pycocotools).
    pub id: u64,
    /// The annotation's `area` field.
    pub area: f64,
    /// `iscrowd`; pycocotools also uses it as the `ignore` flag.
    pub crowd: bool,
}

/// One detection of a cell, after sorting by score and the maxDets cap.
#[derive(Clone, Debug)]
pub(crate) struct DtItem {
    /// Confidence.
    pub score: f64,
    /// Mask area (segm results) or `w * h` of the box (box results), as `loadRes` sets it.
    pub area: f64,
}

/// Everything about one (image, category) pair.
#[derive(Clone, Debug, Default)]
pub(crate) struct Cell {
    /// Ground truth in file order.
    pub gts: Vec<GtItem>,
    /// Detections sorted by descending score (stable), at most `MAX_DETS[2]`.
    pub dts: Vec<DtItem>,
    /// `ious[d * gts.len() + g]`; empty when there are no detections or no ground truth.
    pub ious: Vec<f64>,
}

/// The prepared evaluation: sorted image and category ids and their cells.
#[derive(Clone, Debug)]
pub(crate) struct Prepared {
    /// Sorted unique image ids of the ground truth.
    pub img_ids: Vec<u64>,
    /// Sorted unique category ids of the ground truth.
    pub cat_ids: Vec<u64>,
    /// `cells[i * cat_ids.len() + k]`.
    pub cells: Vec<Cell>,
}

/// How `loadRes` reads a results list: by the first entry having a box.
#[derive(Clone, Copy, PartialEq)]
enum ResultMode {
    /// Box results: `area = w * h`, missing masks become the box polygon.
    Boxes,
    /// Mask results: `area` from the mask, missing boxes from `toBbox`.
    Masks,
}

pub(crate) fn prepare(gt: &CocoDataset, dt: &[CocoResult], iou_type: IouType) -> Result<Prepared, EvalError> {
    let mut img_ids: Vec<u64> = gt.images.iter().map(|im| im.id).collect();
    img_ids.sort_unstable();
    img_ids.dedup();
    let mut cat_ids: Vec<u64> = gt.categories.iter().map(|c| c.id).collect();
    cat_ids.sort_unstable();
    cat_ids.dedup();
    let img_index: HashMap<u64, usize> = img_ids.iter().enumerate().map(|(i, &id)| (id, i)).collect();
    let cat_index: HashMap<u64, usize> = cat_ids.iter().enumerate().map(|(k, &id)| (id, k)).collect();
    let sizes: HashMap<u64, (u32, u32)> = gt.images.iter().map(|im| (im.id, (im.height, im.width))).collect();
    let k_n = cat_ids.len();

    // Ground truth per cell, in file order.
    let mut gt_lists: Vec<Vec<usize>> = vec![Vec::new(); img_ids.len() * k_n];
    let mut seen_ids = HashMap::with_capacity(gt.annotations.len());
    for (j, a) in gt.annotations.iter().enumerate() {
        if let Some(prev) = seen_ids.insert(a.id, j) {
            return Err(EvalError::entry(format!("annotations[{j}] (id {})", a.id), format!("duplicate annotation id (also annotations[{prev}]); pycocotools would silently mix them up")));
        }
        let Some(&i) = img_index.get(&a.image_id) else {
            return Err(EvalError::entry(format!("annotations[{j}] (id {})", a.id), format!("unknown image_id {}", a.image_id)));
        };
        if let Some(&k) = cat_index.get(&a.category_id) {
            gt_lists[i * k_n + k].push(j);
        }
    }

    // Detections per cell, in results order (loadRes ids are 1 + index).
    let mode = match dt.first() {
        Some(r) if r.bbox.is_some() => ResultMode::Boxes,
        _ => ResultMode::Masks,
    };
    let mut dt_lists: Vec<Vec<usize>> = vec![Vec::new(); img_ids.len() * k_n];
    for (j, r) in dt.iter().enumerate() {
        let Some(&i) = img_index.get(&r.image_id) else {
            return Err(EvalError::entry(format!("results[{j}] (image_id {})", r.image_id), format!("image_id {} is not in the ground truth", r.image_id)));
        };
        if !r.score.is_finite() {
            return Err(EvalError::entry(format!("results[{j}] (image_id {})", r.image_id), "non-finite score"));
        }
        if let Some(&k) = cat_index.get(&r.category_id) {
            dt_lists[i * k_n + k].push(j);
        }
    }

    let cells: Result<Vec<Cell>, EvalError> = (0..img_ids.len() * k_n)
        .into_par_iter()
        .map(|c| {
            let (h, w) = sizes[&img_ids[c / k_n.max(1)]];
            build_cell(gt, dt, &gt_lists[c], &dt_lists[c], (h, w), iou_type, mode)
        })
        .collect();
    Ok(Prepared { img_ids, cat_ids, cells: cells? })
}

fn build_cell(gt: &CocoDataset, dt: &[CocoResult], gt_idx: &[usize], dt_idx: &[usize], (h, w): (u32, u32), iou_type: IouType, mode: ResultMode) -> Result<Cell, EvalError> {
    // Stable sort by descending score (np.argsort(-score, kind='mergesort')), then the cap.
    let mut order: Vec<usize> = dt_idx.to_vec();
    order.sort_by(|&a, &b| dt[b].score.partial_cmp(&dt[a].score).unwrap_or(std::cmp::Ordering::Equal));
    order.truncate(MAX_DETS[2]);

    let gts: Vec<GtItem> = gt_idx
        .iter()
        .map(|&j| {
            let a = &gt.annotations[j];
            GtItem { ann_index: j, id: a.id, area: a.area, crowd: a.iscrowd != 0 }
        })
        .collect();
    let crowd: Vec<bool> = gts.iter().map(|g| g.crowd).collect();

    let mut dts = Vec::with_capacity(order.len());
    let mut dt_rles = Vec::new();
    let mut dt_boxes = Vec::new();
    for &j in &order {
        let r = &dt[j];
        let at = || format!("results[{j}] (image_id {})", r.image_id);
        let need_rle = iou_type == IouType::Segm || mode == ResultMode::Masks;
        let rle = if need_rle { Some(result_rle(r, h, w, mode).map_err(|m| EvalError::entry(at(), m))?) } else { None };
        let bbox = match (r.bbox, &rle) {
            (Some(b), _) => b,
            (None, Some(rle)) if mode == ResultMode::Masks => rle.to_bbox(),
            _ => return Err(EvalError::entry(at(), "no bbox (the first result has one, so all are read as box results)")),
        };
        let area = match mode {
            ResultMode::Boxes => bbox[2] * bbox[3],
            ResultMode::Masks => rle.as_ref().map(|r| r.area() as f64).unwrap_or(0.0),
        };
        dts.push(DtItem { score: r.score, area });
        match iou_type {
            IouType::Segm => dt_rles.extend(rle),
            IouType::Bbox => dt_boxes.push(bbox),
        }
    }

    let ious = if gts.is_empty() || dts.is_empty() {
        Vec::new()
    } else {
        match iou_type {
            IouType::Segm => {
                let g: Result<Vec<Rle>, EvalError> = gt_idx.iter().map(|&j| gt_rle(&gt.annotations[j], j, h, w)).collect();
                Rle::iou(&dt_rles, &g?, &crowd)
            }
            IouType::Bbox => {
                let g: Vec<[f64; 4]> = gt_idx.iter().map(|&j| gt.annotations[j].bbox).collect();
                bbox_iou(&dt_boxes, &g, &crowd)
            }
        }
    };
    Ok(Cell { gts, dts, ious })
}

/// The mask of a result as pycocotools sees it (`annToRLE` on the loadRes'ed entry).
fn result_rle(r: &CocoResult, h: u32, w: u32, mode: ResultMode) -> Result<Rle, String> {
    match (&r.segmentation, mode, r.bbox) {
        (Some(seg), _, _) => seg.to_rle(h, w).map_err(|e| e.to_string()),
        (None, ResultMode::Boxes, Some(bb)) => {
            let (x1, y1, x2, y2) = (bb[0], bb[1], bb[0] + bb[2], bb[1] + bb[3]);
            Rle::from_polygons(&[vec![x1, y1, x1, y2, x2, y2, x2, y1]], h, w).map_err(|e| e.to_string())
        }
        _ => Err("no segmentation (needed for segm evaluation)".to_string()),
    }
}

fn gt_rle(a: &CocoAnnotation, j: usize, h: u32, w: u32) -> Result<Rle, EvalError> {
    let at = || format!("annotations[{j}] (id {})", a.id);
    let seg: &Segmentation = a.segmentation.as_ref().ok_or_else(|| EvalError::entry(at(), "no segmentation (needed for segm evaluation)"))?;
    seg.to_rle(h, w).map_err(|e| EvalError::entry(at(), e.to_string()))
}
