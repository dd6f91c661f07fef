//! 95 % intervals of the real stage's figures by a bootstrap over sols
//! ([`tubeloc_eval::bootstrap`]): frames of one sol share terrain, light and pointing, so a sol
//! is resampled whole. Composites carry their frame's `sol` (`tubeloc synth real`); the
//! tube-free frames take theirs from the data's `MANIFEST.tsv`.

use anyhow::Result;
use serde_json::{json, Value};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use tubeloc_core::CocoDataset;
use tubeloc_eval::bootstrap::{groups_by_key, BootstrapSpec};
use tubeloc_eval::coco_eval::CocoEvaluator;

/// The bootstrap of every interval the stage reports: 2000 resamples, 95 %, seed 0.
pub fn spec() -> BootstrapSpec {
    BootstrapSpec::default()
}

/// A frame's group: its sol, or the frame alone when its sol is unknown.
fn key(sol: Option<i64>, frame: usize) -> (Option<i64>, usize) {
    match sol {
        Some(s) => (Some(s), 0),
        None => (None, frame),
    }
}

/// AP50 and AR intervals of `ev` (on the composite set `gt`) by the composites' sols:
/// `{"ap50_ci": [lo, hi], "ar_ci": [lo, hi], "sols": n}`.
/// `Null` when no composite carries a sol.
pub fn ap_ar_by_sol(gt: &CocoDataset, ev: &CocoEvaluator) -> Value {
    match tubeloc_eval::breakdown::intervals_by_image_attribute(ev, gt, "sol", &spec()) {
        Ok(i) => json!({"ap50_ci": [i.ap50.lo, i.ap50.hi], "ar_ci": [i.ar.lo, i.ar.hi], "sols": i.ap50.groups}),
        Err(_) => Value::Null,
    }
}

/// The interval of the median of a pose error `field` (an entry of each pair's `axis`: e.g.
/// `axis_angle_deg`, `perpendicular_mm`; `along_axis_abs_mm` is the absolute `along_axis_mm`)
/// over the matched `pairs` of a pose evaluation (`pose_eval.json`), resampling the sols of
/// their composites in `gt`: `[lo, hi]`, or `Null` without pairs.
pub fn median_by_sol(gt: &CocoDataset, pairs: &Value, field: &str) -> Value {
    let sols: HashMap<u64, Option<i64>> = gt.images.iter().map(|im| (im.id, im.extra.get("sol").and_then(Value::as_i64))).collect();
    let Some(pairs) = pairs.as_array().filter(|p| !p.is_empty()) else { return Value::Null };
    let value = |p: &Value| match field {
        "along_axis_abs_mm" => p["axis"]["along_axis_mm"].as_f64().map(f64::abs),
        f => p["axis"][f].as_f64(),
    };
    let ids: Vec<u64> = pairs.iter().map(|p| p["image_id"].as_u64().unwrap_or(0)).collect();
    let groups = groups_by_key(ids.iter().map(|id| key(sols.get(id).copied().flatten(), *id as usize)));
    let values: Vec<Vec<f64>> = groups.iter().map(|g| g.iter().filter_map(|&i| value(&pairs[i])).filter(|v| v.is_finite()).collect()).collect();
    let i = spec().pooled_statistic(&values, &tubeloc_eval::bootstrap::median);
    json!([i.lo, i.hi])
}

/// The sol of each frame in `data`'s `MANIFEST.tsv`, by its path relative to `data`.
pub fn manifest_sols(data: &Path) -> Result<HashMap<PathBuf, i64>> {
    let rows = tubeloc_synth::real_frames::read_manifest(&data.join("MANIFEST.tsv"))?;
    Ok(rows.into_iter().filter_map(|r| Some((r.file, r.sol?))).collect())
}

/// The interval of `Σ per_frame[i][field] / frames` over the frames `per_frame` (each with the
/// sol `sols[i]`, `None` when unknown): `{"lo", "hi", "sols"}`.
pub fn per_frame_by_sol(per_frame: &[Value], sols: &[Option<i64>], field: &str) -> Value {
    let groups = groups_by_key(sols.iter().enumerate().map(|(i, s)| key(*s, i)));
    let per_group: Vec<(f64, f64)> = groups.iter().map(|g| (g.iter().map(|&i| per_frame[i][field].as_f64().unwrap_or(0.0)).sum(), g.len() as f64)).collect();
    let i = spec().ratio_of_sums(&per_group);
    json!({"lo": i.lo, "hi": i.hi, "sols": i.groups})
}

/// `" [lo, hi]"` from the two-number array `v`, or nothing when it is absent.
pub fn bracket(v: &Value) -> String {
    match (v[0].as_f64(), v[1].as_f64()) {
        (Some(lo), Some(hi)) => format!(" [{lo:.2}, {hi:.2}]"),
        _ => String::new(),
    }
}

/// `" (95 % interval by sol lo-hi, n sols)"` from [`per_frame_by_sol`]'s value, or nothing.
pub fn by_sol_note(v: &Value) -> String {
    match (v["lo"].as_f64(), v["hi"].as_f64()) {
        (Some(lo), Some(hi)) => format!(" (95 % interval by sol {lo:.2}-{hi:.2}, {} sols)", v["sols"]),
        _ => String::new(),
    }
}
