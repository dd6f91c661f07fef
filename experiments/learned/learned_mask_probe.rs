//! Probe: mask AP at IoU 0.50..0.95 and median matched IoU of a learned model under a few
//! decoder settings (select them on a validation set, not on the test sets). The network runs
//! once per image; each setting only re-decodes.
//! `cargo run --release --manifest-path experiments/Cargo.toml --bin learned_mask_probe -- MODEL DATASET_DIR [LIMIT]`
#[path = "common/probe_args.rs"]
mod probe_args;

use tubeloc_detect::learned::dataset::score_detections;
use tubeloc_detect::learned::{decode, DecodeConfig};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (model, imgs) = probe_args::model_and_images("learned_mask_probe", 40)?;
    // PROBE_MIRROR=0: the plain prediction instead of the mirror-averaged default.
    let d = DecodeConfig { mirror_average: std::env::var("PROBE_MIRROR").map_or(true, |v| v != "0"), ..DecodeConfig::default() };
    let preds = imgs.iter().map(|im| tubeloc_detect::learned::predict_for(&model, &im.input, im.width, im.height, &d)).collect::<Result<Vec<_>, _>>()?;
    // The decoder before the mask-based score (docs/design/0009-decoder-score-and-mask-threshold.md):
    // score = peak x mean fg, fixed mask threshold 0.5.
    let old = DecodeConfig { mask_logit_weight: 0.0, length_weight: 0.0, fill_weight: 0.0, mask_logit: 0.5, mask_logit_rel: 0.0, ..d };
    let variants = vec![
        ("default".to_string(), d),
        ("earlier decoder".into(), old),
        ("earlier masks, new score".into(), DecodeConfig { mask_logit: 0.5, mask_logit_rel: 0.0, ..d }),
        ("earlier score, new masks".into(), DecodeConfig { mask_logit_weight: 0.0, length_weight: 0.0, fill_weight: 0.0, ..d }),
        ("score: mask logit only".into(), DecodeConfig { length_weight: 0.0, fill_weight: 0.0, ..d }),
        ("score: no fill".into(), DecodeConfig { fill_weight: 0.0, ..d }),
        ("score: mask logit^2".into(), DecodeConfig { mask_logit_weight: 2.0, ..d }),
        ("score: length^1".into(), DecodeConfig { length_weight: 1.0, ..d }),
        ("score: fill^2".into(), DecodeConfig { fill_weight: 2.0, ..d }),
        ("mask rel 0".into(), DecodeConfig { mask_logit_rel: 0.0, ..d }),
        ("mask rel 0.4".into(), DecodeConfig { mask_logit_rel: 0.4, ..d }),
        ("mask logit 0.5".into(), DecodeConfig { mask_logit: 0.5, ..d }),
        ("mask logit -0.5".into(), DecodeConfig { mask_logit: -0.5, ..d }),
        ("fg 0.4".into(), DecodeConfig { fg_threshold: 0.4, ..d }),
        ("peak 0.3".into(), DecodeConfig { peak_threshold: 0.3, ..d }),
    ];
    if let Ok(path) = std::env::var("PROBE_FEATURES") {
        // Per detection: features of the instance and its best IoU with a tube (for choosing a score).
        use std::fmt::Write as _;
        let mut csv = String::from("image,score,area,lm,lp,width,fill,mean_logit,heat,best_iou\n");
        let cfg = d;
        for (k, (img, pred)) in imgs.iter().zip(&preds).enumerate() {
            let ngt = img.labels.iter().copied().max().unwrap_or(0) as usize;
            let mut gt_area = vec![0usize; ngt + 1];
            for &l in &img.labels {
                gt_area[l as usize] += 1;
            }
            let n = pred.out_w * pred.out_h;
            for det in decode(pred, &cfg) {
                let (mut area, mut inter, mut sl) = (0usize, vec![0usize; ngt + 1], 0.0f64);
                let (mut lo, mut hi) = (f64::MAX, f64::MIN);
                let u = det.axis.direction_px;
                for (i, (&m, &l)) in det.mask.to_mask().unwrap().data.iter().zip(&img.labels).enumerate() {
                    if m != 0 {
                        let (x, y) = (i % img.width, i / img.width);
                        area += 1;
                        inter[l as usize] += 1;
                        sl += tubeloc_detect::learned::net::bilinear4_at(&pred.planes[..n], pred.out_w, pred.out_h, x, y) as f64;
                        let t = (x as f64 - det.axis.centre_px[0]) * u[0] + (y as f64 - det.axis.centre_px[1]) * u[1];
                        lo = lo.min(t);
                        hi = hi.max(t);
                    }
                }
                let best = (1..=ngt).filter(|&g| gt_area[g] > 0).map(|g| inter[g] as f64 / (area + gt_area[g] - inter[g]) as f64).fold(0.0, f64::max);
                let lm = hi - lo + 1.0;
                let (cu, cv) = (((det.axis.centre_px[0] - 1.5) / 4.0).round().clamp(0.0, (pred.out_w - 1) as f64) as usize, ((det.axis.centre_px[1] - 1.5) / 4.0).round().clamp(0.0, (pred.out_h - 1) as f64) as usize);
                let heat = 1.0 / (1.0 + (-pred.planes[n + cv * pred.out_w + cu]).exp());
                let _ = writeln!(csv, "{k},{},{area},{lm},{},{},{},{},{heat},{best}", det.score, det.axis.length_px, det.axis.width_px, area as f64 / (lm * det.axis.width_px), sl / area as f64);
            }
        }
        std::fs::write(&path, csv)?;
    }
    for (name, cfg) in &variants {
        let dets: Vec<_> = preds.iter().map(|p| decode(p, cfg)).collect();
        let m = score_detections(&imgs, &dets);
        println!(
            "{name:24} AP50 {:.3} AP60 {:.3} AP75 {:.3} AP {:.3}  matched at IoU 0.5: {} of {}, median IoU {:.3}",
            m.ap[0],
            m.ap[2],
            m.ap[5],
            m.ap_mean(),
            m.matched_iou.len(),
            m.total_gt,
            m.median_matched_iou()
        );
    }
    Ok(())
}
