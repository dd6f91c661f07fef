//! COCO evaluation without Python: numbers recorded from pycocotools 2.0.11 on a committed
//! fixture, breakdown semantics, hand-checked small cases and error messages.

use crate::common;

use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use tubeloc_core::coco::load_results;
use tubeloc_core::{CocoDataset, CocoResult};
use tubeloc_eval::breakdown::{breakdown, markdown_table};
use tubeloc_eval::coco_eval::{CocoEvaluator, EvalError, IouType};

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures")
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()
}

/// Regenerates the committed fixture (needs pycocotools):
/// `cargo test --release -p tubeloc-eval --test integration -- --ignored
/// coco_eval::regenerate`.
#[test]
#[ignore]
fn regenerate_fixture() {
    let (gt, dt) = common::make(11, 9, common::DtForm::Mask);
    let dir = fixtures();
    let g = common::write(&dir, "coco_small_gt.json", &gt);
    let d = common::write(&dir, "coco_small_dt.json", &dt);
    let out = dir.join("coco_small_pycocotools.json");
    let st = std::process::Command::new("python3").arg(common::script("coco_parity.py")).args([&g, &d]).arg("segm").arg(&out).status().unwrap();
    assert!(st.success());
}

#[test]
fn matches_numbers_recorded_from_pycocotools() {
    let dir = fixtures();
    let gt = CocoDataset::load(&dir.join("coco_small_gt.json")).unwrap();
    let dt = load_results(&dir.join("coco_small_dt.json"), &gt).unwrap();
    let want: Value = serde_json::from_slice(&std::fs::read(dir.join("coco_small_pycocotools.json")).unwrap()).unwrap();
    let res = CocoEvaluator::new(&gt, &dt, IouType::Segm).unwrap().evaluate();
    for (i, (a, b)) in res.stats.iter().zip(floats(&want["stats"])).enumerate() {
        assert!((a - b).abs() <= 1e-9, "stat {i}: {a} vs pycocotools {b}");
    }
    for (i, (a, b)) in res.precision.iter().zip(floats(&want["precision"])).enumerate() {
        assert!((a - b).abs() <= 1e-9, "precision[{i}]: {a} vs pycocotools {b}");
    }
    for (i, (a, b)) in res.recall.iter().zip(floats(&want["recall"])).enumerate() {
        assert!((a - b).abs() <= 1e-9, "recall[{i}]: {a} vs pycocotools {b}");
    }
    assert_eq!(res.precision.len(), floats(&want["precision"]).len());
    assert_eq!(res.summary_text(), want["summary"].as_str().unwrap());
    // PR curve accessor: category-mean of precision[t, :, k, all, 100].
    let curve = res.pr_curve(0);
    let k_def: Vec<usize> = (0..res.cat_ids.len()).filter(|&k| res.precision_at(0, 0, k, 0, 2) > -1.0).collect();
    let mean0 = k_def.iter().map(|&k| res.precision_at(0, 0, k, 0, 2)).sum::<f64>() / k_def.len() as f64;
    assert!((curve[0] - mean0).abs() < 1e-15 && curve.windows(2).all(|w| w[0] >= w[1]), "{curve:?}");
}

fn tiny_gt(anns: Value) -> CocoDataset {
    let v = json!({
        "images": [{"id": 1, "width": 100, "height": 100, "file_name": "a", "terrain": "sand"},
                   {"id": 2, "width": 100, "height": 100, "file_name": "b", "terrain": "rock"}],
        "annotations": anns, "categories": [{"id": 1, "name": "tube"}]});
    serde_json::from_value(v).unwrap()
}

fn boxes(list: &[(u64, [f64; 4], f64)]) -> Vec<CocoResult> {
    list.iter().map(|(img, bb, s)| serde_json::from_value(json!({"image_id": img, "category_id": 1, "score": s, "bbox": bb})).unwrap()).collect()
}

#[test]
fn breakdowns_by_image_and_annotation_attribute() {
    let gt = tiny_gt(json!([
        {"id": 1, "image_id": 1, "category_id": 1, "area": 400, "bbox": [10, 10, 20, 20], "occlusion": "none"},
        {"id": 2, "image_id": 1, "category_id": 1, "area": 400, "bbox": [50, 50, 20, 20], "occlusion": "partial"},
        {"id": 3, "image_id": 2, "category_id": 1, "area": 400, "bbox": [10, 10, 20, 20], "occlusion": "none"}]));
    // Image 1: both objects found. Image 2: only a false positive.
    let dt = boxes(&[(1, [10., 10., 20., 20.], 0.9), (1, [50., 50., 20., 20.], 0.8), (2, [60., 60., 20., 20.], 0.95)]);
    let ev = CocoEvaluator::new(&gt, &dt, IouType::Bbox).unwrap();
    let all = ev.evaluate();
    assert!((all.stats[8] - 2.0 / 3.0).abs() < 1e-12, "AR100 over all: {}", all.stats[8]);

    let by_terrain = breakdown(&ev, &gt, "terrain").unwrap();
    let rows: Vec<(&str, f64, f64)> = by_terrain.rows.iter().map(|r| (r.value.as_str(), r.result.stats[1], r.result.stats[8])).collect();
    // rock: one object, missed, one FP -> AP50 0, AR 0; sand: both found, no FP -> 1, 1
    // (precision is tp / (tp + fp + 2^-52), so "1" is 1 - 2^-52).
    assert_eq!((rows[0].0, rows[0].1, rows[0].2), ("rock", 0.0, 0.0));
    assert_eq!(rows[1].0, "sand");
    assert!((rows[1].1 - 1.0).abs() < 1e-12 && (rows[1].2 - 1.0).abs() < 1e-12, "{rows:?}");
    assert_eq!(by_terrain.rows[1].num_objects, 2);

    let by_occ = breakdown(&ev, &gt, "occlusion").unwrap();
    let none = &by_occ.rows[0];
    assert_eq!(none.value, "none");
    // "none": objects 1 and 3; the detection of object 2 is ignored (matched to an ignored gt).
    // Ranked: FP (0.95), TP (0.9): recall 1/2 reached at precision 1/2.
    assert!((none.result.stats[8] - 0.5).abs() < 1e-12);
    assert!((none.result.stats[1] - 0.5 * 51.0 / 101.0).abs() < 1e-12, "{}", none.result.stats[1]);
    let partial = &by_occ.rows[1];
    assert_eq!((partial.value.as_str(), partial.num_objects), ("partial", 1));
    assert!((partial.result.stats[8] - 1.0).abs() < 1e-12);

    let table = markdown_table(&[by_terrain, by_occ]);
    assert!(table.contains("| terrain | rock | 1 | 1 | 0.000 |"), "{table}");
    assert_eq!(table.lines().count(), 2 + 4);

    let e = breakdown(&ev, &gt, "weather").unwrap_err().to_string();
    assert!(e.contains("weather") && e.contains("no image"), "{e}");
}

