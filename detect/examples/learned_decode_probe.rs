//! Probe: validation AP50 of a learned model under a few decoder settings.
//! `cargo run --release -p tubeloc-detect --example learned_decode_probe -- MODEL DATASET_DIR [LIMIT]`
use std::path::Path;
use tubeloc_detect::learned::dataset::{ap50, load_coco_dir};
use tubeloc_detect::learned::{DecodeConfig, LearnedModel};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().collect();
    if a.len() < 3 {
        return Err("usage: learned_decode_probe MODEL DATASET_DIR [LIMIT]".into());
    }
    let model = LearnedModel::load(Path::new(&a[1]))?;
    let limit = a.get(3).and_then(|s| s.parse().ok()).unwrap_or(40);
    let imgs = load_coco_dir(Path::new(&a[2]), model.meta.preprocess, Some(limit))?;
    let d = DecodeConfig::default();
    for img in imgs.iter().take(3) {
        let pred = model.predict(&img.input, img.width, img.height)?;
        let (out, ow, oh) = (&pred.planes, pred.out_w, pred.out_h);
        let n = ow * oh;
        let sig = |v: f32| 1.0 / (1.0 + (-v).exp());
        let fg = out[..n].iter().filter(|&&v| v > 0.0).count();
        let heat_hi = out[n..2 * n].iter().filter(|&&v| sig(v) > 0.2).count();
        let hmax = out[n..2 * n].iter().fold(f32::MIN, |a, &v| a.max(sig(v)));
        let gt = img.labels.iter().filter(|&&l| l != 0).count() / 16;
        let ngt = img.labels.iter().copied().max().unwrap_or(0);
        let half: f32 = (0..n).filter(|&c| out[c] > 0.0).map(|c| out[4 * n + c]).sum::<f32>() / fg.max(1) as f32;
        println!("fg cells {fg} (gt ~{gt}), heat>0.2 cells {heat_hi}, heat max {hmax:.3}, mean half-len {:.1} px, gt tubes {ngt}, detections {}", half * 64.0, tubeloc_detect::learned::decode(&pred, &d).len());
    }
    let variants = [
        ("default", d),
        ("stride-4 masks", DecodeConfig { fine_mask: false, ..d }),
        ("mask logit -0.5", DecodeConfig { mask_logit: -0.5, ..d }),
        ("mask logit -1", DecodeConfig { mask_logit: -1.0, ..d }),
        ("mask logit 0.5", DecodeConfig { mask_logit: 0.5, ..d }),
        ("fg 0.4", DecodeConfig { fg_threshold: 0.4, ..d }),
        ("fg 0.6", DecodeConfig { fg_threshold: 0.6, ..d }),
        ("peak 0.3", DecodeConfig { peak_threshold: 0.3, ..d }),

    ];
    for (name, cfg) in variants {
        println!("{name:16} AP50 {:.4}", ap50(&model, &imgs, &cfg)?);
    }
    Ok(())
}
