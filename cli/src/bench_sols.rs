//! Where a detector holds and where it fails: AP50 and AR on each sol of a composite set, with
//! the rover camera that took the sol's frames. A pooled figure over a handful of sols hides
//! how far apart they are; a V&V engineer asks which cameras and terrains it holds on.

use anyhow::Result;
use serde_json::{json, Value};
use std::collections::{BTreeMap, BTreeSet};
use tubeloc_core::{CocoDataset, RoverCamera};
use tubeloc_eval::coco_eval::CocoEvaluator;

/// The camera of a composite: [`RoverCamera::name`] of its background frame's product name
/// (the image's `background` field), or `"unknown"`.
fn camera_of(im: &tubeloc_core::CocoImage) -> String {
    im.extra.get("background").and_then(Value::as_str).and_then(RoverCamera::of_product).map_or_else(|| "unknown".to_string(), |c| c.name())
}

/// For each sol of `gt`'s images (the `sol` field; images without one are left out), in
/// increasing order: `{"sol", "cameras", "images", "tubes", "ap50", "ar"}` of `ev` (prepared on
/// `gt`) on that sol's images alone ([`tubeloc_eval::breakdown::breakdown`] by `sol`);
/// `cameras` lists the distinct cameras of its frames ([`camera_of`]). `Null` when no image
/// carries a sol.
pub fn by_sol(gt: &CocoDataset, ev: &CocoEvaluator) -> Result<Value> {
    let mut cameras: BTreeMap<i64, BTreeSet<String>> = BTreeMap::new();
    for im in &gt.images {
        if let Some(s) = im.extra.get("sol").and_then(Value::as_i64) {
            cameras.entry(s).or_default().insert(camera_of(im));
        }
    }
    if cameras.is_empty() {
        return Ok(Value::Null);
    }
    let rows: BTreeMap<i64, Value> = tubeloc_eval::breakdown::breakdown(ev, gt, "sol")?
        .rows
        .into_iter()
        .filter_map(|r| {
            let sol: i64 = r.value.parse().ok()?;
            let cameras: Vec<&String> = cameras.get(&sol)?.iter().collect();
            Some((sol, json!({"sol": sol, "cameras": cameras, "images": r.num_images, "tubes": r.num_objects, "ap50": r.result.stats[1], "ar": r.result.stats[8]})))
        })
        .collect();
    Ok(Value::Array(rows.into_values().collect()))
}

/// A markdown table of [`by_sol`] results of several detectors on one set: one row per sol
/// (its cameras, images and tubes from the first detector that has the sol), one "AP50 / AR"
/// column per `(name, rows)`; `-` where a detector has no figure for the sol (AP undefined, or
/// the sol absent). `None` when no detector has rows.
pub fn table(detectors: &[(&str, &Value)]) -> Option<String> {
    let detectors: Vec<(&str, &Vec<Value>)> = detectors.iter().filter_map(|(name, v)| Some((*name, v.as_array()?))).collect();
    let mut sols: BTreeMap<i64, &Value> = BTreeMap::new();
    for (_, rows) in &detectors {
        for r in rows.iter() {
            if let Some(s) = r["sol"].as_i64() {
                sols.entry(s).or_insert(r);
            }
        }
    }
    if sols.is_empty() {
        return None;
    }
    let names: Vec<&str> = detectors.iter().map(|d| d.0).collect();
    let mut md = format!("| sol | camera | images | tubes | {} |\n|---:|---|---:|---:|{}\n", names.join(" | "), "---|".repeat(names.len()));
    for (sol, first) in sols {
        let cameras: Vec<&str> = first["cameras"].as_array().map(|c| c.iter().filter_map(Value::as_str).collect()).unwrap_or_default();
        let cells: Vec<String> = detectors
            .iter()
            .map(|(_, rows)| {
                let r = rows.iter().find(|r| r["sol"].as_i64() == Some(sol));
                match r.and_then(|r| Some((r["ap50"].as_f64().filter(|v| *v >= 0.0)?, r["ar"].as_f64().filter(|v| *v >= 0.0)?))) {
                    Some((ap, ar)) => format!("{ap:.3} / {ar:.3}"),
                    None => "-".to_string(),
                }
            })
            .collect();
        md.push_str(&format!("| {sol} | {} | {} | {} | {} |\n", cameras.join(", "), first["images"], first["tubes"], cells.join(" | ")));
    }
    Some(md)
}