#[test]
fn crowd_regions_absorb_detections_and_no_results_give_zero() {
    let gt = tiny_gt(json!([
        {"id": 1, "image_id": 1, "category_id": 1, "area": 400, "bbox": [10, 10, 20, 20]},
        {"id": 2, "image_id": 1, "category_id": 1, "area": 2500, "bbox": [40, 40, 50, 50], "iscrowd": 1}]));
    // Three detections inside the crowd box: ignored, not false positives.
    let dt = boxes(&[(1, [41., 41., 10., 10.], 0.99), (1, [60., 60., 10., 10.], 0.98), (1, [10., 10., 20., 20.], 0.5), (1, [70., 70., 10., 10.], 0.97)]);
    let res = CocoEvaluator::new(&gt, &dt, IouType::Bbox).unwrap().evaluate();
    assert!((res.stats[0] - 1.0).abs() < 1e-12, "{}", res.summary_text());
    // No results at all: AP and AR are 0 where ground truth exists (pycocotools would raise).
    let res = CocoEvaluator::new(&gt, &[], IouType::Bbox).unwrap().evaluate();
    assert_eq!(res.stats[0], 0.0);
    // The only medium object is a crowd region (ignored): AP medium is undefined.
    assert_eq!(res.stats[4], -1.0, "{}", res.summary_text());
    assert!(res.summary_text().lines().nth(4).unwrap().ends_with("= -1.000"));
}

#[test]
fn evaluator_errors_name_the_entry() {
    let gt = tiny_gt(json!([
        {"id": 1, "image_id": 1, "category_id": 1, "area": 400, "bbox": [10, 10, 20, 20]},
        {"id": 1, "image_id": 2, "category_id": 1, "area": 400, "bbox": [10, 10, 20, 20]}]));
    let e = CocoEvaluator::new(&gt, &[], IouType::Bbox).err().unwrap().to_string();
    assert!(e.contains("annotations[1] (id 1)") && e.contains("duplicate"), "{e}");

    let gt = tiny_gt(json!([{"id": 1, "image_id": 1, "category_id": 1, "area": 400, "bbox": [10, 10, 20, 20]}]));
    let dt = boxes(&[(1, [1., 1., 2., 2.], 0.5), (5, [1., 1., 2., 2.], 0.5)]);
    let e = CocoEvaluator::new(&gt, &dt, IouType::Bbox).err().unwrap().to_string();
    assert!(e.contains("results[1] (image_id 5)") && e.contains("not in the ground truth"), "{e}");
    // segm evaluation needs ground-truth masks
    let dt = boxes(&[(1, [1., 1., 2., 2.], 0.5)]);
    let e = CocoEvaluator::new(&gt, &dt, IouType::Segm).err().unwrap();
    assert!(matches!(e, EvalError::Entry { .. }) && e.to_string().contains("annotations[0] (id 1): no segmentation"), "{e}");
}

#[test]
fn shards_merge_and_results_with_wrong_mask_size_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (gt_v, dt_v) = common::make(21, 5, common::DtForm::Mask);
    let gt_path = common::write(dir.path(), "gt.json", &gt_v);
    let gt = CocoDataset::load(&gt_path).unwrap();
    let all = dt_v.as_array().unwrap().clone();
    let (a, b) = all.split_at(all.len() / 2);
    let pa = common::write(dir.path(), "a.json", &Value::Array(a.to_vec()));
    let pb = common::write(dir.path(), "b.json", &Value::Array(b.to_vec()));
    let mut merged = load_results(&pa, &gt).unwrap();
    merged.extend(load_results(&pb, &gt).unwrap());
    let full: Vec<CocoResult> = serde_json::from_value(dt_v.clone()).unwrap();
    assert_eq!(CocoEvaluator::new(&gt, &merged, IouType::Segm).unwrap().evaluate(), CocoEvaluator::new(&gt, &full, IouType::Segm).unwrap().evaluate());
    // A mask made for image 19 (64x48) attached to image 16 (120x90).
    let mut bad = all[..3].to_vec();
    let seg = all.iter().find(|d| d["image_id"] == 19).unwrap()["segmentation"].clone();
    bad[2] = json!({"image_id": 16, "category_id": 1, "score": 0.5, "segmentation": seg});
    let p = common::write(dir.path(), "bad.json", &Value::Array(bad));
    let e = load_results(&p, &gt).unwrap_err().to_string();
    assert!(e.contains("bad.json") && e.contains("results[2] (image_id 16)") && e.contains("[48, 64]"), "{e}");
}
