//! `tubeloc detect --method fused`: Line2D candidates scored by the learned segmenter's
//! agreement, checked against the two detectors run on their own. Needs
//! `../shared/data/real_mars` beside the repository (composites on real grey frames).

mod common;

use common::*;
use serde_json::Value;
use std::path::Path;
use tubeloc_core::{Rle, Segmentation};

fn detections(path: &Path) -> Vec<Value> {
    serde_json::from_str::<Value>(&std::fs::read_to_string(path).unwrap()).unwrap().as_array().unwrap().clone()
}

fn mask(v: &Value) -> Rle {
    let size = &v["segmentation"]["size"];
    let (h, w) = (size[0].as_u64().unwrap() as u32, size[1].as_u64().unwrap() as u32);
    let seg: Segmentation = serde_json::from_value(v["segmentation"].clone()).unwrap();
    seg.to_rle(h, w).unwrap()
}

fn iou(a: &Rle, b: &Rle) -> f64 {
    Rle::iou(std::slice::from_ref(a), std::slice::from_ref(b), &[false])[0]
}

/// On composites on real Navcam frames (validation sols, each frame's own camera and ground):
/// every fused detection is a Line2D candidate (same template, box and verifier probability
/// as Line2D with every candidate kept), its agreement is the best score of a learned
/// detection overlapping it at mask IoU >= 0.3 (never 0: a candidate the network does not see
/// is dropped), its score is P L, at least 0.02, and each image's list runs strongest first.
#[test]
fn fused_detections_are_line2d_candidates_scored_by_learned_agreement() {
    let dir = tempfile::tempdir().unwrap();
    let real = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/real_mars");
    assert!(real.join("MANIFEST.tsv").exists(), "{} is missing: this test needs ../shared/data beside the repository", real.display());
    let set = dir.path().join("set");
    ok(&["synth", "real", "--data", p(&real), "--split", "val", "--kind", "grey", "--per-view", "1", "--limit", "3", "--seed", "3", "--out", p(&set)]);
    let lib = dir.path().join("default.tlt");
    ok(&["templates", "build", "--out", p(&lib)]);
    let run = |args: &[&str], name: &str| -> Vec<Value> {
        let out = dir.path().join(name);
        let mut all = vec!["detect", "--dataset", p(&set), "--out", p(&out)];
        all.extend_from_slice(args);
        ok(&all);
        detections(&out)
    };
    let fused = run(&["--method", "fused", "--templates", p(&lib)], "fused.json");
    let candidates = run(&["--method", "line2d", "--templates", p(&lib), "--min-probability", "0"], "candidates.json");
    let learned = run(&["--method", "learned"], "learned.json");
    assert!(!fused.is_empty(), "the composites' tubes give fused detections");
    assert!(fused.len() < candidates.len(), "the fusion drops candidates: {} of {}", fused.len(), candidates.len());
    for (k, f) in fused.iter().enumerate() {
        let same = candidates.iter().find(|c| c["image_id"] == f["image_id"] && c["template_id"] == f["template_id"] && c["bbox"] == f["bbox"]);
        let c = same.unwrap_or_else(|| panic!("fused detection {k} is no Line2D candidate: {f}"));
        let prob = f["probability"].as_f64().unwrap();
        assert_eq!(prob, c["probability"].as_f64().unwrap(), "{f}");
        let m = mask(f);
        let best = learned.iter().filter(|l| l["image_id"] == f["image_id"] && iou(&mask(l), &m) >= 0.3).map(|l| l["score"].as_f64().unwrap()).fold(0.0, f64::max);
        let agreement = f["agreement"].as_f64().unwrap();
        assert!((agreement - best).abs() < 1e-6, "agreement {agreement}, best overlapping learned score {best}: {f}");
        assert!(agreement > 0.0, "{f}");
        let score = f["score"].as_f64().unwrap();
        assert!((score - prob * agreement).abs() < 1e-5, "{f}");
        assert!(score >= 0.02 - 1e-6, "{f}");
        if k > 0 && fused[k - 1]["image_id"] == f["image_id"] {
            assert!(fused[k - 1]["score"].as_f64().unwrap() >= score, "strongest first in each image");
        }
    }

    // `--fusion-config` sets the fusion: a higher cut keeps the fused detections at or above it.
    let cfg = dir.path().join("fusion.json");
    std::fs::write(&cfg, r#"{"threshold": 0.2}"#).unwrap();
    let strict = run(&["--method", "fused", "--templates", p(&lib), "--fusion-config", p(&cfg)], "strict.json");
    let above: Vec<&Value> = fused.iter().filter(|f| f["score"].as_f64().unwrap() >= 0.2 - 1e-6).collect();
    assert_eq!(strict.len(), above.len(), "--fusion-config threshold 0.2");
    // A misspelt or out-of-range field is refused, naming the file; the option belongs to fused.
    for (text, expect) in [(r#"{"min_iouu": 0.3}"#, "unknown field `min_iouu`"), (r#"{"threshold": 0}"#, "threshold 0 must be in (0, 1]")] {
        std::fs::write(&cfg, text).unwrap();
        let o = tubeloc(&["detect", "--method", "fused", "--templates", p(&lib), "--fusion-config", p(&cfg), "--dataset", p(&set), "--out", p(&dir.path().join("x.json"))]);
        assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
        assert!(stderr(&o).contains("fusion.json") && stderr(&o).contains(expect), "{}", stderr(&o));
    }
    let o = tubeloc(&["detect", "--method", "line2d", "--templates", p(&lib), "--fusion-config", p(&cfg), "--dataset", p(&set), "--out", p(&dir.path().join("x.json"))]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(!dir.path().join("x.json").exists(), "no output on error");
    // The verifier's cut does not apply: every candidate it scores is fused.
    let o = tubeloc(&["detect", "--method", "fused", "--templates", p(&lib), "--min-probability", "0.5", "--dataset", p(&set), "--out", p(&dir.path().join("x.json"))]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--min-probability is the Line2D verifier's cut"), "{}", stderr(&o));
    // Line2D without its templates is a usage error naming the option.
    let o = tubeloc(&["detect", "--method", "fused", "--dataset", p(&set), "--out", p(&dir.path().join("x.json"))]);
    assert_ne!(o.status.code(), Some(0));
    assert!(stderr(&o).contains("--templates"), "{}", stderr(&o));
}
