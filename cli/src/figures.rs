//! Figures read back from the files the subcommands write (`eval --out`, `eval --poses --out`,
//! `calib groundtruth`), for the reports of `tubeloc demo` and `tubeloc bench`.

use anyhow::{Context, Result};
use serde_json::{json, Value};
use std::collections::BTreeMap;
use std::path::Path;
use tubeloc_core::files;

/// `(AP50, AR100)` from a `metrics.json` written by `tubeloc eval --out`.
pub fn ap50_ar(metrics: &Path) -> Option<(f64, f64)> {
    let v: Value = files::read_json(metrics).ok()?;
    let get = |name: &str| v["stats"].as_array()?.iter().find(|s| s["name"] == name)?["value"].as_f64();
    Some((get("AP50")?, get("AR100")?))
}

/// Tag-pair poses (`T_cam_tube_tags`, from `calib groundtruth`) against the renderer's exact
/// `T_cam_tube`, per camera height and per (two tags | one tag): count, median and p90 of the
/// centre distance (mm) and of the axis angle (deg).
pub fn tag_pose_errors(ann: &Path) -> Result<Value> {
    use tubeloc_core::Pose;
    let v: Value = files::read_json(ann)?;
    let height: BTreeMap<u64, f64> = v["images"].as_array().into_iter().flatten().filter_map(|im| Some((im["id"].as_u64()?, im["height_m"].as_f64()?))).collect();
    let mut groups: BTreeMap<String, (Vec<f64>, Vec<f64>)> = BTreeMap::new();
    for a in v["annotations"].as_array().into_iter().flatten() {
        let (Some(est), Some(gt)) = (a.get("T_cam_tube_tags"), a.get("T_cam_tube")) else { continue };
        let est: Pose = serde_json::from_value(est.clone()).with_context(|| format!("{}: T_cam_tube_tags", ann.display()))?;
        let gt: Pose = serde_json::from_value(gt.clone()).with_context(|| format!("{}: T_cam_tube", ann.display()))?;
        let e = tubeloc_eval::pose::pose_axis_error(&est, &gt);
        let h = a["image_id"].as_u64().and_then(|id| height.get(&id).copied()).unwrap_or(f64::NAN);
        let tags = if a["tags_pose"]["single_tag"].as_bool().unwrap_or(false) { "one tag" } else { "two tags" };
        let g = groups.entry(format!("{h} m, {tags}")).or_default();
        g.0.push(e.centre_distance_mm);
        g.1.push(e.axis_angle_deg);
    }
    let q = |x: &mut Vec<f64>, p: f64| {
        x.sort_by(f64::total_cmp);
        tubeloc_eval::pose_summary::percentile(x, p).unwrap_or(f64::NAN)
    };
    let mut r = serde_json::Map::new();
    for (k, (mut d, mut ang)) in groups {
        r.insert(k, json!({"n": d.len(), "pos_median_mm": q(&mut d, 50.0), "pos_p90_mm": q(&mut d, 90.0), "axis_median_deg": q(&mut ang, 50.0), "axis_p90_deg": q(&mut ang, 90.0)}));
    }
    Ok(Value::Object(r))
}

/// The pose table of a `report.md` written by `tubeloc eval --poses --out` (its header row
/// starts with `| poses |`), or `None` when absent.
pub fn pose_table(report_md: &Path) -> Option<String> {
    let md = std::fs::read_to_string(report_md).ok()?;
    let lines: Vec<&str> = md.lines().skip_while(|l| !(l.starts_with("| poses |") && l.contains("axis"))).take_while(|l| l.starts_with('|')).collect();
    (!lines.is_empty()).then(|| lines.join("\n") + "\n")
}

/// Markdown rows of [`tag_pose_errors`]'s result, with the table header.
pub fn tag_table(t: &serde_json::Map<String, Value>) -> String {
    let mut r = String::from("| camera height, tags seen | tubes | position median mm | p90 mm | axis median deg | p90 deg |\n|---|---|---|---|---|---|\n");
    for (k, g) in t {
        let f = |n: &str| g[n].as_f64().map(|x| format!("{x:.2}")).unwrap_or_default();
        r += &format!("| {k} | {} | {} | {} | {} | {} |\n", g["n"], f("pos_median_mm"), f("pos_p90_mm"), f("axis_median_deg"), f("axis_p90_deg"));
    }
    r
}
