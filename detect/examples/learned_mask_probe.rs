//! Probe: mask AP at IoU 0.50..0.95 and median matched IoU of a learned model under a few
//! decoder settings (select them on a validation set, not on the test sets). The network runs
//! once per image; each setting only re-decodes.
//! `cargo run --release -p tubeloc-detect --example learned_mask_probe -- MODEL DATASET_DIR [LIMIT]`
use rayon::prelude::*;
use std::path::Path;
use tubeloc_detect::learned::dataset::{average_precision, load_coco_dir};
use tubeloc_detect::learned::{decode, DecodeConfig, LearnedModel, Prediction, TrainImage};

/// AP at IoU 0.50..0.95 (as `dataset::mask_scores`), matched IoUs at 0.5, number of tubes.
fn scores(imgs: &[TrainImage], preds: &[Prediction], cfg: &DecodeConfig) -> ([f64; 10], Vec<f64>, usize) {
    let per: Vec<(usize, usize, Vec<(f64, Vec<(usize, f64)>)>)> = imgs
        .par_iter()
        .zip(preds)
        .map(|(img, pred)| {
            let dets = decode(pred, cfg);
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
                    for (m, &l) in d.mask.data.iter().zip(&img.labels) {
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
    let total = per.iter().map(|p| p.1).sum();
    let mut ap = [0.0; 10];
    let mut matched = Vec::new();
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
                        matched.push(iou);
                    }
                }
                all.push((*score, hit));
            }
        }
        *ap_t = average_precision(&mut all, total);
    }
    matched.sort_by(f64::total_cmp);
    (ap, matched, total)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().collect();
    if a.len() < 3 {
        return Err("usage: learned_mask_probe MODEL DATASET_DIR [LIMIT]".into());
    }
    let model = LearnedModel::load(Path::new(&a[1]))?;
    let limit = a.get(3).and_then(|s| s.parse().ok()).unwrap_or(40);
    let imgs = load_coco_dir(Path::new(&a[2]), model.meta.preprocess, Some(limit))?;
    let preds = imgs.iter().map(|im| model.predict(&im.input, im.width, im.height)).collect::<Result<Vec<_>, _>>()?;
    let d = DecodeConfig::default();
    let mut variants = vec![
        ("default".to_string(), d),
        ("mask logit 0".into(), DecodeConfig { mask_logit: 0.0, ..d }),
        ("fg 0.4".into(), DecodeConfig { fg_threshold: 0.4, ..d }),
    ];
    for e in [-2.0f32, -1.0, 0.0] {
        variants.push((format!("extend {e}"), DecodeConfig { extend_logit: e, ..d }));
    }
    for lw in [0.5f32, 1.0, 2.0] {
        variants.push((format!("length^{lw}"), DecodeConfig { length_weight: lw, ..d }));
        variants.push((format!("extend -1 length^{lw}"), DecodeConfig { length_weight: lw, extend_logit: -1.0, ..d }));
    }
    for (name, cfg) in &variants {
        let (ap, m, total) = scores(&imgs, &preds, cfg);
        println!(
            "{name:24} AP50 {:.3} AP60 {:.3} AP75 {:.3} AP {:.3}  matched at IoU 0.5: {} of {total}, median IoU {:.3}",
            ap[0],
            ap[2],
            ap[5],
            ap.iter().sum::<f64>() / 10.0,
            m.len(),
            m.get(m.len() / 2).copied().unwrap_or(0.0)
        );
    }
    Ok(())
}
