//! Parity with pycocotools: every case of `common::cases()` is written to JSON, evaluated here
//! and by `scripts/coco_parity.py` (pycocotools' COCOeval), and the 12 stats, the full
//! precision (T x R x K x A x M) and recall (T x K x A x M) arrays must agree to 1e-9, and the
//! printed summary must be identical.
//!
//! Needs `python3` with pycocotools. Without it the test is skipped with a message, unless the
//! environment variable `CI` is set, in which case it fails.

use crate::common;

use std::process::Command;
use tubeloc_core::coco::load_results;
use tubeloc_core::CocoDataset;
use tubeloc_eval::coco_eval::{CocoEvaluator, IouType};

#[test]
fn coco_eval_matches_pycocotools() {
    if !common::have_pycocotools() {
        if std::env::var_os("CI").is_some() {
            panic!("CI is set but `python3 -c \"import pycocotools\"` fails: install pycocotools (pip install pycocotools)");
        }
        eprintln!("\n*** SKIPPED coco_eval_matches_pycocotools: python3 with pycocotools not found (pip install pycocotools) ***\n");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    for case in common::cases() {
        let gt_path = common::write(dir.path(), &format!("{}_gt.json", case.name), &case.gt);
        let dt_path = common::write(dir.path(), &format!("{}_dt.json", case.name), &case.dt);
        let out_path = dir.path().join(format!("{}_py.json", case.name));
        let run = Command::new("python3").arg(common::script("coco_parity.py")).args([&gt_path, &dt_path]).arg(case.iou_type).arg(&out_path).output().expect("python3 runs");
        assert!(run.status.success(), "{}: pycocotools failed: {}", case.name, String::from_utf8_lossy(&run.stderr));
        let py: serde_json::Value = serde_json::from_slice(&std::fs::read(&out_path).unwrap()).unwrap();

        let gt = CocoDataset::load(&gt_path).unwrap();
        let dt = load_results(&dt_path, &gt).unwrap();
        let iou_type: IouType = case.iou_type.parse().unwrap();
        let res = CocoEvaluator::new(&gt, &dt, iou_type).unwrap().evaluate();
        compare(case.name, &res, &py);
    }
}

fn floats(v: &serde_json::Value) -> Vec<f64> {
    v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()
}

fn compare(name: &str, res: &tubeloc_eval::coco_eval::EvalResult, py: &serde_json::Value) {
    let stats = floats(&py["stats"]);
    for (i, (a, b)) in res.stats.iter().zip(&stats).enumerate() {
        assert!((a - b).abs() <= 1e-9, "{name}: stat {i}: rust {a} vs pycocotools {b}");
    }
    // The fixtures must exercise the metrics: most stats defined and not trivially 0 or 1.
    let informative = stats.iter().filter(|&&s| s > 0.0 && s < 1.0).count();
    assert!(informative >= 6, "{name}: fixture too easy: {stats:?}");
    let shape: Vec<usize> = py["precision_shape"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap() as usize).collect();
    assert_eq!(shape, vec![10, 101, res.cat_ids.len(), 4, 3], "{name}");
    let p = floats(&py["precision"]);
    assert_eq!(p.len(), res.precision.len(), "{name}");
    for (i, (a, b)) in res.precision.iter().zip(&p).enumerate() {
        assert!((a - b).abs() <= 1e-9, "{name}: precision[{i}]: rust {a} vs pycocotools {b}");
    }
    let r = floats(&py["recall"]);
    assert_eq!(r.len(), res.recall.len(), "{name}");
    for (i, (a, b)) in res.recall.iter().zip(&r).enumerate() {
        assert!((a - b).abs() <= 1e-9, "{name}: recall[{i}]: rust {a} vs pycocotools {b}");
    }
    assert_eq!(res.summary_text(), py["summary"].as_str().unwrap(), "{name}: summary text");
}
