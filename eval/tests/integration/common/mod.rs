//! Deterministic COCO fixtures for the evaluation tests: tube-like rotated rectangles on images
//! of a few sizes, with edge cases (images without ground truth or without detections, tied
//! scores, crowd regions, tiny objects, an area exactly on a range boundary, more than 100
//! detections in one image, a category without ground truth, polygons and both RLE forms).
#![allow(dead_code)]

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use tubeloc_core::{Rle, Segmentation};

/// One evaluation case: ground truth, results and the IoU type to evaluate.
pub struct Case {
    pub name: &'static str,
    pub gt: Value,
    pub dt: Value,
    pub iou_type: &'static str,
}

/// How results carry their geometry.
#[derive(Clone, Copy, PartialEq)]
pub enum DtForm {
    /// Compressed RLE only (pycocotools' "segm" results).
    Mask,
    /// Compressed RLE plus a box (loadRes then takes areas from the boxes).
    MaskAndBox,
    /// A box only.
    Box,
}

fn tube_polygon(cx: f64, cy: f64, len: f64, wid: f64, ang: f64) -> Vec<f64> {
    let (c, s) = (ang.cos(), ang.sin());
    let mut p = Vec::with_capacity(8);
    for (u, v) in [(-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5)] {
        let (a, b) = (u * len, v * wid);
        p.push(cx + a * c - b * s);
        p.push(cy + a * s + b * c);
    }
    p
}

fn seg_value(seg: &Segmentation) -> Value {
    serde_json::to_value(seg).unwrap()
}

/// Builds a dataset and results with the given seed.
pub fn make(seed: u64, n_images: usize, form: DtForm) -> (Value, Value) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let sizes = [(64u32, 48u32), (200, 160), (120, 90)];
    let scores = [0.9, 0.8, 0.8, 0.5, 0.3, 0.3];
    let mut images = Vec::new();
    let mut anns = Vec::new();
    let mut dts = Vec::new();
    let mut ann_id = 1u64;
    for i in 0..n_images {
        let img_id = 10 + 3 * i as u64; // non-contiguous ids
        let (w, h) = sizes[i % sizes.len()];
        let terrain = ["sand", "rock", "bedrock"][i % 3];
        images.push(json!({"id": img_id, "width": w, "height": h, "file_name": format!("{img_id}.png"),
                           "terrain": terrain, "time": if i % 2 == 0 { "noon" } else { "dusk" }}));
        let n_obj = if i == 0 { 0 } else { rng.random_range(1..5) };
        let no_dets = i == 1;
        for o in 0..n_obj {
            let big = w >= 200 && o == 0;
            let (len, wid) = if big {
                (rng.random_range(110.0..170.0), rng.random_range(70.0..100.0))
            } else if o % 3 == 2 {
                (rng.random_range(4.0..9.0), rng.random_range(2.0..4.0)) // tiny
            } else {
                (rng.random_range(15.0..60.0), rng.random_range(6.0..20.0))
            };
            let cx = rng.random_range(0.2..0.8) * w as f64;
            let cy = rng.random_range(0.2..0.8) * h as f64;
            let ang = rng.random_range(0.0..3.1);
            let poly = tube_polygon(cx, cy, len, wid, ang);
            let rle = Rle::from_polygons(std::slice::from_ref(&poly), h, w).unwrap();
            let crowd = o == 3;
            let cat = if rng.random_bool(0.7) { 1 } else { 2 };
            let seg = match (crowd, rng.random_range(0..3)) {
                (true, _) | (_, 2) => json!({"size": [h, w], "counts": rle.counts}),
                (_, 0) => json!([poly]),
                _ => seg_value(&Segmentation::from_rle(&rle)),
            };
            let mut area = rle.area() as f64;
            if i == 2 && o == 0 {
                area = 1024.0; // exactly on the small/medium boundary (both ranges include it)
            }
            let bb = rle.to_bbox();
            let occl = ["none", "partial"][rng.random_range(0..2)];
            anns.push(json!({"id": ann_id, "image_id": img_id, "category_id": cat, "segmentation": seg,
                             "area": area, "bbox": bb, "iscrowd": crowd as u8, "occlusion": occl}));
            ann_id += 1;
            if no_dets {
                continue;
            }
            // Detections: near-copies (some duplicated), several inside crowd regions.
            let copies = if crowd {
                3
            } else if rng.random_bool(0.2) {
                0
            } else if rng.random_bool(0.2) {
                2
            } else {
                1
            };
            for _ in 0..copies {
                let dp = tube_polygon(cx + rng.random_range(-3.0..3.0), cy + rng.random_range(-3.0..3.0), len * rng.random_range(0.8..1.2), wid * rng.random_range(0.8..1.2), ang + rng.random_range(-0.15..0.15));
                let dcat = if rng.random_bool(0.9) { cat } else { 3 - cat };
                let score = scores[rng.random_range(0..scores.len())];
                dts.push(det(img_id, dcat, score, &dp, h, w, form, &mut rng));
            }
        }
        // False positives, and over 100 detections in image 3.
        let n_fp = if i == 3 {
            130
        } else if no_dets {
            0
        } else {
            rng.random_range(0..4)
        };
        for _ in 0..n_fp {
            let dp = tube_polygon(rng.random_range(0.0..w as f64), rng.random_range(0.0..h as f64), rng.random_range(5.0..40.0), rng.random_range(3.0..12.0), rng.random_range(0.0..3.1));
            let score = if i == 3 { rng.random_range(0.0..1.0) } else { scores[rng.random_range(0..scores.len())] };
            dts.push(det(img_id, rng.random_range(1..3), score, &dp, h, w, form, &mut rng));
        }
    }
    let gt = json!({
        "info": {"description": format!("tubeloc eval fixture seed {seed}")},
        "images": images, "annotations": anns,
        "categories": [{"id": 1, "name": "tube"}, {"id": 2, "name": "cap"}, {"id": 3, "name": "unused"}],
    });
    (gt, Value::Array(dts))
}

