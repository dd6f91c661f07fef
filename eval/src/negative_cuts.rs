//! Cuts on a detection probability chosen on frames without a tube, per image kind.
//!
//! The detections of each image are first suppressed as a verifier keeps them: taken by
//! score, one whose mask overlaps a kept one's at IoU above `nms_iou` is dropped. On the `n`
//! tube-free images of one kind every kept detection is false, so the cut for that kind keeps
//! at most `⌊b n⌋` of them (`b` false detections per frame): halfway between the last score
//! it keeps and the first it drops ([`lowest_cut`]); `0` where no cut is needed.

use std::collections::BTreeMap;
use tubeloc_core::{CocoDataset, CocoResult, Rle};

/// The cut of one group of tube-free images (one kind under one geometry).
#[derive(Clone, Debug, PartialEq)]
pub struct GroupCut {
    /// Grey (three equal channels) or colour.
    pub grey: bool,
    /// The images' `geometry` field (`pds`, `assumed`; empty where absent).
    pub geometry: String,
    /// Tube-free images in the group.
    pub images: usize,
    /// Detections left on them after suppression.
    pub detections: usize,
    /// The group's cut ([`lowest_cut`]).
    pub cut: f64,
}

/// The cuts chosen for colour and grey tube-free images: per kind, the highest of its
/// groups' cuts, so that every geometry meets the bound.
#[derive(Clone, Debug, PartialEq)]
pub struct KindCuts {
    /// Cut for colour images (0 without colour images).
    pub colour: f64,
    /// Cut for grey images (0 without grey images).
    pub grey: f64,
    /// Each group's cut.
    pub groups: Vec<GroupCut>,
}

/// A cut at which at most `⌊bound · images⌋` of `scores` (probabilities in `[0, 1]`) are at
/// or above it: `0` when that many or fewer scores exist at all, else halfway between the
/// `(⌊bound · images⌋ + 1)`-th highest score and the next higher one (or 1), so that a
/// probability computed again a rounding error away falls on the same side.
pub fn lowest_cut(scores: &[f64], images: usize, bound: f64) -> f64 {
    let allowed = (bound * images as f64).floor() as usize;
    if scores.len() <= allowed {
        return 0.0;
    }
    let mut s = scores.to_vec();
    s.sort_by(|a, b| b.total_cmp(a));
    let above = if allowed == 0 { 1.0 } else { s[allowed - 1] };
    0.5 * (s[allowed] + above)
}

/// The results of each image after suppression by mask IoU above `nms_iou` (strongest
/// first); image sizes from `gt`. Errors name the result and the problem.
pub fn suppressed(gt: &CocoDataset, dt: &[CocoResult], nms_iou: f64) -> Result<Vec<CocoResult>, String> {
    let sizes: BTreeMap<u64, (u32, u32)> = gt.images.iter().map(|i| (i.id, (i.height, i.width))).collect();
    let mut by_image: BTreeMap<u64, Vec<(usize, Rle)>> = BTreeMap::new();
    for (k, d) in dt.iter().enumerate() {
        let (h, w) = sizes.get(&d.image_id).copied().ok_or_else(|| format!("detection {k} is on image {}, which the ground truth does not hold", d.image_id))?;
        let seg = d.segmentation.as_ref().ok_or_else(|| format!("detection {k} has no segmentation (mask)"))?;
        by_image.entry(d.image_id).or_default().push((k, seg.to_rle(h, w).map_err(|e| format!("detection {k}: {e}"))?));
    }
    let mut out = Vec::new();
    for (_, mut list) in by_image {
        list.sort_by(|a, b| dt[b.0].score.total_cmp(&dt[a.0].score).then(a.0.cmp(&b.0)));
        let keep = tubeloc_core::keep_by_iou(&list.iter().map(|(_, m)| Some(m)).collect::<Vec<_>>(), nms_iou);
        out.extend(list.iter().zip(keep).filter(|(_, k)| *k).map(|((k, _), _)| dt[*k].clone()));
    }
    Ok(out)
}

