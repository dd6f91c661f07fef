//! Image side of the fit: a gradient pyramid of the region of interest and 1D edge searches
//! along contour normals.
//!
//! Level 0 is the crop of the input image; level `k+1` averages 2x2 blocks of level `k` (pixel
//! centres stay consistent with [`CameraModel::scaled`]). Each level is smoothed with the
//! binomial kernel `[1 4 6 4 1]/16` (σ ≈ 1 px) and differentiated with central differences,
//! giving `(∂I/∂x, ∂I/∂y)` in intensity units per level pixel. Level 0 may be left unsmoothed
//! ([`build_pyramid_with`]): on a 10-16 px wide tube the smoothing merges the shading ramp
//! inside a limb with the limb's step and moves the gradient maximum inward.

use nalgebra::{Point2, Vector2};
use tubeloc_core::{CameraModel, Plane};

/// Gradient image of one pyramid level and the camera that maps into its pixels.
#[derive(Clone, Debug)]
pub struct GradientLevel {
    /// Camera for this level's pixel grid (cropped and scaled).
    pub camera: CameraModel,
    /// Width of the level, pixels.
    pub width: usize,
    /// Height of the level, pixels.
    pub height: usize,
    /// Scale of this level relative to full resolution (1, 0.5, 0.25, ...).
    pub scale: f64,
    /// `(∂I/∂x, ∂I/∂y)` of the level, smoothed unless built unsmoothed (intensity per level
    /// pixel), interleaved,
    /// row-major (`grad[y * width + x]`), for one memory access per bilinear tap.
    pub grad: Vec<[f32; 2]>,
    /// For an unsmoothed level ([`build_pyramid_with`]), the same level smoothed: a fit's
    /// acceptance (inlier fraction) and residual statistics are taken on it.
    pub smoothed: Option<Box<GradientLevel>>,
}

impl GradientLevel {
    /// The smoothed version of this level (itself when it is smoothed).
    pub fn smooth(&self) -> &GradientLevel {
        self.smoothed.as_deref().unwrap_or(self)
    }
}

/// The crop rectangle `(x0, y0, w, h)` of `bbox` grown by `margin` pixels, clamped to the image.
/// Returns `None` when the rectangle does not overlap the image.
pub fn roi(bbox: [f64; 4], margin: f64, width: usize, height: usize) -> Option<(usize, usize, usize, usize)> {
    let x0 = (bbox[0] - margin).floor().max(0.0);
    let y0 = (bbox[1] - margin).floor().max(0.0);
    let x1 = (bbox[0] + bbox[2] + margin).ceil().min(width as f64);
    let y1 = (bbox[1] + bbox[3] + margin).ceil().min(height as f64);
    if !(x1 - x0 >= 8.0 && y1 - y0 >= 8.0) {
        return None;
    }
    Some((x0 as usize, y0 as usize, (x1 - x0) as usize, (y1 - y0) as usize))
}

fn crop(img: &Plane<f32>, x0: usize, y0: usize, w: usize, h: usize) -> Plane<f32> {
    let mut data = Vec::with_capacity(w * h);
    for y in y0..y0 + h {
        data.extend_from_slice(&img.row(y)[x0..x0 + w]);
    }
    Plane::from_vec(w, h, data)
}

fn downsample(p: &Plane<f32>) -> Plane<f32> {
    let (w, h) = (p.width / 2, p.height / 2);
    let mut data = Vec::with_capacity(w * h);
    for y in 0..h {
        let (r0, r1) = (p.row(2 * y), p.row(2 * y + 1));
        data.extend((0..w).map(|x| 0.25 * (r0[2 * x] + r0[2 * x + 1] + r1[2 * x] + r1[2 * x + 1])));
    }
    Plane::from_vec(w, h, data)
}

/// One output sample of the binomial kernel `[1 4 6 4 1]/16` over five inputs.
#[inline(always)]
fn binom(a: f32, b: f32, c: f32, d: f32, e: f32) -> f32 {
    ((a + e) + 4.0 * (b + d) + 6.0 * c) * (1.0 / 16.0)
}

