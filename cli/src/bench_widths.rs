//! Where a detector's misses are: the true tubes of a composite set found by a detection, by
//! the tube's width in the image.

use anyhow::Result;
use serde_json::{json, Value};
use tubeloc_core::{CocoDataset, CocoResult, Rle};

/// Upper ends of the width bands, pixels (the last band is open).
pub const WIDTH_BANDS_PX: [f64; 4] = [5.0, 7.0, 9.0, 12.0];

/// Mask IoU at or above which a detection finds a tube.
const FOUND_IOU: f64 = 0.5;

/// The band of a width `w` (pixels): the first band whose upper end exceeds it.
fn band_of(w: f64) -> usize {
    WIDTH_BANDS_PX.iter().position(|&hi| w < hi).unwrap_or(WIDTH_BANDS_PX.len())
}

/// The label of band `i` ("< 5 px", "5-7 px", ..., ">= 12 px").
pub fn band_label(i: usize) -> String {
    match i {
        0 => format!("< {} px", WIDTH_BANDS_PX[0]),
        i if i >= WIDTH_BANDS_PX.len() => format!(">= {} px", WIDTH_BANDS_PX[WIDTH_BANDS_PX.len() - 1]),
        i => format!("{}-{} px", WIDTH_BANDS_PX[i - 1], WIDTH_BANDS_PX[i]),
    }
}

/// For each width band, `{"tubes": n, "found": k}`: the tubes of `gt` whose width `f D / r`
/// ([`tubeloc_synth::real_set::tube_ranges_and_widths`]) falls in it, and how many of them have
/// a detection of `dt` on their image whose mask overlaps theirs at IoU >= 0.5, whatever its
/// score (what a perfect ranking of these detections could find). Tubes without a width are
/// left out.
pub fn found_by_width(gt: &CocoDataset, dt: &[CocoResult]) -> Result<Value> {
    let size: std::collections::HashMap<u64, (u32, u32)> = gt.images.iter().map(|im| (im.id, (im.height, im.width))).collect();
    let mut masks: std::collections::HashMap<u64, Vec<Rle>> = std::collections::HashMap::new();
    for d in dt {
        if let (Some(seg), Some(&(h, w))) = (&d.segmentation, size.get(&d.image_id)) {
            masks.entry(d.image_id).or_default().push(seg.to_rle(h, w)?);
        }
    }
    let mut bands = vec![(0usize, 0usize); WIDTH_BANDS_PX.len() + 1];
    for (a, rw) in gt.annotations.iter().zip(tubeloc_synth::real_set::tube_ranges_and_widths(gt)) {
        let (Some((_, w)), Some(&(h, iw)), Some(seg)) = (rw, size.get(&a.image_id), &a.segmentation) else { continue };
        let truth = seg.to_rle(h, iw)?;
        let found = masks.get(&a.image_id).is_some_and(|m| Rle::iou(m, std::slice::from_ref(&truth), &[false]).iter().any(|&iou| iou >= FOUND_IOU));
        let b = &mut bands[band_of(w)];
        b.0 += 1;
        b.1 += usize::from(found);
    }
    Ok(Value::Array(bands.iter().enumerate().map(|(i, &(n, k))| json!({"band": band_label(i), "tubes": n, "found": k})).collect()))
}

/// A markdown table of [`found_by_width`] results, one row per `(name, bands)` ("found / tubes"
/// per band); rows whose bands are not an array are left out; `None` when none is left.
pub fn table(rows: &[(String, &Value)]) -> Option<String> {
    let rows: Vec<_> = rows.iter().filter_map(|(name, v)| Some((name, v.as_array()?))).collect();
    if rows.is_empty() {
        return None;
    }
    let labels: Vec<String> = (0..=WIDTH_BANDS_PX.len()).map(band_label).collect();
    let mut md = format!("| detections | {} |\n|---|{}\n", labels.join(" | "), "---:|".repeat(labels.len()));
    for (name, bands) in rows {
        let cells: Vec<String> = bands.iter().map(|b| format!("{} / {}", b["found"], b["tubes"])).collect();
        md.push_str(&format!("| {name} | {} |\n", cells.join(" | ")));
    }
    Some(md)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A tube 8.55 px wide (fx 500 px, 1 m away) is found by a detection with its mask, not by
    /// one beside it; a tube of an image without a camera has no width and is left out.
    #[test]
    fn a_tube_is_found_in_its_width_band_by_a_detection_on_it() {
        let ds: CocoDataset = serde_json::from_value(json!({
            "images": [{"id": 1, "width": 100, "height": 100, "camera": {"fx": 500.0}}, {"id": 2, "width": 100, "height": 100}],
            "annotations": [
                {"id": 1, "image_id": 1, "category_id": 1, "area": 200.0, "bbox": [10, 10, 20, 10], "segmentation": [[10, 10, 30, 10, 30, 20, 10, 20]], "T_cam_tube": {"translation": [0.0, 0.0, 1.0]}},
                {"id": 2, "image_id": 1, "category_id": 1, "area": 200.0, "bbox": [60, 60, 20, 10], "segmentation": [[60, 60, 80, 60, 80, 70, 60, 70]], "T_cam_tube": {"translation": [0.0, 0.0, 1.0]}},
                {"id": 3, "image_id": 2, "category_id": 1, "area": 200.0, "bbox": [10, 10, 20, 10], "segmentation": [[10, 10, 30, 10, 30, 20, 10, 20]], "T_cam_tube": {"translation": [0.0, 0.0, 1.0]}}
            ],
            "categories": [{"id": 1, "name": "tube"}]
        }))
        .unwrap();
        let det = |image_id: u64, x: f64| serde_json::from_value::<CocoResult>(json!({"image_id": image_id, "category_id": 1, "score": 0.5, "segmentation": [[x, 10, x + 20.0, 10, x + 20.0, 20, x, 20]]})).unwrap();
        let v = found_by_width(&ds, &[det(1, 10.0), det(1, 40.0), det(2, 10.0)]).unwrap();
        let bands = v.as_array().unwrap();
        assert_eq!(bands.len(), 5);
        assert_eq!(bands[2], json!({"band": "7-9 px", "tubes": 2, "found": 1}));
        assert_eq!(bands.iter().map(|b| b["tubes"].as_u64().unwrap()).sum::<u64>(), 2);
        let md = table(&[("learned".to_string(), &v), ("absent".to_string(), &Value::Null)]).unwrap();
        assert!(md.starts_with("| detections | < 5 px | 5-7 px | 7-9 px | 9-12 px | >= 12 px |") && md.contains("| learned | 0 / 0 | 0 / 0 | 1 / 2 | 0 / 0 | 0 / 0 |") && !md.contains("absent"), "{md}");
        assert!(table(&[("absent".to_string(), &Value::Null)]).is_none());
    }

    #[test]
    fn widths_fall_in_their_bands() {
        assert_eq!([4.9, 5.0, 6.99, 7.0, 11.9, 12.0, 40.0].map(band_of), [0, 1, 1, 2, 3, 4, 4]);
        assert_eq!((band_label(0), band_label(2), band_label(4)), ("< 5 px".to_string(), "7-9 px".to_string(), ">= 12 px".to_string()));
    }
}
