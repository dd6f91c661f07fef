//! Non-maximum suppression of raw matches by their placed silhouettes' IoU, and re-ranking
//! within each suppressed cluster.

use crate::line2d::matching::{fine_score_at, RawMatch};
use crate::line2d::response::ResponseMaps;
use crate::line2d::template::{Template, TemplateLibrary};
use crate::line2d::SIM_MAX;

/// IoU of two templates' silhouettes placed at their match positions.
pub fn placed_mask_iou(ta: &Template, a: &RawMatch, tb: &Template, b: &RawMatch) -> f32 {
    let (aw, ah) = (ta.levels[0].width as i32, ta.levels[0].height as i32);
    let (bw, bh) = (tb.levels[0].width as i32, tb.levels[0].height as i32);
    let (x0, y0) = (a.x.max(b.x), a.y.max(b.y));
    let (x1, y1) = ((a.x + aw).min(b.x + bw), (a.y + ah).min(b.y + bh));
    if x1 <= x0 || y1 <= y0 {
        return 0.0;
    }
    let (aa, ab) = (ta.area, tb.area);
    let mut inter = 0u32;
    let ub = ((x1 - x0) * (y1 - y0)) as u32;
    let ub = ub.min(aa).min(ab);
    if ub == 0 {
        return 0.0;
    }
    for y in y0..y1 {
        let ra = &ta.mask[((y - a.y) * aw + (x0 - a.x)) as usize..((y - a.y) * aw + (x1 - a.x)) as usize];
        let rb = &tb.mask[((y - b.y) * bw + (x0 - b.x)) as usize..((y - b.y) * bw + (x1 - b.x)) as usize];
        inter += ra.iter().zip(rb).map(|(&p, &q)| (p & q) as u32).sum::<u32>();
    }
    let uni = aa + ab - inter;
    if uni == 0 {
        0.0
    } else {
        inter as f32 / uni as f32
    }
}

/// Greedy NMS over matches sorted by decreasing score: a match is dropped when its placed
/// silhouette overlaps an already kept one with IoU above `iou`. Keeps at most `max`.
pub fn nms(matches: &[RawMatch], lib: &TemplateLibrary, iou: f32, max: usize) -> Vec<RawMatch> {
    nms_clusters(matches, lib, iou, max).into_iter().map(|c| c[0]).collect()
}

/// At most this many raw matches (the best-scoring) enter NMS.
pub const MAX_NMS_INPUT: usize = 20_000;

/// NMS returning each kept match (first) with the matches it suppressed (its cluster), in
/// decreasing score order. A suppressed match joins the first kept match it overlaps.
pub fn nms_clusters(matches: &[RawMatch], lib: &TemplateLibrary, iou: f32, max: usize) -> Vec<Vec<RawMatch>> {
    let mut clusters: Vec<Vec<RawMatch>> = Vec::new();
    for m in matches.iter().take(MAX_NMS_INPUT) {
        let tm = &lib.templates[m.template as usize];
        let hit = clusters.iter().position(|c| {
            let tk = &lib.templates[c[0].template as usize];
            // Upper bound first: IoU <= min(areas, box overlap) / (sum of areas - that).
            let k = &c[0];
            let ox = (k.x + tk.levels[0].width as i32).min(m.x + tm.levels[0].width as i32) - k.x.max(m.x);
            let oy = (k.y + tk.levels[0].height as i32).min(m.y + tm.levels[0].height as i32) - k.y.max(m.y);
            if ox <= 0 || oy <= 0 {
                return false;
            }
            let ub = ((ox * oy) as u32).min(tk.area).min(tm.area) as f32;
            ub / ((tk.area + tm.area) as f32 - ub) > iou && placed_mask_iou(tk, k, tm, m) > iou
        });
        match hit {
            Some(i) => clusters[i].push(*m),
            None if clusters.len() < max => clusters.push(vec![*m]),
            None => {}
        }
    }
    clusters
}

/// Re-ranks a cluster: among matches within `margin` points of the best, the one with the best
/// re-ranking score (response maps `rr`, best over +-1 px) wins; returns it with its position
/// moved to that best pixel and the cluster's best LINE-2D score.
pub fn rerank(cluster: &[RawMatch], lib: &TemplateLibrary, rr: &ResponseMaps, margin: f32) -> RawMatch {
    rerank_with(cluster, lib, rr, margin, |_, _, _| 0.0)
}

/// [`rerank`] with a bonus: the key of a candidate placed at `(x, y)` is
/// `E_rr / (4 n) + bonus(template, x, y)` (fraction of the maximal re-ranking similarity plus
/// e.g. the weighted verification contrast).
pub fn rerank_with(cluster: &[RawMatch], lib: &TemplateLibrary, rr: &ResponseMaps, margin: f32, bonus: impl Fn(&Template, i32, i32) -> f32) -> RawMatch {
    let top = cluster[0];
    let mut best = (f64::NEG_INFINITY, top);
    for m in cluster.iter().filter(|m| m.score >= top.score - margin) {
        let t = &lib.templates[m.template as usize];
        let (tw, th) = (t.levels[0].width as i32, t.levels[0].height as i32);
        let n = t.levels[0].features.len().max(1) as f64;
        for dy in -1..=1 {
            for dx in -1..=1 {
                let (x, y) = (m.x + dx, m.y + dy);
                if x < 0 || y < 0 || x + tw > rr.width as i32 || y + th > rr.height as i32 {
                    continue;
                }
                let e = fine_score_at(rr, t, x as usize, y as usize) as f64;
                let key = e / (SIM_MAX as f64 * n) + bonus(t, x, y) as f64;
                if key > best.0 {
                    best = (key, RawMatch { template: m.template, x, y, score: top.score });
                }
            }
        }
    }
    best.1
}
