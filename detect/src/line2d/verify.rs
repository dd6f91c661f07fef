//! Verification of Line2D matches by the tube's radiometric signature.
//!
//! Line2D only looks at gradient orientations along the silhouette contour, so straight rock
//! edges, slab seams and shadow borders score as high as tubes. The sample tubes are white
//! alumina (plus a gold seal): brighter than the terrain just around them. For each template,
//! `n` inside samples (silhouette pixels at least `ring_inner` px from its border) and `n` ring
//! samples (pixels `ring_inner..=ring_outer` px outside it, Chebyshev distance) are chosen spread
//! out once; a match placed at `(x, y)` then gets the luminance contrast
//!
//! `C = (mean_in L - mean_ring L) / (mean_ring L + 1)`, with `L = (R + G + B) / 3`,
//!
//! over the samples that fall inside the image, in O(n) per match. The verified score is
//! `s = similarity / 100 + w · clamp(C, -1, 1)`; matches with `C < min_contrast` are dropped.
//! Scoring happens before non-maximum suppression so that a verified tube wins its cluster
//! over a brighter-edged rock it overlaps.

use crate::line2d::template::Template;

/// Knobs of the radiometric verification.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VerifyParams {
    /// Weight `w` of the clamped contrast in the verified score (0 = Line2D score only).
    pub contrast_weight: f32,
    /// Matches with contrast below this are dropped (`-inf` keeps all).
    pub min_contrast: f32,
    /// Inside samples are at least this far from the silhouette border, and ring samples at
    /// least this far outside it, pixels (skips the blurred edge).
    pub ring_inner: u32,
    /// Ring samples are at most this far outside the silhouette, pixels.
    pub ring_outer: u32,
    /// Samples per set (inside, ring).
    pub samples: usize,
    /// Weight of the contrast when re-ranking the templates of one NMS cluster (which
    /// template, hence mask and pose, the detection reports); 0 = Line2D re-ranking only.
    pub rerank_weight: f32,
}

impl Default for VerifyParams {
    fn default() -> Self {
        VerifyParams { contrast_weight: 0.5, min_contrast: -0.2, ring_inner: 2, ring_outer: 6, samples: 48, rerank_weight: 0.0 }
    }
}

/// Sample offsets of one template, relative to its level-0 top-left pixel.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TemplateSamples {
    /// Inside samples `(dx, dy)`.
    pub inside: Vec<(i16, i16)>,
    /// Ring samples `(dx, dy)` (may be negative or beyond the template box).
    pub ring: Vec<(i16, i16)>,
    /// Side of each ring sample relative to the silhouette's principal axis: 0 and 1 for the
    /// two long sides (within 80 % of the half-length from the centroid along the axis),
    /// 2 beyond the ends.
    pub side: Vec<u8>,
}

/// Square (Chebyshev) morphology of a 0/1 mask clipped to its `w x h` box: `out[p] = 1` when
/// the `(2r+1)²` square around `p`, clipped to the box, holds at least one 1 (`all = false`:
/// dilation, "within Chebyshev distance r of a 1") or only 1s (`all = true`: erosion, "more
/// than r from every 0 inside the box"). Separable: a sliding window count along rows, then
/// along columns, O(w h) whatever `r`.
fn square_morphology(mask: &[u8], w: usize, h: usize, r: usize, all: bool) -> Vec<u8> {
    // `hits(count, len)`: the window of `len` pixels holding `count` ones passes.
    let hits = |count: u32, len: usize| if all { count as usize == len } else { count > 0 };
    let mut rows = vec![0u8; w * h];
    let mut prefix = vec![0u32; w.max(h) + 1];
    for y in 0..h {
        let line = &mask[y * w..(y + 1) * w];
        for x in 0..w {
            prefix[x + 1] = prefix[x] + line[x] as u32;
        }
        for x in 0..w {
            let (a, b) = (x.saturating_sub(r), (x + r + 1).min(w));
            rows[y * w + x] = hits(prefix[b] - prefix[a], b - a) as u8;
        }
    }
    let mut out = vec![0u8; w * h];
    for x in 0..w {
        for y in 0..h {
            prefix[y + 1] = prefix[y] + rows[y * w + x] as u32;
        }
        for y in 0..h {
            let (a, b) = (y.saturating_sub(r), (y + r + 1).min(h));
            out[y * w + x] = hits(prefix[b] - prefix[a], b - a) as u8;
        }
    }
    out
}

