//! Probe: mask AP at IoU 0.50..0.95 and median matched IoU of a learned model under a few
//! decoder settings (select them on a validation set, not on the test sets).
//! `cargo run --release -p tubeloc-detect --example learned_mask_probe -- MODEL DATASET_DIR [LIMIT]`
use std::path::Path;
use tubeloc_detect::learned::dataset::{load_coco_dir, mask_scores};
use tubeloc_detect::learned::{DecodeConfig, LearnedModel};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().collect();
    if a.len() < 3 {
        return Err("usage: learned_mask_probe MODEL DATASET_DIR [LIMIT]".into());
    }
    let model = LearnedModel::load(Path::new(&a[1]))?;
    let limit = a.get(3).and_then(|s| s.parse().ok()).unwrap_or(40);
    let imgs = load_coco_dir(Path::new(&a[2]), model.meta.preprocess, Some(limit))?;
    let d = DecodeConfig::default();
    let variants = [
        ("default", d),
        ("stride-4 masks", DecodeConfig { fine_mask: false, ..d }),
        ("mask logit 0", DecodeConfig { mask_logit: 0.0, ..d }),
        ("mask logit 1", DecodeConfig { mask_logit: 1.0, ..d }),
        ("fg 0.4", DecodeConfig { fg_threshold: 0.4, ..d }),
        ("fg 0.6", DecodeConfig { fg_threshold: 0.6, ..d }),
        ("peak 0.3", DecodeConfig { peak_threshold: 0.3, ..d }),
    ];
    for (name, cfg) in variants {
        let m = mask_scores(&model, &imgs, &cfg)?;
        println!(
            "{name:16} AP50 {:.3} AP60 {:.3} AP75 {:.3} AP {:.3}  matched at IoU 0.5: {} of {}, median IoU {:.3}",
            m.ap[0], m.ap[2], m.ap[5], m.ap_mean(), m.matched_iou.len(), m.total_gt, m.median_matched_iou()
        );
    }
    Ok(())
}
