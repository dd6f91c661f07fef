//! The pose evidence: fitted by `tubeloc eval --fit-pose-evidence`, applied by `tubeloc refine
//! --snapped-out --pose-evidence`, checked on scenes it was not fitted on.

use crate::common;

use common::*;
use serde_json::Value;
use std::path::{Path, PathBuf};
use tubeloc_core::{CocoDataset, PoseEvidence, Rle, Segmentation, TubeAxisPose};

/// A rendered scene set and detections of it: each well visible tube's true mask at score
/// 0.6, and the same mask moved 60 px to the right (onto bare terrain) at score 0.95, so that
/// the scores rank every false detection above every tube.
fn scene_with_decoys(dir: &Path, seed: &str) -> (PathBuf, PathBuf) {
    let ds = dir.join(format!("scenes{seed}"));
    ok(&["synth", "--preset", "tiny", "--scenes", "3", "--scale", "0.5", "--resolution", "512", "--seed", seed, "--out", p(&ds)]);
    let gt = CocoDataset::load(&ds.join("annotations.json")).unwrap();
    let mut results = Vec::new();
    for a in &gt.annotations {
        if a.extra.get("visible_fraction").and_then(Value::as_f64).unwrap_or(0.0) < 0.8 {
            continue;
        }
        let im = gt.images.iter().find(|im| im.id == a.image_id).unwrap();
        let m = a.segmentation.as_ref().unwrap().to_rle(im.height, im.width).unwrap().to_mask().unwrap();
        let moved = tubeloc_core::BinaryMask::from_fn(m.width, m.height, |x, y| x >= 60 && m.get(x - 60, y));
        for (mask, score) in [(&m, 0.6), (&moved, 0.95)] {
            results.push(serde_json::json!({"image_id": a.image_id, "category_id": 1, "score": score, "segmentation": Segmentation::from_rle(&Rle::from_mask(mask))}));
        }
    }
    assert!(results.len() >= 8, "{} detections", results.len());
    let (raw, dets) = (dir.join(format!("raw{seed}.json")), dir.join(format!("dets{seed}.json")));
    std::fs::write(&raw, serde_json::to_string(&results).unwrap()).unwrap();
    ok(&["detect", "--method", "external", "--results", p(&raw), "--dataset", p(&ds), "--out", p(&dets)]);
    (ds, dets)
}

/// AP50 printed by `tubeloc eval`.
fn ap50(o: &std::process::Output) -> f64 {
    let out = String::from_utf8_lossy(&o.stdout);
    let line = out.lines().find(|l| l.contains("IoU=0.50 ") && l.contains("area=   all")).unwrap();
    line.rsplit('=').next().unwrap().trim().parse().unwrap()
}