/// Appends the binomial blur `[1 4 6 4 1]/16` of `row` (clamped at its ends) to `out`; the
/// interior without index clamping, so that it vectorizes.
fn binom_row(row: &[f32], out: &mut Vec<f32>) {
    let w = row.len();
    let at = |x: isize| row[x.clamp(0, w as isize - 1) as usize];
    let clamped = |x: usize| {
        let xi = x as isize;
        binom(at(xi - 2), at(xi - 1), row[x], at(xi + 1), at(xi + 2))
    };
    if w <= 4 {
        out.extend((0..w).map(clamped));
        return;
    }
    out.extend((0..2).map(clamped));
    out.extend(row.windows(5).map(|v| binom(v[0], v[1], v[2], v[3], v[4])));
    out.extend((w - 2..w).map(clamped));
}

/// Separable binomial blur `[1 4 6 4 1]/16` with clamped borders (interior loops without
/// index clamping, so that they vectorize; the buffers are filled row by row, not zeroed
/// first).
fn blur(p: &Plane<f32>) -> Plane<f32> {
    let (w, h) = (p.width, p.height);
    let cl = |v: isize, n: usize| v.clamp(0, n as isize - 1) as usize;
    let mut tmp = Vec::with_capacity(w * h);
    for y in 0..h {
        binom_row(p.row(y), &mut tmp);
    }
    let mut data = Vec::with_capacity(w * h);
    for y in 0..h {
        let yi = y as isize;
        let r = |k: isize| &tmp[cl(yi + k, h) * w..(cl(yi + k, h) + 1) * w];
        let (r0, r1, r2, r3, r4) = (r(-2), r(-1), r(0), r(1), r(2));
        data.extend((0..w).map(|x| binom(r0[x], r1[x], r2[x], r3[x], r4[x])));
    }
    Plane::from_vec(w, h, data)
}

/// Central-difference gradients `(∂x, ∂y)` (one-sided at the borders), interleaved.
fn gradients(p: &Plane<f32>) -> Vec<[f32; 2]> {
    let (w, h) = (p.width, p.height);
    // Plain indexed loops over preallocated rows: the cost does not depend on how the
    // compiler splits the crate into codegen units (an iterator chain here was left
    // un-inlined in some splits, 4x slower).
    let mut g = vec![[0.0f32; 2]; w * h];
    if w == 0 {
        return g;
    }
    for (y, out) in g.chunks_exact_mut(w).enumerate() {
        let (row, up, dn) = (&p.row(y)[..w], &p.row(y.saturating_sub(1))[..w], &p.row((y + 1).min(h - 1))[..w]);
        let sy = if y == 0 || y == h - 1 { 1.0 } else { 0.5 };
        if w < 2 {
            out[0] = [0.0, (dn[0] - up[0]) * sy];
            continue;
        }
        out[0] = [row[1] - row[0], (dn[0] - up[0]) * sy];
        for x in 1..w - 1 {
            out[x] = [0.5 * (row[x + 1] - row[x - 1]), (dn[x] - up[x]) * sy];
        }
        out[w - 1] = [row[w - 1] - row[w - 2], (dn[w - 1] - up[w - 1]) * sy];
    }
    g
}

/// Builds `levels` gradient levels for the crop `(x0, y0, w, h)` of `image` seen by `camera`.
/// Stops early when a level would be smaller than 16 pixels on a side.
pub fn build_pyramid(image: &Plane<f32>, camera: &CameraModel, rect: (usize, usize, usize, usize), levels: usize) -> Vec<GradientLevel> {
    build_pyramid_with(image, camera, rect, levels, true)
}

/// [`build_pyramid`] with the smoothing of level 0 (full resolution) optional: `blur_level0 =
/// false` differentiates it unsmoothed for the fit and keeps the smoothed one in
/// [`GradientLevel::smoothed`] (the coarser levels are smoothed either way).
pub fn build_pyramid_with(image: &Plane<f32>, camera: &CameraModel, rect: (usize, usize, usize, usize), levels: usize, blur_level0: bool) -> Vec<GradientLevel> {
    let (x0, y0, w, h) = rect;
    let mut cur = crop(image, x0, y0, w, h);
    let mut cam = camera.cropped(x0 as u32, y0 as u32, w as u32, h as u32);
    let mut out = Vec::with_capacity(levels);
    let mut scale = 1.0;
    for k in 0..levels.max(1) {
        if k > 0 {
            if cur.width / 2 < 16 || cur.height / 2 < 16 {
                break;
            }
            cur = downsample(&cur);
            cam = cam.scaled(0.5);
            cam.width = cur.width as u32;
            cam.height = cur.height as u32;
            scale *= 0.5;
        }
        let smooth = GradientLevel { camera: cam.clone(), width: cur.width, height: cur.height, scale, grad: gradients(&blur(&cur)), smoothed: None };
        if k == 0 && !blur_level0 {
            let sharp = GradientLevel { camera: cam.clone(), width: cur.width, height: cur.height, scale, grad: gradients(&cur), smoothed: None };
            out.push(GradientLevel { smoothed: Some(Box::new(smooth)), ..sharp });
        } else {
            out.push(smooth);
        }
    }
    out
}

