//! `tubeloc detect --method fused`: the learned detections and Line2D's pose-verified ones in
//! one list by their pose evidence (record 0069), checked against the two detectors run on
//! their own and the learned detections refined and scored by `tubeloc refine`. Needs
//! `../shared/data/real_mars` beside the repository (composites on real grey frames).

use crate::common;

use common::*;
use serde_json::Value;

/// On composites on real Navcam frames (validation sols, each frame's own camera and ground):
/// every fused detection is a learned detection snapped and scored by the shipped pose
/// evidence (as `tubeloc refine --snapped-out --pose-evidence shipped` gives it) or a verified
/// Line2D detection (as `tubeloc detect --method line2d` gives it); every detection of either
/// that is not fused overlaps a more probable fused one at mask IoU > 0.5; fused detections do
/// not overlap one another and run most probable first in each image.
#[test]
fn fused_detections_are_the_learned_and_verified_line2d_ones_by_pose_evidence() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (set, lib) = real_grey_val_set_and_library(d);
    let run = |args: &[&str], name: &str| -> Vec<Value> {
        let out = d.join(name);
        let mut all = vec!["detect", "--dataset", p(&set), "--out", p(&out)];
        all.extend_from_slice(args);
        ok(&all);
        detections(&out)
    };
    let fused = run(&["--method", "fused", "--templates", p(&lib)], "fused.json");
    let verified = run(&["--method", "line2d", "--templates", p(&lib)], "line2d.json");
    run(&["--method", "learned"], "learned.json");
    let scored = d.join("scored.json");
    ok(&["refine", "--dataset", p(&set), "--detections", p(&d.join("learned.json")), "--ground", "auto", "--out", p(&d.join("poses.json")), "--snapped-out", p(&scored), "--pose-evidence", "shipped"]);
    let learned = detections(&scored);
    assert!(!fused.is_empty() && !learned.is_empty() && !verified.is_empty());

    let same = |a: &Value, b: &Value| a["image_id"] == b["image_id"] && (score(a) - score(b)).abs() < 1e-5 && iou(&mask(a), &mask(b)) > 0.999;
    let (mut from_learned, mut from_line2d) = (0, 0);
    for f in &fused {
        if f.get("template_id").is_some() {
            assert!(verified.iter().any(|v| v["template_id"] == f["template_id"] && v["probability"] == f["probability"] && same(v, f)), "a Line2D fused detection is a verified one: {f}");
            from_line2d += 1;
        } else {
            assert!(learned.iter().any(|l| same(l, f)), "a learned fused detection is a snapped, scored one");
            from_learned += 1;
        }
    }
    assert!(from_learned > 0 && from_line2d > 0, "both detectors contribute: {from_learned} learned, {from_line2d} Line2D");
    for (k, f) in fused.iter().enumerate() {
        for g in &fused[k + 1..] {
            if f["image_id"] == g["image_id"] {
                assert!(iou(&mask(f), &mask(g)) <= 0.5, "two fused detections overlap");
                assert!(score(f) >= score(g), "most probable first in each image");
            }
        }
    }
    for c in learned.iter().chain(&verified) {
        if fused.iter().any(|f| same(f, c)) {
            continue;
        }
        assert!(fused.iter().any(|f| f["image_id"] == c["image_id"] && score(f) >= score(c) - 1e-6 && iou(&mask(f), &mask(c)) > 0.5), "a detection left out overlaps a more probable fused one");
    }

    // The fusion needs the pose verifier; the error names the way out. (Without --templates
    // it searches with the default library: `cli.rs`.)
    let x = d.join("x.json");
    let o = tubeloc(&["detect", "--method", "fused", "--templates", p(&lib), "--pose-verifier", "off", "--dataset", p(&set), "--out", p(&x)]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("leave out --pose-verifier off"), "{}", stderr(&o));
    assert!(!x.exists(), "no output on error");
}
