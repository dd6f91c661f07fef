//! COCO dataset directories (as written by `tubeloc synth`) to training images, and a simple
//! mask AP at IoU 0.5 for validation during training.
//!
//! A dataset directory holds `annotations.json` and the images; an image's `file_name` is
//! looked up relative to the directory, then under `images/`.

use super::augment::TrainImage;
use super::decode::{decode, predict_for, DecodeConfig, LearnedInstance};
use super::error::LearnedError;
use super::model::LearnedModel;
use super::preprocess::Preprocess;
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use tubeloc_core::CocoDataset;

/// Loads every image of a COCO dataset directory with its instance masks, preprocessed.
/// `limit` keeps only the first `limit` images (by id order in the file).
pub fn load_coco_dir(dir: &Path, pre: Preprocess, limit: Option<usize>) -> Result<Vec<TrainImage>, LearnedError> {
    load_coco_dir_at_scale(dir, pre, limit, None)
}

/// The working scale of a dataset image ([`crate::scale::working_scale`]) from its `camera`
/// and optional `ground` (`{"normal": [nx, ny, nz], "d": d}`, `n · X = d`, n up, camera frame)
/// fields; 1 without a camera.
pub fn image_working_scale(im: &tubeloc_core::CocoImage, band: crate::scale::RangeBand) -> f64 {
    let Some(cam) = im.extra.get("camera").and_then(|c| serde_json::from_value::<tubeloc_core::CameraModel>(c.clone()).ok()) else { return 1.0 };
    crate::scale::working_scale(&cam, ground_field(im), band)
}

/// The `ground` field of a dataset image as written: `(n, d)` of `n · X = d` (n up, camera
/// frame, metres), unchecked ([`image_ground`] checks it).
pub fn ground_field(im: &tubeloc_core::CocoImage) -> Option<(nalgebra::Vector3<f64>, f64)> {
    let g = im.extra.get("ground")?;
    let n = g.get("normal")?.as_array()?;
    let d = g.get("d")?.as_f64()?;
    Some((nalgebra::Vector3::new(n.first()?.as_f64()?, n.get(1)?.as_f64()?, n.get(2)?.as_f64()?), d))
}

/// The ground plane of a dataset image from its `ground` field (`{"normal": [nx, ny, nz],
/// "d": d}`, `n · X = d`, n up, camera frame, metres, as `tubeloc synth real` writes it);
/// `None` without one or when it is not a valid plane.
pub fn image_ground(im: &tubeloc_core::CocoImage) -> Option<tubeloc_core::GroundPlane> {
    ground_field(im).and_then(|(n, d)| tubeloc_core::GroundPlane::new(n, d).ok())
}

/// The `gray_norm` field of a dataset image (`{"p50": median, "inv": gain}`, as `tubeloc synth
/// negatives` writes for a crop: the [`GrayNormMap`](super::preprocess::GrayNormMap) of the
/// whole frame it was cut from); `None` without one or when out of range.
pub fn frame_gray_norm(im: &tubeloc_core::CocoImage) -> Option<super::preprocess::GrayNormMap> {
    let g = im.extra.get("gray_norm")?;
    super::preprocess::GrayNormMap::from_parts(g.get("p50")?.as_f64()? as f32, g.get("inv")?.as_f64()? as f32)
}

/// [`load_coco_dir`] with each image's working scale set from its camera and ground
/// ([`image_working_scale`]) when `band` is given, so that training crops see tubes at the
/// scale inference resamples them to.
pub fn load_coco_dir_at_scale(dir: &Path, pre: Preprocess, limit: Option<usize>, band: Option<crate::scale::RangeBand>) -> Result<Vec<TrainImage>, LearnedError> {
    let ann = dir.join("annotations.json");
    let ds = CocoDataset::load(&ann).map_err(|e| LearnedError::Dataset { path: ann.clone(), msg: e.to_string() })?;
    let n = limit.unwrap_or(usize::MAX).min(ds.images.len());
    ds.images[..n]
        .par_iter()
        .map(|im| {
            let mut p: PathBuf = dir.join(&im.file_name);
            if !p.exists() {
                p = dir.join("images").join(&im.file_name);
            }
            let err = |msg: String| LearnedError::Dataset { path: p.clone(), msg };
            let rgb = crate::input::load(&p).map_err(err)?;
            let (w, h) = (rgb.width, rgb.height);
            if (w, h) != (im.width as usize, im.height as usize) {
                return Err(err(format!("image is {w}x{h} but annotations.json says {}x{}", im.width, im.height)));
            }
            let mut masks = Vec::new();
            for a in ds.annotations.iter().filter(|a| a.image_id == im.id && a.iscrowd == 0) {
                let Some(seg) = &a.segmentation else { continue };
                let m = seg.to_rle(im.height, im.width).and_then(|r| r.to_mask()).map_err(|e| LearnedError::Dataset { path: ann.clone(), msg: format!("annotation {}: {e}", a.id) })?;
                masks.push(m.data);
            }
            // A crop cut from a larger frame carries the frame's map, so that it is normalized
            // as inference normalizes the whole frame (`tubeloc synth negatives`).
            let input = match (pre, frame_gray_norm(im)) {
                (Preprocess::GrayNorm, Some(map)) => map.apply_all(&rgb.rgb, w * h),
                (_, _) => pre.apply(&rgb.rgb, w, h),
            };
            let mut t = TrainImage::new(w, h, input, &masks);
            if let Some(band) = band {
                t.scale = image_working_scale(im, band) as f32;
            }
            Ok(t)
        })
        .collect()
}