/// Result of a 1D edge search.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EdgeHit {
    /// Signed offset of the edge from the start point along the normal, level pixels.
    pub offset: f64,
    /// Directional derivative at the edge, `∇I · n` (sign = polarity along the outward normal).
    pub strength: f32,
}

impl GradientLevel {
    /// True when `p` is at least `margin` pixels inside this level's image.
    #[inline]
    pub fn inside(&self, p: &Point2<f64>, margin: f64) -> bool {
        p.x >= margin && p.y >= margin && p.x <= self.width as f64 - 1.0 - margin && p.y <= self.height as f64 - 1.0 - margin
    }

    /// Directional derivative `∇I(q) · n` by bilinear interpolation of the gradient planes.
    #[inline]
    pub fn directional(&self, q: &Point2<f64>, n: &Vector2<f64>) -> f32 {
        let g = self.gradient(q.x as f32, q.y as f32);
        g[0] * n.x as f32 + g[1] * n.y as f32
    }

    /// Bilinearly interpolated `(gx, gy)` at `(x, y)` (level pixels, clamped to the image).
    #[inline]
    pub fn gradient(&self, x: f32, y: f32) -> [f32; 2] {
        let (w, h) = (self.width, self.height);
        let x = x.clamp(0.0, (w - 1) as f32);
        let y = y.clamp(0.0, (h - 1) as f32);
        // Non-negative after the clamp: truncation is the floor (through i32: one instruction).
        let (x0, y0) = (x as i32 as usize, y as i32 as usize);
        let (fx, fy) = (x - x0 as f32, y - y0 as f32);
        let x1 = (x0 + 1).min(w - 1) - x0;
        let y1 = if y0 + 1 < h { w } else { 0 };
        self.taps(y0 * w + x0, x1, y1, fx, fy)
    }

    /// The bilinear blend of the gradient at `grad[i]`, its right neighbour `grad[i + dx]`
    /// and the two below them (`+ dy`), with fractions `fx`, `fy`.
    #[inline(always)]
    fn taps(&self, i: usize, dx: usize, dy: usize, fx: f32, fy: f32) -> [f32; 2] {
        let (a, b, c, d) = (self.grad[i], self.grad[i + dx], self.grad[i + dy], self.grad[i + dy + dx]);
        let mut out = [0f32; 2];
        for k in 0..2 {
            let top = a[k] + (b[k] - a[k]) * fx;
            let bot = c[k] + (d[k] - c[k]) * fx;
            out[k] = top + (bot - top) * fy;
        }
        out
    }