/// The cut per kind on the tube-free images of `gt` (images without a non-crowd annotation;
/// their kind from the boolean image field `grey`, as `tubeloc synth real` writes it, their
/// geometry from `geometry`) for at most `bound` false detections per image of `dt` after
/// suppression at `nms_iou`, in each geometry of the kind. Errors when a tube-free image has no
/// `grey` field or when there is no tube-free image.
pub fn kind_cuts(gt: &CocoDataset, dt: &[CocoResult], nms_iou: f64, bound: f64) -> Result<KindCuts, String> {
    let with_tubes: std::collections::HashSet<u64> = gt.annotations.iter().filter(|a| a.iscrowd == 0).map(|a| a.image_id).collect();
    let mut group_of: BTreeMap<u64, (bool, String)> = BTreeMap::new();
    for im in gt.images.iter().filter(|i| !with_tubes.contains(&i.id)) {
        let g = im.extra.get("grey").and_then(|v| v.as_bool()).ok_or_else(|| format!("image {} ({}) has no boolean \"grey\" field (its kind: three equal channels or colour)", im.id, im.file_name))?;
        let geometry = im.extra.get("geometry").and_then(|v| v.as_str()).unwrap_or("").to_string();
        group_of.insert(im.id, (g, geometry));
    }
    if group_of.is_empty() {
        return Err("the ground truth has no image without a tube".into());
    }
    let kept = suppressed(gt, dt, nms_iou)?;
    let mut images: BTreeMap<(bool, String), usize> = BTreeMap::new();
    for key in group_of.values() {
        *images.entry(key.clone()).or_default() += 1;
    }
    let mut scores: BTreeMap<(bool, String), Vec<f64>> = images.keys().map(|k| (k.clone(), Vec::new())).collect();
    for d in &kept {
        if let Some(key) = group_of.get(&d.image_id) {
            scores.get_mut(key).expect("every group has a list").push(d.score);
        }
    }
    let groups: Vec<GroupCut> =
        images.iter().map(|((grey, geometry), &n)| GroupCut { grey: *grey, geometry: geometry.clone(), images: n, detections: scores[&(*grey, geometry.clone())].len(), cut: lowest_cut(&scores[&(*grey, geometry.clone())], n, bound) }).collect();
    let cut_of = |grey: bool| groups.iter().filter(|g| g.grey == grey).map(|g| g.cut).fold(0.0, f64::max);
    Ok(KindCuts { colour: cut_of(false), grey: cut_of(true), groups })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cut_keeps_at_most_the_bound_per_frame() {
        // Four frames, at most 0.5 per frame: two detections may stay.
        let s = [0.9, 0.1, 0.5, 0.7, 0.3];
        // Halfway between the third highest (0.5) and the second (0.7).
        let c = lowest_cut(&s, 4, 0.5);
        assert!((c - 0.6).abs() < 1e-12, "{c}");
        assert_eq!(s.iter().filter(|&&x| x >= c).count(), 2);
        assert_eq!(lowest_cut(&s, 10, 0.5), 0.0);
        assert_eq!(lowest_cut(&[], 3, 0.0), 0.0);
        // None allowed: halfway between the highest and 1.
        assert!((lowest_cut(&s, 3, 0.0) - 0.95).abs() < 1e-12);
    }

    fn box_rle(x0: usize, x1: usize) -> serde_json::Value {
        let m = tubeloc_core::BinaryMask::from_fn(20, 20, |x, y| (x0..x1).contains(&x) && (5..9).contains(&y));
        serde_json::to_value(tubeloc_core::Segmentation::from_rle(&Rle::from_mask(&m))).unwrap()
    }

    #[test]
    fn cuts_per_kind_count_suppressed_detections_on_tube_free_frames_only() {
        let gt: CocoDataset = serde_json::from_value(serde_json::json!({
            "images": [
                {"id": 1, "width": 20, "height": 20, "file_name": "c1.png", "grey": false},
                {"id": 2, "width": 20, "height": 20, "file_name": "c2.png", "grey": false},
                {"id": 3, "width": 20, "height": 20, "file_name": "g1.png", "grey": true},
                {"id": 4, "width": 20, "height": 20, "file_name": "t.png"}],
            "annotations": [{"id": 1, "image_id": 4, "category_id": 1, "area": 40.0, "bbox": [2, 5, 10, 4], "segmentation": [[2, 5, 12, 5, 12, 9, 2, 9]]}],
            "categories": [{"id": 1, "name": "tube"}]
        }))
        .unwrap();
        let r = |image_id: u64, score: f64, x0: usize, x1: usize| -> CocoResult { serde_json::from_value(serde_json::json!({"image_id": image_id, "category_id": 1, "score": score, "segmentation": box_rle(x0, x1)})).unwrap() };
        let dt = vec![
            // Colour frame 1: 0.8 and a weaker copy of it (suppressed), and 0.6 elsewhere.
            r(1, 0.8, 2, 10),
            r(1, 0.75, 2, 11),
            r(1, 0.6, 12, 18),
            // Colour frame 2: 0.4.
            r(2, 0.4, 2, 10),
            // Grey frame: 0.3.
            r(3, 0.3, 2, 10),
            // A frame with a tube does not count.
            r(4, 0.99, 14, 18),
        ];
        let c = kind_cuts(&gt, &dt, 0.5, 0.5).unwrap();
        let counts: Vec<(bool, usize, usize)> = c.groups.iter().map(|g| (g.grey, g.images, g.detections)).collect();
        assert_eq!(counts, vec![(false, 2, 3), (true, 1, 1)]);
        // Colour: 0.8, 0.6, 0.4 after suppression; one may stay (2 frames x 0.5).
        assert!((c.colour - 0.7).abs() < 1e-12, "{c:?}");
        // Grey: 1 frame x 0.5 = 0 allowed.
        assert!((c.grey - 0.65).abs() < 1e-12, "{c:?}");
        // A second geometry of colour frames: each geometry meets the bound, the kind's cut is
        // the higher one.
        let mut two = gt.clone();
        for id in [1, 2] {
            two.images[id - 1].extra.insert("geometry".into(), serde_json::json!(if id == 1 { "assumed" } else { "pds" }));
        }
        let c2 = kind_cuts(&two, &dt, 0.5, 0.5).unwrap();
        // Frame 1 alone (0.8, 0.6; none allowed): halfway between 0.8 and 1; frame 2 (0.4): 0.7.
        assert!((c2.colour - 0.9).abs() < 1e-12, "{c2:?}");
        assert_eq!(c2.groups.iter().map(|g| g.geometry.as_str()).collect::<Vec<_>>(), vec!["assumed", "pds", ""]);
        let mut no_kind = gt.clone();
        no_kind.images[1].extra.remove("grey");
        assert_eq!(kind_cuts(&no_kind, &dt, 0.5, 0.5).unwrap_err(), "image 2 (c2.png) has no boolean \"grey\" field (its kind: three equal channels or colour)");
    }
}