/// Runs the model on a preprocessed training image at its working scale, as inference does
/// ([`super::detect_planes_at_scale`]; at scale 1 without copying the input).
pub fn detect_image(model: &LearnedModel, img: &TrainImage, cfg: &DecodeConfig) -> Result<Vec<LearnedInstance>, LearnedError> {
    if img.scale != 1.0 {
        return super::detect_planes_at_scale(model, img.input.clone(), img.width, img.height, img.scale as f64, cfg);
    }
    Ok(super::shaped(decode(&predict_for(model, &img.input, img.width, img.height, cfg)?, cfg), cfg))
}

/// Mask quality of a model on labelled images (see [`mask_scores`]).
#[derive(Clone, Debug)]
pub struct MaskScores {
    /// Mask AP at IoU 0.50, 0.55, ..., 0.95.
    pub ap: [f64; 10],
    /// IoU of each detection matched at IoU 0.5, sorted ascending.
    pub matched_iou: Vec<f64>,
    /// Ground-truth tubes with at least one pixel.
    pub total_gt: usize,
}

impl MaskScores {
    /// Mean AP over the ten IoU thresholds (COCO's AP).
    pub fn ap_mean(&self) -> f64 {
        self.ap.iter().sum::<f64>() / 10.0
    }

    /// Median IoU of the detections matched at IoU 0.5 (0 when none).
    pub fn median_matched_iou(&self) -> f64 {
        self.matched_iou.get(self.matched_iou.len() / 2).copied().unwrap_or(0.0)
    }
}

/// Mask AP over images at the ten COCO IoU thresholds (all detections pooled, sorted by score;
/// per image and threshold, each detection in score order takes the unmatched ground truth of
/// highest IoU if that IoU reaches the threshold; precision made monotone and sampled at 101
/// recall points as COCO does). A quick validation figure; `tubeloc eval` gives the full one.
pub fn mask_scores(model: &LearnedModel, images: &[TrainImage], cfg: &DecodeConfig) -> Result<MaskScores, LearnedError> {
    let dets = images.iter().map(|img| detect_image(model, img, cfg)).collect::<Result<Vec<_>, _>>()?;
    Ok(score_detections(images, &dets))
}

/// Per image: the largest label, the number of tubes present, and per detection its score and
/// its IoU with every tube present.
type ImageMatches = (usize, usize, Vec<(f64, Vec<(usize, f64)>)>);

/// [`mask_scores`] of detections already made: `dets[i]` are the instances of `images[i]`,
/// in decreasing score order.
pub fn score_detections(images: &[TrainImage], dets: &[Vec<LearnedInstance>]) -> MaskScores {
    // Per image: the largest label, the number of tubes present, and per detection its score
    // and its IoU with every tube present.
    let per: Vec<ImageMatches> = images
        .par_iter()
        .zip(dets)
        .map(|(img, dets)| {
            let ngt = img.labels.iter().copied().max().unwrap_or(0) as usize;
            let mut gt_area = vec![0usize; ngt + 1];
            for &l in &img.labels {
                gt_area[l as usize] += 1;
            }
            let present: Vec<usize> = (1..=ngt).filter(|&k| gt_area[k] > 0).collect();
            let ious = dets
                .iter()
                .map(|d| {
                    let mut inter = vec![0usize; ngt + 1];
                    let mut area = 0usize;
                    let mask = d.mask.to_mask().map(|m| m.data).unwrap_or_default();
                    for (m, &l) in mask.iter().zip(&img.labels) {
                        if *m != 0 {
                            area += 1;
                            inter[l as usize] += 1;
                        }
                    }
                    (d.score, present.iter().map(|&k| (k, inter[k] as f64 / (area + gt_area[k] - inter[k]) as f64)).collect())
                })
                .collect();
            (ngt, present.len(), ious)
        })
        .collect();
    let total_gt = per.iter().map(|p| p.1).sum();
    let mut ap = [0.0; 10];
    let mut matched_iou = Vec::new();
    for (t, ap_t) in ap.iter_mut().enumerate() {
        let thr = 0.5 + 0.05 * t as f64;
        let mut all = Vec::new();
        for (ngt, _, ious) in &per {
            let mut used = vec![false; ngt + 1];
            for (score, cand) in ious {
                let best = cand.iter().filter(|(k, _)| !used[*k]).copied().max_by(|a, b| a.1.total_cmp(&b.1));
                let hit = matches!(best, Some((_, iou)) if iou >= thr);
                if let (true, Some((k, iou))) = (hit, best) {
                    used[k] = true;
                    if t == 0 {
                        matched_iou.push(iou);
                    }
                }
                all.push((*score, hit));
            }
        }
        *ap_t = average_precision(&mut all, total_gt);
    }
    matched_iou.sort_by(f64::total_cmp);
    MaskScores { ap, matched_iou, total_gt }
}

