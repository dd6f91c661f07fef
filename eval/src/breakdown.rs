//! Per-attribute breakdowns of the COCO metrics: the same 12 numbers for each value of an
//! image attribute (terrain, time of day, camera height, split: images with another value are
//! left out, as pycocotools with `params.imgIds` restricted) or of an annotation attribute
//! (occlusion, dust: ground truth with another value is ignored, like ground truth outside an
//! area range, so detections matched to it count neither way).
//!
//! Attributes are read from the `extra` fields of images and annotations; values are compared
//! as text (`"sand"`, `1.5`, `true`); a missing attribute is the value `(none)`.

use crate::coco_eval::{CocoEvaluator, EvalError, EvalResult, STATS};
use serde_json::{json, Map, Value};
use std::collections::BTreeSet;
use tubeloc_core::CocoDataset;

/// Where an attribute lives.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum AttrLevel {
    /// A field of the images.
    Image,
    /// A field of the annotations.
    Annotation,
}

/// Metrics for one value of an attribute.
#[derive(Clone, Debug)]
pub struct BreakdownRow {
    /// The value, as text.
    pub value: String,
    /// Images evaluated.
    pub num_images: usize,
    /// Non-crowd ground-truth objects that carry this value (image attribute: in these images).
    pub num_objects: usize,
    /// The full evaluation for this value.
    pub result: EvalResult,
}

/// The breakdown of one attribute.
#[derive(Clone, Debug)]
pub struct Breakdown {
    /// Attribute name.
    pub attribute: String,
    /// Image or annotation attribute.
    pub level: AttrLevel,
    /// One row per value, sorted by value.
    pub rows: Vec<BreakdownRow>,
}

fn text(v: Option<&Value>) -> String {
    match v {
        None | Some(Value::Null) => "(none)".to_string(),
        Some(Value::String(s)) => s.clone(),
        Some(other) => other.to_string(),
    }
}

fn attr_of(extra: &Map<String, Value>, attr: &str) -> String {
    text(extra.get(attr))
}

/// AP50 and AR of `evaluator` (prepared on `gt`) with intervals from a bootstrap that resamples
/// the values of the image attribute `attr` (e.g. `sol`: the frames of one sol are drawn
/// together; [`CocoEvaluator::intervals_by_group`]). An image without the attribute is a group
/// of its own; an attribute on no image is an error.
pub fn intervals_by_image_attribute(evaluator: &CocoEvaluator, gt: &CocoDataset, attr: &str, spec: &crate::bootstrap::BootstrapSpec) -> Result<crate::coco_eval::bootstrap::ApArIntervals, EvalError> {
    if !gt.images.iter().any(|im| im.extra.get(attr).is_some_and(|v| !v.is_null())) {
        return Err(EvalError::Entry { entry: format!("attribute {attr:?}"), message: "found on no image of the ground truth".into() });
    }
    let group: std::collections::HashMap<u64, Option<String>> = gt.images.iter().map(|im| (im.id, im.extra.get(attr).filter(|v| !v.is_null()).map(|v| text(Some(v))))).collect();
    Ok(evaluator.intervals_by_group(
        &|id| match group.get(&id).cloned().flatten() {
            Some(v) => (Some(v), 0),
            None => (None, id),
        },
        spec,
    ))
}

/// Evaluates `evaluator` (prepared on `gt`) once per value of `attr`. The attribute is looked up
/// on images first, then on annotations; an attribute found on neither is an error.
pub fn breakdown(evaluator: &CocoEvaluator, gt: &CocoDataset, attr: &str) -> Result<Breakdown, EvalError> {
    let on_images = gt.images.iter().any(|im| im.extra.contains_key(attr));
    let on_anns = gt.annotations.iter().any(|a| a.extra.contains_key(attr));
    let level = match (on_images, on_anns) {
        (true, _) => AttrLevel::Image,
        (false, true) => AttrLevel::Annotation,
        (false, false) => return Err(EvalError::Entry { entry: format!("attribute {attr:?}"), message: "found on no image and no annotation of the ground truth".into() }),
    };
    let mut rows = Vec::new();
    match level {
        AttrLevel::Image => {
            let img_val: std::collections::HashMap<u64, String> = gt.images.iter().map(|im| (im.id, attr_of(&im.extra, attr))).collect();
            let values: BTreeSet<&String> = img_val.values().collect();
            for v in values {
                let keep = |id: u64| img_val.get(&id) == Some(v);
                let result = evaluator.evaluate_with(&keep, &|_| false);
                let num_objects = gt.annotations.iter().filter(|a| a.iscrowd == 0 && img_val.get(&a.image_id) == Some(v)).count();
                rows.push(BreakdownRow { value: v.clone(), num_images: result.num_images, num_objects, result });
            }
        }
        AttrLevel::Annotation => {
            let ann_val: Vec<String> = gt.annotations.iter().map(|a| attr_of(&a.extra, attr)).collect();
            let values: BTreeSet<&String> = ann_val.iter().collect();
            for v in values {
                let ignore = |j: usize| &ann_val[j] != v;
                let result = evaluator.evaluate_with(&|_| true, &ignore);
                let num_objects = gt.annotations.iter().zip(&ann_val).filter(|(a, av)| a.iscrowd == 0 && *av == v).count();
                rows.push(BreakdownRow { value: v.clone(), num_images: result.num_images, num_objects, result });
            }
        }
    }
    Ok(Breakdown { attribute: attr.to_string(), level, rows })
}

fn cell(v: f64) -> String {
    if v < 0.0 {
        "-".to_string()
    } else {
        format!("{v:.3}")
    }
}

/// A markdown table of breakdowns: one row per (attribute, value) with AP, AP50, AP75,
/// AP small/medium/large, AR1, AR10 and AR100 (`-` where undefined).
pub fn markdown_table(breakdowns: &[Breakdown]) -> String {
    let cols = [0usize, 1, 2, 3, 4, 5, 6, 7, 8];
    let mut s = String::from("| attribute | value | images | objects |");
    for &c in &cols {
        s += &format!(" {} |", STATS[c].name);
    }
    s += "\n|---|---|---:|---:|";
    s += &"---:|".repeat(cols.len());
    s += "\n";
    for b in breakdowns {
        for r in &b.rows {
            s += &format!("| {} | {} | {} | {} |", b.attribute, r.value, r.num_images, r.num_objects);
            for &c in &cols {
                s += &format!(" {} |", cell(r.result.stats[c]));
            }
            s += "\n";
        }
    }
    s
}

/// JSON form of breakdowns: attribute, level and per value the counts and the 12 named stats.
pub fn to_json(breakdowns: &[Breakdown]) -> Value {
    Value::Array(
        breakdowns
            .iter()
            .map(|b| {
                let rows: Vec<Value> = b
                    .rows
                    .iter()
                    .map(|r| {
                        let stats: Map<String, Value> = STATS.iter().zip(r.result.stats).map(|(s, v)| (s.name.to_string(), json!(v))).collect();
                        json!({"value": r.value, "num_images": r.num_images, "num_objects": r.num_objects, "stats": stats})
                    })
                    .collect();
                json!({"attribute": b.attribute, "level": b.level, "rows": rows})
            })
            .collect(),
    )
}