/// Up to `n` spread-out points of `pts` (a regular stride over the list, which is in row-major
/// order; cheap and deterministic).
fn thin(pts: Vec<(i16, i16)>, n: usize) -> Vec<(i16, i16)> {
    if pts.len() <= n || n == 0 {
        return pts;
    }
    (0..n).map(|i| pts[i * pts.len() / n]).collect()
}

/// Chooses the inside and ring samples of a template.
pub fn template_samples(t: &Template, p: &VerifyParams) -> TemplateSamples {
    let (tw, th) = (t.levels[0].width as usize, t.levels[0].height as usize);
    let pad = p.ring_outer as usize + 1;
    let (w, h) = (tw + 2 * pad, th + 2 * pad);
    let mut m = vec![0u8; w * h];
    for y in 0..th {
        for x in 0..tw {
            m[(y + pad) * w + x + pad] = t.mask[y * tw + x];
        }
    }
    // Inside: more than `ring_inner` px (Chebyshev) from every background pixel; ring: within
    // `ring_outer` px of the silhouette but more than `ring_inner` px from it.
    let core = square_morphology(&m, w, h, p.ring_inner as usize, true);
    let near = square_morphology(&m, w, h, p.ring_inner as usize, false);
    let far = square_morphology(&m, w, h, p.ring_outer as usize, false);
    let mut inside = Vec::new();
    let mut ring = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let (i, dx, dy) = (y * w + x, x as i16 - pad as i16, y as i16 - pad as i16);
            if m[i] == 1 && core[i] == 1 {
                inside.push((dx, dy));
            } else if m[i] == 0 && far[i] == 1 && near[i] == 0 {
                ring.push((dx, dy));
            }
        }
    }
    if inside.is_empty() {
        inside = (0..th).flat_map(|y| (0..tw).map(move |x| (x, y))).filter(|&(x, y)| t.mask[y * tw + x] != 0).map(|(x, y)| (x as i16, y as i16)).collect();
    }
    let ring = thin(ring, p.samples);
    let side = ring_sides(t, &ring);
    TemplateSamples { inside: thin(inside, p.samples), ring, side }
}

/// Side of each ring sample (see [`TemplateSamples::side`]), from the second moments of the
/// template's silhouette.
fn ring_sides(t: &Template, ring: &[(i16, i16)]) -> Vec<u8> {
    let tw = t.levels[0].width as usize;
    let (mut n, mut sx, mut sy) = (0f64, 0f64, 0f64);
    for (i, _) in t.mask.iter().enumerate().filter(|(_, &v)| v != 0) {
        n += 1.0;
        sx += (i % tw) as f64;
        sy += (i / tw) as f64;
    }
    if n == 0.0 {
        return vec![2; ring.len()];
    }
    let (cx, cy) = (sx / n, sy / n);
    let (mut mxx, mut myy, mut mxy) = (0f64, 0f64, 0f64);
    for (i, _) in t.mask.iter().enumerate().filter(|(_, &v)| v != 0) {
        let (dx, dy) = ((i % tw) as f64 - cx, (i / tw) as f64 - cy);
        mxx += dx * dx;
        myy += dy * dy;
        mxy += dx * dy;
    }
    let th = 0.5 * (2.0 * mxy).atan2(mxx - myy);
    let (ux, uy) = (th.cos(), th.sin());
    let half = t.mask.iter().enumerate().filter(|(_, &v)| v != 0).map(|(i, _)| (((i % tw) as f64 - cx) * ux + ((i / tw) as f64 - cy) * uy).abs()).fold(0.0, f64::max);
    ring.iter()
        .map(|&(x, y)| {
            let (dx, dy) = (x as f64 - cx, y as f64 - cy);
            let along = dx * ux + dy * uy;
            let across = -dx * uy + dy * ux;
            if along.abs() > 0.8 * half {
                2
            } else if across > 0.0 {
                0
            } else {
                1
            }
        })
        .collect()
}