/// Mask AP at IoU 0.5 ([`mask_scores`]).
pub fn ap50(model: &LearnedModel, images: &[TrainImage], cfg: &DecodeConfig) -> Result<f64, LearnedError> {
    Ok(mask_scores(model, images, cfg)?.ap[0])
}

/// COCO-style 101-point interpolated AP of scored hits (`true` = true positive).
pub fn average_precision(dets: &mut [(f64, bool)], total_gt: usize) -> f64 {
    if total_gt == 0 {
        return 0.0;
    }
    dets.sort_by(|a, b| b.0.total_cmp(&a.0));
    let (mut tp, mut fp) = (0usize, 0usize);
    let mut rec = Vec::with_capacity(dets.len());
    let mut prec = Vec::with_capacity(dets.len());
    for &(_, hit) in dets.iter() {
        if hit {
            tp += 1
        } else {
            fp += 1
        }
        rec.push(tp as f64 / total_gt as f64);
        prec.push(tp as f64 / (tp + fp) as f64);
    }
    for i in (0..prec.len().saturating_sub(1)).rev() {
        prec[i] = prec[i].max(prec[i + 1]);
    }
    let mut sum = 0.0;
    for k in 0..=100 {
        let r = k as f64 / 100.0;
        let i = rec.partition_point(|&x| x < r);
        if i < prec.len() {
            sum += prec[i];
        }
    }
    sum / 101.0
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn ap_of_perfect_and_half_detections() {
        let mut d = vec![(0.9, true), (0.8, true)];
        assert!((average_precision(&mut d, 2) - 1.0).abs() < 1e-12);
        // One of two found, ranked first: precision 1 up to recall 0.5 (51 of 101 points).
        let mut d = vec![(0.9, true), (0.1, false)];
        assert!((average_precision(&mut d, 2) - 51.0 / 101.0).abs() < 1e-12);
        assert_eq!(average_precision(&mut [], 0), 0.0);
    }

    /// A crop that carries its frame's gray-norm map is normalized by it (as inference
    /// normalizes the whole frame), one without by its own pixels; other preprocessings ignore
    /// the field, and a map out of range is not used.
    #[test]
    fn a_crop_is_normalized_by_its_frames_map() {
        use super::super::preprocess::GrayNormMap;
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("images")).unwrap();
        // A dark crop of a brighter frame: its own percentiles stretch it, the frame's do not.
        let crop = image::RgbImage::from_fn(64, 32, |x, y| image::Rgb([(20 + (x + y) % 40) as u8; 3]));
        crop.save(dir.path().join("images/c.png")).unwrap();
        let frame_map = GrayNormMap::from_parts(0.5, 4.0).unwrap();
        let write = |gray_norm: serde_json::Value| {
            let mut im = serde_json::json!({"id": 1, "file_name": "c.png", "width": 64, "height": 32});
            if !gray_norm.is_null() {
                im["gray_norm"] = gray_norm;
            }
            let doc = serde_json::json!({"images": [im], "annotations": [], "categories": [{"id": 1, "name": "tube"}]});
            std::fs::write(dir.path().join("annotations.json"), doc.to_string()).unwrap();
            load_coco_dir(dir.path(), Preprocess::GrayNorm, None).unwrap().remove(0).input
        };
        let rgb = crop.as_raw();
        let framed = write(serde_json::json!({"p50": 0.5, "inv": 4.0}));
        assert_eq!(framed, frame_map.apply_all(rgb, 64 * 32));
        assert!(framed.iter().all(|&v| v < -1.0), "a dark crop stays dark under the frame's map");
        let own = write(serde_json::Value::Null);
        assert_eq!(own, super::super::preprocess::gray_norm(rgb, 64 * 32));
        assert!(own.iter().any(|&v| v > 0.5), "its own map stretches it");
        assert_eq!(write(serde_json::json!({"p50": 0.5, "inv": -1.0})), own, "a bad map is not used");
        assert!(GrayNormMap::from_parts(1.5, 1.0).is_none() && GrayNormMap::from_parts(0.5, f32::NAN).is_none());
        let (p50, inv) = frame_map.parts();
        assert_eq!(GrayNormMap::from_parts(p50, inv), Some(frame_map));
    }
}