    /// Searches `p + k n`, `k = -radius..=radius`, for local maxima of `|∇I · n|` above
    /// `min_strength` with the requested polarity (`polarity` = +1 or -1 keeps only that sign
    /// of `∇I · n`; 0 keeps both). Returns up to [`MAX_HYPOTHESES`] edges, strongest first,
    /// each at least `rel_strength` times the strongest; offsets refined by a parabola through
    /// the neighbours.
    pub fn search_all(&self, p: &Point2<f64>, n: &Vector2<f64>, radius: usize, min_strength: f32, polarity: i8, rel_strength: f32) -> EdgeHits {
        let m = (2 * radius + 1).min(129);
        // The usual radii (up to 16) zero a short buffer only.
        let mut short = [0f32; 33];
        let mut long: [f32; 129];
        let buf: &mut [f32] = if m <= short.len() {
            &mut short[..m]
        } else {
            long = [0f32; 129];
            &mut long[..m]
        };
        let r = (m as isize - 1) / 2;
        // Where the whole segment lies at least one pixel inside the right and bottom borders,
        // no tap needs the border clamps of [`GradientLevel::gradient`] (the same values).
        let (first, last) = (p - n * r as f64, p + n * r as f64);
        let (xmax, ymax) = (self.width as f64 - 1.0 - 1e-3, self.height as f64 - 1.0 - 1e-3);
        if first.x.min(last.x) >= 0.0 && first.y.min(last.y) >= 0.0 && first.x.max(last.x) < xmax && first.y.max(last.y) < ymax {
            let (w, nx, ny) = (self.width, n.x as f32, n.y as f32);
            for (i, v) in buf.iter_mut().enumerate() {
                let q = p + n * (i as f64 - r as f64);
                let (x, y) = (q.x as f32, q.y as f32);
                // Non-negative and below the level's size: truncation is the floor, and the
                // conversion through i32 is a single instruction (to usize it is not).
                let (x0, y0) = (x as i32 as usize, y as i32 as usize);
                let g = self.taps(y0 * w + x0, 1, w, x - x0 as f32, y - y0 as f32);
                *v = g[0] * nx + g[1] * ny;
            }
        } else {
            for (i, v) in buf.iter_mut().enumerate() {
                let k = i as f64 - r as f64;
                *v = self.directional(&(p + n * k), n);
            }
        }
        let mut hits = EdgeHits::default();
        let mut cand: [(usize, f32); 16] = [(0, 0.0); 16];
        let mut nc = 0;
        for i in 1..m - 1 {
            let g = buf[i];
            if polarity > 0 && g <= 0.0 || polarity < 0 && g >= 0.0 {
                continue;
            }
            let a = g.abs();
            if a < min_strength || a < buf[i - 1].abs() || a < buf[i + 1].abs() {
                continue;
            }
            if nc < cand.len() {
                cand[nc] = (i, a);
                nc += 1;
            }
        }
        let cand = &mut cand[..nc];
        cand.sort_unstable_by(|a, b| b.1.total_cmp(&a.1));
        let top = cand.first().map_or(0.0, |c| c.1);
        for &(i, a) in cand.iter().take(MAX_HYPOTHESES) {
            if a < rel_strength * top {
                break;
            }
            let (l, c, rr) = (buf[i - 1].abs() as f64, buf[i].abs() as f64, buf[i + 1].abs() as f64);
            let den = l - 2.0 * c + rr;
            let delta = if den < -1e-12 { (0.5 * (l - rr) / den).clamp(-0.5, 0.5) } else { 0.0 };
            hits.hits[hits.len] = EdgeHit { offset: i as f64 - r as f64 + delta, strength: buf[i] };
            hits.len += 1;
        }
        hits
    }

    /// The strongest edge of [`GradientLevel::search_all`], if any.
    pub fn search(&self, p: &Point2<f64>, n: &Vector2<f64>, radius: usize, min_strength: f32, polarity: i8) -> Option<EdgeHit> {
        let h = self.search_all(p, n, radius, min_strength, polarity, 1.0);
        (h.len > 0).then(|| h.hits[0])
    }
}

/// Most edge hypotheses kept per contour sample.
pub const MAX_HYPOTHESES: usize = 3;

/// Up to [`MAX_HYPOTHESES`] edges found along one normal, strongest first.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EdgeHits {
    /// The hits; only the first `len` are valid.
    pub hits: [EdgeHit; MAX_HYPOTHESES],
    /// Number of valid hits.
    pub len: usize,
}

impl Default for EdgeHit {
    fn default() -> Self {
        EdgeHit { offset: 0.0, strength: 0.0 }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_a_subpixel_step_edge_on_every_level() {
        // Vertical step at x = 40.3 (area-weighted), image 96x64.
        let (w, h) = (96, 64);
        let data: Vec<f32> = (0..w * h)
            .map(|i| {
                let x = (i % w) as f64;
                ((x + 0.5 - 40.3).clamp(0.0, 1.0) * 0.6 + 0.2) as f32
            })
            .collect();
        let img = Plane::from_vec(w, h, data);
        let cam = CameraModel::from_hfov(w as u32, h as u32, 60.0);
        let pyr = build_pyramid(&img, &cam, (0, 0, w, h), 3);
        assert_eq!(pyr.len(), 3);
        for lv in &pyr {
            // Edge position in this level's coordinates: (x + 0.5) s - 0.5 with x = 40.3 (pixel
            // x covers [x - 0.5, x + 0.5], so the 50% crossing is at x = 40.3).
            let xe = (40.3 + 0.5) * lv.scale - 0.5;
            let p = Point2::new(xe - 2.2, 8.0 * lv.scale);
            let hit = lv.search(&p, &Vector2::x(), 5, 0.01, 0).unwrap();
            assert!((p.x + hit.offset - xe).abs() < 0.1, "level {}: {:?} vs {xe}", lv.scale, hit);
            assert!(hit.strength > 0.0);
            assert!(lv.search(&p, &Vector2::x(), 5, 0.01, -1).is_none(), "wrong polarity is rejected");
        }
    }
}