/// Per-template samples of a library, computed on first use (only templates that match).
#[derive(Debug, Default)]
pub struct SampleCache {
    cells: Vec<std::sync::OnceLock<TemplateSamples>>,
}

impl SampleCache {
    /// An empty cache for `n` templates.
    pub fn new(n: usize) -> Self {
        SampleCache { cells: (0..n).map(|_| std::sync::OnceLock::new()).collect() }
    }

    /// The samples of `t` (computed once, thread-safe).
    pub fn get(&self, t: &Template, p: &VerifyParams) -> &TemplateSamples {
        self.cells[t.id as usize].get_or_init(|| template_samples(t, p))
    }
}

/// Luminance `L = (R + G + B) / 3` of an interleaved RGB8 image.
pub fn luminance(rgb: &[u8]) -> Vec<u8> {
    rgb.chunks_exact(3).map(|c| ((c[0] as u16 + c[1] as u16 + c[2] as u16) / 3) as u8).collect()
}

/// Contrast `C` of the samples placed at `(x, y)` in a `w x h` luminance image; `None` when
/// fewer than a quarter of either sample set falls inside the image.
pub fn contrast(luma: &[u8], w: usize, h: usize, s: &TemplateSamples, x: i32, y: i32) -> Option<f32> {
    let mean = |pts: &[(i16, i16)]| -> Option<f32> {
        let (mut sum, mut n) = (0u32, 0usize);
        for &(dx, dy) in pts {
            let (xx, yy) = (x + dx as i32, y + dy as i32);
            if xx >= 0 && yy >= 0 && (xx as usize) < w && (yy as usize) < h {
                sum += luma[yy as usize * w + xx as usize] as u32;
                n += 1;
            }
        }
        (n > 0 && n * 4 >= pts.len()).then(|| sum as f32 / n as f32)
    };
    let li = mean(&s.inside)?;
    let lr = mean(&s.ring)?;
    Some((li - lr) / (lr + 1.0))
}