#[cfg(test)]
mod tests {
    use super::*;
    use tubeloc_core::CocoResult;
    use tubeloc_eval::coco_eval::IouType;

    /// Two sols of two cameras: a detection on the one tube of sol 53 (MSL Navcam) scores it
    /// AP50 1, none on sol 5105's (MER Pancam) scores it 0; the image without a sol is left out;
    /// the table has a row per sol, in order, and a column per detector.
    #[test]
    fn each_sol_is_scored_on_its_own_frames_with_its_camera() {
        let square = |x: f64| json!([[x, 10, x + 20.0, 10, x + 20.0, 30, x, 30]]);
        let ds: CocoDataset = serde_json::from_value(json!({
            "images": [
                {"id": 1, "width": 100, "height": 100, "sol": 5105, "background": "real/1p581379812rsdd2fcp2398l2m1.png"},
                {"id": 2, "width": 100, "height": 100, "sol": 53, "background": "real/NLA_402200516EDR_F0043212NCAM00315M_.jpg"},
                {"id": 3, "width": 100, "height": 100}
            ],
            "annotations": [
                {"id": 1, "image_id": 1, "category_id": 1, "area": 400.0, "bbox": [10, 10, 20, 20], "segmentation": square(10.0)},
                {"id": 2, "image_id": 2, "category_id": 1, "area": 400.0, "bbox": [10, 10, 20, 20], "segmentation": square(10.0)},
                {"id": 3, "image_id": 3, "category_id": 1, "area": 400.0, "bbox": [10, 10, 20, 20], "segmentation": square(10.0)}
            ],
            "categories": [{"id": 1, "name": "tube"}]
        }))
        .unwrap();
        let det = |image_id: u64, x: f64| serde_json::from_value::<CocoResult>(json!({"image_id": image_id, "category_id": 1, "score": 0.9, "segmentation": square(x)})).unwrap();
        let dt = vec![det(1, 60.0), det(2, 10.0), det(3, 10.0)];
        let ev = CocoEvaluator::new(&ds, &dt, IouType::Segm).unwrap();
        let v = by_sol(&ds, &ev).unwrap();
        let rows = v.as_array().unwrap();
        assert_eq!(rows.len(), 2);
        assert_eq!((rows[0]["sol"].as_i64(), rows[0]["cameras"].clone(), rows[0]["images"].as_u64(), rows[0]["tubes"].as_u64()), (Some(53), json!(["navcam"]), Some(1), Some(1)));
        assert!((rows[0]["ap50"].as_f64().unwrap() - 1.0).abs() < 1e-9 && (rows[0]["ar"].as_f64().unwrap() - 1.0).abs() < 1e-9, "{v}");
        assert_eq!((rows[1]["sol"].as_i64(), rows[1]["cameras"].clone()), (Some(5105), json!(["mer-pancam"])));
        assert!(rows[1]["ap50"].as_f64().unwrap().abs() < 1e-9, "{v}");
        let md = table(&[("learned", &v), ("absent", &Value::Null), ("other", &json!([{"sol": 53, "ap50": -1.0, "ar": -1.0}]))]).unwrap();
        assert!(md.starts_with("| sol | camera | images | tubes | learned | other |"), "{md}");
        assert!(md.contains("| 53 | navcam | 1 | 1 | 1.000 / 1.000 | - |") && md.contains("| 5105 | mer-pancam | 1 | 1 | 0.000 / 0.000 | - |"), "{md}");
        assert!(md.find("| 53 |").unwrap() < md.find("| 5105 |").unwrap(), "sols in increasing order");
        let no_sol: CocoDataset = serde_json::from_value(json!({"images": [{"id": 3, "width": 100, "height": 100}], "annotations": [], "categories": [{"id": 1, "name": "tube"}]})).unwrap();
        assert!(by_sol(&no_sol, &CocoEvaluator::new(&no_sol, &[], IouType::Segm).unwrap()).unwrap().is_null());
        assert!(table(&[("absent", &Value::Null)]).is_none());
    }
}
