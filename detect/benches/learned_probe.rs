//! Speed of the learned segmenter: one training step (batch of augmented crops, forward,
//! backward, AdamW) of `TubeNet` (width 8) on an 8 x 1 x 384 x 384 batch, and inference on one
//! 1024 x 1024 image (preprocessing + network + decoding); then inference on a 2560 x 2560
//! image (a 1024 x 1024 Navcam frame at its working scale) under glibc's default heap policy
//! and, in the same run, under the kept heap that `tubeloc` sets at start
//! (`tubeloc_core::heap::keep_freed_memory`, record 0075; the policy cannot be undone, so it
//! comes last). Run: `RAYON_NUM_THREADS=2 cargo bench -p tubeloc-detect --bench learned_probe`.

use criterion::{criterion_group, criterion_main, Criterion};
use tubeloc_detect::learned::augment::{AugmentConfig, TrainImage};
use tubeloc_detect::learned::{detect_rgb, DecodeConfig, LearnedModel, Preprocess, TrainConfig, Trainer};

fn synthetic_image(size: usize) -> (Vec<u8>, Vec<u8>) {
    let mut rgb = vec![0u8; size * size * 3];
    let mut mask = vec![0u8; size * size];
    for y in 0..size {
        for x in 0..size {
            let v = (((x * 7 + y * 13) % 31) * 4 + 60) as u8;
            let on = (y as isize - (size / 2) as isize).abs() < 7 && x > size / 3 && x < size / 3 + size / 4;
            let v = if on { 200 } else { v };
            rgb[(y * size + x) * 3..][..3].copy_from_slice(&[v, v, v]);
            mask[y * size + x] = on as u8;
        }
    }
    (rgb, mask)
}

fn bench(c: &mut Criterion) {
    let pre = Preprocess::default();
    let (rgb, mask) = synthetic_image(768);
    let img = TrainImage::new(768, 768, pre.apply(&rgb, 768, 768), &[mask]);
    // The shipped architecture: width 8, stride-4 heads.
    let model = LearnedModel::new(pre, 8, 1).unwrap();
    let cfg = TrainConfig { batch: 8, augment: AugmentConfig { crop: 384, ..Default::default() }, ..Default::default() };
    let mut trainer = Trainer::new(model, cfg).unwrap();
    let images = vec![img];
    let mut g = c.benchmark_group("learned");
    g.sample_size(10);
    g.bench_function("train_step_8x1x384x384", |b| b.iter(|| trainer.step(&images).unwrap()));
    let (rgb, _) = synthetic_image(1024);
    let model = &trainer.model;
    g.bench_function("detect_rgb_1024x1024", |b| b.iter(|| detect_rgb(model, &rgb, 1024, 1024, &DecodeConfig::default()).unwrap()));
    // With the optional full-resolution mask branch (`tubeloc train --fine-mask`).
    let fine = LearnedModel::with_fine_mask(pre, 8, true, 1).unwrap();
    g.bench_function("detect_rgb_1024x1024_fine_mask", |b| b.iter(|| detect_rgb(&fine, &rgb, 1024, 1024, &DecodeConfig::default()).unwrap()));
    let (big, _) = synthetic_image(2560);
    g.bench_function("detect_rgb_2560x2560_default_heap", |b| b.iter(|| detect_rgb(model, &big, 2560, 2560, &DecodeConfig::default()).unwrap()));
    let kept = tubeloc_core::heap::keep_freed_memory();
    g.bench_function(if kept { "detect_rgb_2560x2560_kept_heap" } else { "detect_rgb_2560x2560_kept_heap_not_applied" }, |b| b.iter(|| detect_rgb(model, &big, 2560, 2560, &DecodeConfig::default()).unwrap()));
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