/// Verified score `similarity / 100 + w clamp(C, -1, 1)`, or `None` when the match is dropped
/// (`C < min_contrast`, or no contrast measurable while `min_contrast` is finite).
pub fn verified_score(similarity: f32, c: Option<f32>, p: &VerifyParams) -> Option<f32> {
    match c {
        Some(c) if c >= p.min_contrast || !p.min_contrast.is_finite() => Some(similarity / 100.0 + p.contrast_weight * c.clamp(-1.0, 1.0)),
        Some(_) => None,
        None if p.min_contrast.is_finite() && p.min_contrast > -1.0 => None,
        None => Some(similarity / 100.0 - p.contrast_weight),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::line2d::template::TemplateLevel;

    fn rect_template(tw: usize, th: usize) -> Template {
        Template {
            id: 0,
            alpha_deg: 90.0,
            psi_deg: 0.0,
            distance: 1.0,
            t_cam_tube: tubeloc_core::Pose::identity(),
            centre: [tw as f32 / 2.0, th as f32 / 2.0],
            levels: vec![TemplateLevel { width: tw as u16, height: th as u16, features: vec![] }],
            mask: vec![1; tw * th],
            area: (tw * th) as u32,
        }
    }

    #[test]
    fn samples_lie_inside_and_in_the_ring() {
        let t = rect_template(30, 12);
        let p = VerifyParams::default();
        let s = template_samples(&t, &p);
        assert_eq!(s.inside.len(), p.samples);
        assert_eq!(s.ring.len(), p.samples);
        for &(x, y) in &s.inside {
            assert!(x >= 2 && y >= 2 && x < 28 && y < 10, "inside sample ({x},{y}) too close to the border");
        }
        for &(x, y) in &s.ring {
            // Chebyshev distance outside the rectangle [0, 30) x [0, 12).
            let d = (-x).max(x - 29).max(-y).max(y - 11);
            assert!((3..=6).contains(&d), "ring sample ({x},{y}) at distance {d}");
        }
    }

    #[test]
    fn ring_samples_are_split_into_the_two_long_sides_and_the_ends() {
        let t = rect_template(40, 10);
        let s = template_samples(&t, &VerifyParams { samples: 400, ..VerifyParams::default() });
        assert_eq!(s.side.len(), s.ring.len());
        let (mut top, mut bottom) = (None, None);
        for (&(x, y), &side) in s.ring.iter().zip(&s.side) {
            if !(0..40).contains(&x) {
                assert_eq!(side, 2, "({x},{y}) beyond an end");
            } else if (6..34).contains(&x) {
                // Samples along the long sides, well inside the 80 % of the half-length.
                let slot = if y < 0 { &mut top } else { &mut bottom };
                assert_ne!(side, 2, "({x},{y}) on a long side");
                assert_eq!(*slot.get_or_insert(side), side, "one side, one label");
            }
        }
        assert!(top.is_some() && bottom.is_some() && top != bottom);
    }

    /// The separable square morphology equals the definition: the brute-force Chebyshev
    /// distance from each pixel to the nearest pixel of the other value, on random blobs.
    #[test]
    fn square_morphology_matches_brute_force_chebyshev_distance() {
        let (w, h) = (23usize, 17usize);
        let mut state = 12345u64;
        let mut mask = vec![0u8; w * h];
        for _ in 0..6 {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let (cx, cy, r) = ((state >> 33) as usize % w, (state >> 45) as usize % h, 1 + (state >> 55) as usize % 5);
            for y in cy.saturating_sub(r)..(cy + r).min(h) {
                for x in cx.saturating_sub(r + 1)..(cx + r).min(w) {
                    mask[y * w + x] = 1;
                }
            }
        }
        // Distance from (x, y) to the nearest pixel of value `v` inside the box.
        let dist = |x: usize, y: usize, v: u8| -> usize { (0..h).flat_map(|yy| (0..w).map(move |xx| (xx, yy))).filter(|&(xx, yy)| mask[yy * w + xx] == v).map(|(xx, yy)| xx.abs_diff(x).max(yy.abs_diff(y))).min().unwrap_or(usize::MAX) };
        for r in [0usize, 1, 2, 4] {
            let dil = square_morphology(&mask, w, h, r, false);
            let ero = square_morphology(&mask, w, h, r, true);
            for y in 0..h {
                for x in 0..w {
                    assert_eq!(dil[y * w + x] == 1, dist(x, y, 1) <= r, "dilation r {r} at ({x},{y})");
                    assert_eq!(ero[y * w + x] == 1, dist(x, y, 0) > r, "erosion r {r} at ({x},{y})");
                }
            }
        }
    }

    #[test]
    fn bright_tube_on_dark_ground_has_positive_contrast_and_wins() {
        let (w, h) = (80usize, 60usize);
        let t = rect_template(30, 12);
        let p = VerifyParams::default();
        let s = template_samples(&t, &p);
        let mut luma = vec![80u8; w * h];
        for y in 20..32 {
            for x in 25..55 {
                luma[y * w + x] = 200;
            }
        }
        let c = contrast(&luma, w, h, &s, 25, 20).unwrap();
        assert!((c - (200.0 - 80.0) / 81.0).abs() < 1e-4, "contrast {c}");
        // The same template on flat ground has no contrast; on a dark stripe it is negative.
        assert_eq!(contrast(&luma, w, h, &s, 2, 40).unwrap(), 0.0);
        let hi = verified_score(85.0, Some(c), &p).unwrap();
        let lo = verified_score(95.0, Some(0.0), &p).unwrap();
        assert!(hi > lo);
        assert_eq!(verified_score(95.0, Some(-0.5), &p), None);
        // Fully outside the image: not measurable.
        assert_eq!(contrast(&luma, w, h, &s, 500, 500), None);
    }
}
