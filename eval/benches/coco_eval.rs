//! Speed of the COCO evaluation: 1000 images of 1280x960 with 3 tubes each and 100 mask
//! detections per image (compressed RLE, tube-sized: about 150 x 25 px), `segm`.
//! Measures `CocoEvaluator::new` (RLE decoding, IoUs) + `evaluate` (matching, accumulation).
//! Run: `cargo bench -p tubeloc-eval --bench coco_eval`.

use criterion::{criterion_group, criterion_main, Criterion};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde_json::json;
use tubeloc_core::{CocoDataset, CocoResult, Rle, Segmentation};
use tubeloc_eval::coco_eval::{CocoEvaluator, IouType};

const W: u32 = 1280;
const H: u32 = 960;

fn tube(rng: &mut ChaCha8Rng, cx: f64, cy: f64, ang: f64) -> Vec<f64> {
    let (len, wid) = (rng.random_range(130.0..170.0), rng.random_range(20.0..30.0));
    let (c, s) = (ang.cos(), ang.sin());
    [(-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5)]
        .iter()
        .flat_map(|&(u, v): &(f64, f64)| {
            let (a, b) = (u * len, v * wid);
            [cx + a * c - b * s, cy + a * s + b * c]
        })
        .collect()
}

fn dataset(n_images: usize, dets_per_image: usize) -> (CocoDataset, Vec<CocoResult>) {
    let per_image: Vec<(serde_json::Value, Vec<serde_json::Value>, Vec<serde_json::Value>)> = (0..n_images)
        .into_par_iter()
        .map(|i| {
            let mut rng = ChaCha8Rng::seed_from_u64(i as u64);
            let img = json!({"id": i + 1, "width": W, "height": H, "file_name": format!("{i}.png")});
            let mut anns = Vec::new();
            let mut dts = Vec::new();
            let centres: Vec<(f64, f64, f64)> = (0..3).map(|_| (rng.random_range(150.0..1130.0), rng.random_range(150.0..810.0), rng.random_range(0.0..std::f64::consts::PI))).collect();
            for (o, &(cx, cy, a)) in centres.iter().enumerate() {
                let rle = Rle::from_polygons(&[tube(&mut rng, cx, cy, a)], H, W).unwrap();
                anns.push(json!({"id": i * 3 + o + 1, "image_id": i + 1, "category_id": 1,
                    "segmentation": Segmentation::from_rle(&rle), "area": rle.area(), "bbox": rle.to_bbox(), "iscrowd": 0}));
            }
            for d in 0..dets_per_image {
                let (cx, cy, a) = if d < 30 {
                    let (cx, cy, a) = centres[d % 3];
                    (cx + rng.random_range(-15.0..15.0), cy + rng.random_range(-15.0..15.0), a + rng.random_range(-0.2..0.2))
                } else {
                    (rng.random_range(100.0..1180.0), rng.random_range(100.0..860.0), rng.random_range(0.0..std::f64::consts::PI))
                };
                let rle = Rle::from_polygons(&[tube(&mut rng, cx, cy, a)], H, W).unwrap();
                dts.push(json!({"image_id": i + 1, "category_id": 1, "score": rng.random_range(0.0..1.0),
                    "segmentation": Segmentation::from_rle(&rle)}));
            }
            (img, anns, dts)
        })
        .collect();
    let mut images = Vec::new();
    let mut anns = Vec::new();
    let mut dts = Vec::new();
    for (i, a, d) in per_image {
        images.push(i);
        anns.extend(a);
        dts.extend(d);
    }
    let gt: CocoDataset = serde_json::from_value(json!({"images": images, "annotations": anns, "categories": [{"id": 1, "name": "tube"}]})).unwrap();
    let dt: Vec<CocoResult> = serde_json::from_value(serde_json::Value::Array(dts)).unwrap();
    (gt, dt)
}

fn bench(c: &mut Criterion) {
    let (gt, dt) = dataset(1000, 100);
    let mut g = c.benchmark_group("coco_eval");
    g.sample_size(10);
    g.bench_function("segm_1000img_100det", |b| b.iter(|| CocoEvaluator::new(&gt, &dt, IouType::Segm).unwrap().evaluate().stats[0]));
    let ev = CocoEvaluator::new(&gt, &dt, IouType::Segm).unwrap();
    g.bench_function("segm_1000img_100det_evaluate_only", |b| b.iter(|| ev.evaluate().stats[0]));
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