#[allow(clippy::too_many_arguments)]
fn det(img: u64, cat: u64, score: f64, poly: &[f64], h: u32, w: u32, form: DtForm, rng: &mut ChaCha8Rng) -> Value {
    let rle = Rle::from_polygons(&[poly.to_vec()], h, w).unwrap();
    let bb = rle.to_bbox();
    let noisy = [bb[0] + rng.random_range(-0.5..0.5), bb[1] + rng.random_range(-0.5..0.5), bb[2] + rng.random_range(-0.5..0.5), bb[3] + rng.random_range(-0.5..0.5)];
    match form {
        DtForm::Mask => json!({"image_id": img, "category_id": cat, "score": score, "segmentation": seg_value(&Segmentation::from_rle(&rle))}),
        DtForm::MaskAndBox => json!({"image_id": img, "category_id": cat, "score": score,
                                     "segmentation": seg_value(&Segmentation::from_rle(&rle)), "bbox": noisy}),
        DtForm::Box => json!({"image_id": img, "category_id": cat, "score": score, "bbox": noisy}),
    }
}

/// The parity cases.
pub fn cases() -> Vec<Case> {
    let mut out = Vec::new();
    let (gt, dt) = make(1, 14, DtForm::Mask);
    out.push(Case { name: "segm_masks", gt, dt, iou_type: "segm" });
    let (gt, dt) = make(2, 14, DtForm::MaskAndBox);
    out.push(Case { name: "segm_masks_with_boxes", gt, dt, iou_type: "segm" });
    let (gt, dt) = make(3, 14, DtForm::Box);
    out.push(Case { name: "bbox_boxes", gt, dt, iou_type: "bbox" });
    let (gt, dt) = make(4, 10, DtForm::Box);
    out.push(Case { name: "segm_from_boxes", gt, dt, iou_type: "segm" });
    let (gt, dt) = make(5, 10, DtForm::Mask);
    out.push(Case { name: "bbox_from_masks", gt, dt, iou_type: "bbox" });
    // Few detections, all on one image: most cells have ground truth and no detections.
    let (gt, mut dt) = make(6, 8, DtForm::Mask);
    if let Value::Array(v) = &mut dt {
        v.retain(|d| d["image_id"] == 16);
    }
    out.push(Case { name: "sparse_detections", gt, dt, iou_type: "segm" });
    out
}

/// Writes `value` as JSON to `dir/name` and returns the path.
pub fn write(dir: &Path, name: &str, value: &Value) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, serde_json::to_vec(value).unwrap()).unwrap();
    p
}

/// Whether `python3 -c "import pycocotools"` works.
pub fn have_pycocotools() -> bool {
    std::process::Command::new("python3").args(["-c", "import pycocotools.cocoeval"]).output().map(|o| o.status.success()).unwrap_or(false)
}

/// Path of a file under the repository's `scripts/`.
pub fn script(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts").join(name)
}