#[test]
fn pose_evidence_fitted_on_some_scenes_ranks_tubes_first_on_others() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Fit on one set of scenes.
    let (ds, dets) = scene_with_decoys(d, "5");
    let (poses, snapped, model) = (d.join("poses5.json"), d.join("snapped5.json"), d.join("evidence.json"));
    ok(&["refine", "--dataset", p(&ds), "--detections", p(&dets), "--ground", "auto", "--out", p(&poses), "--snapped-out", p(&snapped)]);
    let o = ok(&["eval", "--gt", p(&ds.join("annotations.json")), "--dt", p(&snapped), "--fit-pose-evidence", p(&model), "--evidence-poses", p(&poses), "--fitted-on", "tiny seed 5"]);
    assert!(stderr(&o).contains("by the pose evidence"), "{}", stderr(&o));
    let m: PoseEvidence = serde_json::from_str(&std::fs::read_to_string(&model).unwrap()).unwrap();
    assert!(m.validate().is_ok());
    assert_eq!(m.fitted_on, "tiny seed 5");

    // Held out: other scenes, the same kind of decoys.
    let (ds, dets) = scene_with_decoys(d, "6");
    let gt = ds.join("annotations.json");
    let (poses, by_score, by_evidence) = (d.join("poses6.json"), d.join("by_score.json"), d.join("by_evidence.json"));
    ok(&["refine", "--dataset", p(&ds), "--detections", p(&dets), "--ground", "auto", "--out", p(&poses), "--snapped-out", p(&by_score)]);
    let o = ok(&["refine", "--dataset", p(&ds), "--detections", p(&dets), "--ground", "auto", "--out", p(&poses), "--snapped-out", p(&by_evidence), "--pose-evidence", p(&model)]);
    assert!(stderr(&o).contains("scored by their poses' evidence"), "{}", stderr(&o));
    // Each snapped detection's score is the model's probability of its pose; the poses keep
    // the detector's scores.
    let pose_list: Vec<TubeAxisPose> = serde_json::from_str(&std::fs::read_to_string(&poses).unwrap()).unwrap();
    let ranked = tubeloc_core::detection::read_coco_results(&by_evidence).unwrap();
    assert_eq!(pose_list.len(), ranked.len());
    for (pose, det) in pose_list.iter().zip(&ranked) {
        assert!((det.score - m.probability(pose)).abs() < 1e-12);
        assert!(pose.score == 0.6 || pose.score == 0.95, "pose score {}", pose.score);
    }
    // The best ranking possible: the true detections alone (tubes less visible have none, so
    // it is below 1).
    let true_only: Vec<Value> = serde_json::from_str::<Vec<Value>>(&std::fs::read_to_string(&by_score).unwrap()).unwrap().into_iter().filter(|d| d["score"] == 0.6).collect();
    let best = d.join("true_only.json");
    std::fs::write(&best, serde_json::to_string(&true_only).unwrap()).unwrap();
    let ap = |f: &Path| ap50(&ok(&["eval", "--gt", p(&gt), "--dt", p(f)]));
    let (a_best, a_score, a_evidence) = (ap(&best), ap(&by_score), ap(&by_evidence));
    assert!(a_score < a_best - 0.2, "ranked by score (decoys first): AP50 {a_score}, best {a_best}");
    assert!(a_evidence > a_best - 0.02, "ranked by the pose evidence: AP50 {a_evidence}, best {a_best}, by score {a_score}");

    // The shipped evidence is embedded and loads by name.
    ok(&["refine", "--dataset", p(&ds), "--detections", p(&dets), "--ground", "auto", "--out", p(&poses), "--snapped-out", p(&by_evidence), "--pose-evidence", "shipped"]);

    // Bad input: the error names the file and the problem; nothing is fitted or written.
    let bad = d.join("bad.json");
    std::fs::write(&bad, r#"{"features": ["x"], "mean": [0,0,0,0,0], "scale": [1,1,1,1,1], "weights": [0,0,0,0,0], "bias": 0}"#).unwrap();
    let o = tubeloc(&["refine", "--dataset", p(&ds), "--detections", p(&dets), "--out", p(&d.join("p.json")), "--snapped-out", p(&d.join("s.json")), "--pose-evidence", p(&bad)]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("bad.json") && stderr(&o).contains("features"), "{}", stderr(&o));
    assert!(!d.join("p.json").exists() && !d.join("s.json").exists());
    // One image: the same refusal, before the poses are written.
    let gt_doc = CocoDataset::load(&gt).unwrap();
    let (camera, image) = (d.join("camera.json"), ds.join("images").join(&gt_doc.images[0].file_name));
    std::fs::write(&camera, serde_json::to_string(&gt_doc.images[0].extra["camera"]).unwrap()).unwrap();
    let o =
        tubeloc(&["refine", "--image", p(&image), "--camera", p(&camera), "--detections", p(&dets), "--image-id", &gt_doc.images[0].id.to_string(), "--out", p(&d.join("p.json")), "--snapped-out", p(&d.join("s.json")), "--pose-evidence", p(&bad)]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("bad.json"), "{}", stderr(&o));
    assert!(!d.join("p.json").exists() && !d.join("s.json").exists());
    let o = tubeloc(&["refine", "--dataset", p(&ds), "--detections", p(&dets), "--out", p(&poses), "--pose-evidence", "shipped"]);
    assert_eq!(o.status.code(), Some(2), "--pose-evidence without --snapped-out");
    let (short, out) = (d.join("short.json"), d.join("never.json"));
    std::fs::write(&short, serde_json::to_string(&pose_list[..1]).unwrap()).unwrap();
    let o = tubeloc(&["eval", "--gt", p(&gt), "--dt", p(&by_score), "--fit-pose-evidence", p(&out), "--evidence-poses", p(&short)]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("short.json holds 1 poses") && stderr(&o).contains("by_score.json"), "{}", stderr(&o));
    assert!(!out.exists());
}
