//! `tubeloc detect --method line2d` verifies Line2D's candidates by their poses (record 0068):
//! checked against the same candidates refined, snapped and scored by the CLI's separate
//! steps (`refine --snapped-out --pose-evidence`). Needs `../shared/data/real_mars` beside the
//! repository (composites on real grey frames with their cameras and ground).

use crate::common;

use common::*;
use serde_json::Value;
use std::path::Path;

/// The snapped candidates each image keeps: most probable first, none overlapping a kept one
/// at mask IoU above 0.5, at or above `cut`.
fn kept_by_rule(snapped: &[Value], cut: f64) -> Vec<Value> {
    let mut order: Vec<&Value> = snapped.iter().collect();
    order.sort_by(|a, b| score(b).total_cmp(&score(a)));
    let mut kept: Vec<Value> = Vec::new();
    for c in order.into_iter().filter(|c| score(c) >= cut) {
        if !kept.iter().any(|k| k["image_id"] == c["image_id"] && iou(&mask(k), &mask(c)) > 0.5) {
            kept.push(c.clone());
        }
    }
    kept
}

/// On composites on real Navcam frames (validation sols, each frame's own camera and ground):
/// every verified detection is a Line2D candidate (same template and clutter probability),
/// its mask and score are the candidate's snapped mask and pose evidence as `tubeloc refine`
/// gives them, and the detections are exactly the candidates the rule keeps at the shipped grey
/// cut; a verifier file with a limb check keeps a subset of them. A verifier file sets the cut; bad files and options are refused; without a ground the
/// clutter verifier's cut applies, with a note.
#[test]
fn verified_line2d_detections_are_the_candidates_their_pose_evidence_keeps() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (set, lib) = real_grey_val_set_and_library(d);
    let run = |args: &[&str], name: &str| -> (Vec<Value>, String) {
        let out = d.join(name);
        let mut all = vec!["detect", "--method", "line2d", "--templates", p(&lib), "--out", p(&out)];
        all.extend_from_slice(args);
        let o = ok(&all);
        (detections(&out), stderr(&o))
    };
    let (candidates, _) = run(&["--dataset", p(&set), "--min-probability", "0", "--pose-verifier", "off"], "candidates.json");
    let shipped: Value = serde_json::from_str(&std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/models/line2d.pose_verifier.json")).unwrap()).unwrap();
    let (verified, _) = run(&["--dataset", p(&set)], "verified.json");
    // A verifier file with a limb check (record 0080) keeps a subset of them.
    let mut with_limbs = shipped.clone();
    with_limbs["max_limb_continuation"] = serde_json::json!(0.6);
    let with_limbs_file = d.join("with_limbs.json");
    std::fs::write(&with_limbs_file, with_limbs.to_string()).unwrap();
    let (checked, _) = run(&["--dataset", p(&set), "--pose-verifier", p(&with_limbs_file)], "checked.json");
    assert!(!checked.is_empty() && checked.len() <= verified.len(), "{} with the limb check, {} without", checked.len(), verified.len());
    for c in &checked {
        assert!(verified.iter().any(|v| v["image_id"] == c["image_id"] && v["template_id"] == c["template_id"] && iou(&mask(v), &mask(c)) > 0.999), "{c} is no verified detection");
    }

    // The shipped verifier's evidence, and the candidates refined and scored by it.
    let evidence = d.join("evidence.json");
    std::fs::write(&evidence, shipped["evidence"].to_string()).unwrap();
    let snapped_path = d.join("snapped.json");
    ok(&["refine", "--dataset", p(&set), "--detections", p(&d.join("candidates.json")), "--ground", "auto", "--out", p(&d.join("poses.json")), "--snapped-out", p(&snapped_path), "--pose-evidence", p(&evidence)]);
    let snapped = detections(&snapped_path);
    assert_eq!(snapped.len(), candidates.len());
    let cut = shipped["threshold_grey"].as_f64().unwrap();
    let expected = kept_by_rule(&snapped, cut);

    assert!(!verified.is_empty(), "the composites' tubes give verified detections");
    assert!(verified.len() < candidates.len() / 4, "verification drops most candidates: {} of {}", verified.len(), candidates.len());
    assert_eq!(verified.len(), expected.len(), "verified {} vs kept by the rule {}", verified.len(), expected.len());
    for v in &verified {
        let s = score(v);
        assert_eq!(v["pose_probability"].as_f64().unwrap(), s, "{v}");
        assert!(s >= cut - 1e-6, "{v}");
        let c = candidates.iter().position(|c| c["image_id"] == v["image_id"] && c["template_id"] == v["template_id"] && c["probability"] == v["probability"]);
        let c = c.unwrap_or_else(|| panic!("verified detection is no Line2D candidate: {v}"));
        let e = &snapped[c];
        assert!((score(e) - s).abs() < 1e-5, "score {s} vs refine's {}", score(e));
        assert!(iou(&mask(e), &mask(v)) > 0.999, "the snapped mask");
        assert!(expected.iter().any(|x| x["image_id"] == e["image_id"] && x["template_id"] == e["template_id"] && (score(x) - score(e)).abs() < 1e-12), "{v} is kept by the rule");
    }
    for (k, v) in verified.iter().enumerate() {
        for w in &verified[k + 1..] {
            assert!(v["image_id"] != w["image_id"] || iou(&mask(v), &mask(w)) <= 0.5, "two verified detections overlap");
        }
    }

    // A verifier file sets the cuts: 0 keeps every candidate the suppression leaves, 1 none.
    let file = d.join("verifier.json");
    for (t, n) in [(0.0, kept_by_rule(&snapped, 0.0).len()), (1.0, 0)] {
        let mut v = shipped.clone();
        v["threshold_grey"] = serde_json::json!(t);
        std::fs::write(&file, v.to_string()).unwrap();
        let (got, _) = run(&["--dataset", p(&set), "--pose-verifier", p(&file)], "custom.json");
        assert_eq!(got.len(), n, "grey cut {t}");
    }
    // Refused, naming the file or the option.
    std::fs::write(&file, shipped.to_string().replace("\"nms_iou\":0.5", "\"nms_iou\":2.0")).unwrap();
    let o = tubeloc(&["detect", "--method", "line2d", "--templates", p(&lib), "--dataset", p(&set), "--out", p(&d.join("x.json")), "--pose-verifier", p(&file)]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains(&format!("--pose-verifier: pose verifier {}: nms_iou 2 is not in (0, 1]", p(&file))), "{}", stderr(&o));
    let o = tubeloc(&["detect", "--method", "line2d", "--templates", p(&lib), "--dataset", p(&set), "--out", p(&d.join("x.json")), "--no-verifier"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("--no-verifier needs --pose-verifier off"), "{}", stderr(&o));
    assert!(!d.join("x.json").exists(), "nothing written");

    // Without a ground plane the candidates are kept at the clutter verifier's cut, with a note.
    let mut no_ground: Value = serde_json::from_str(&std::fs::read_to_string(set.join("annotations.json")).unwrap()).unwrap();
    for im in no_ground["images"].as_array_mut().unwrap() {
        im.as_object_mut().unwrap().remove("ground");
    }
    let set2 = d.join("set_no_ground");
    std::fs::create_dir_all(&set2).unwrap();
    std::fs::write(set2.join("annotations.json"), no_ground.to_string()).unwrap();
    std::fs::create_dir_all(set2.join("images")).unwrap();
    for f in std::fs::read_dir(set.join("images")).unwrap() {
        let f = f.unwrap().path();
        std::fs::copy(&f, set2.join("images").join(f.file_name().unwrap())).unwrap();
    }
    let (plain, note) = run(&["--dataset", p(&set2)], "no_ground.json");
    let (plain_off, _) = run(&["--dataset", p(&set2), "--pose-verifier", "off"], "no_ground_off.json");
    assert!(note.contains("not verified by their poses"), "{note}");
    assert_eq!(plain, plain_off);
    assert!(plain.iter().all(|v| v.get("pose_probability").is_none()));
}
