//! Coarse-to-fine matching of a template library against an image (raw matches; their
//! suppression and re-ranking: [`crate::line2d::nms`]).
//!
//! Similarity of template `T` placed with its top-left pixel at `c` (Hinterstoisser et al.):
//! `E(c) = Σ_f S_{o_f}(c + p_f)` where `S_o` is the response map of orientation `o`
//! (see [`crate::line2d::response`]), i.e. for each feature the best `floor(4 |cos|)` over its
//! spreading neighbourhood. The score in percent is `100 E / (4 n)` for `n` features.
//!
//! Pyramid: level 1 (half resolution, spreading `t1`, default 8) evaluates every template at
//! every grid position `(c T, r T)` through the linearized memories; grid positions that reach
//! the coarse threshold and are local maxima of the template's score map become candidates.
//! Level 0 (full resolution, spreading `t0`, default 4) then evaluates the template's level-0
//! features at every second row of a `(2 t1 + 5)²` window around `2 (c T, r T)`, then at the
//! rows next to the best one, and keeps the best if it reaches the threshold; a row of the
//! window is 32 lanes scored at once from contiguous response-map bytes. A row is abandoned
//! as soon as its best partial sum plus [`SIM_MAX`] for every feature still to add stays below
//! both the threshold and the best score so far (on clutter most rows stop after 24-40 of 64
//! features).
//!
//! Accumulation is integer and cannot overflow: per-feature values are at most 4, so blocks of
//! up to 63 features are summed in `u8` (`63 · 4 = 252 <= 255`, plain wrapping adds that never
//! wrap, vectorized 32 lanes wide), and each block is widened into `u16` totals (up to
//! 16383 features). Rayon runs across templates.

use crate::line2d::gradient::{downsample_rgb, quantize_rgb};
use crate::line2d::params::MatchParams;
use crate::line2d::response::{linearize, response_maps, spread, LinearMemories, ResponseMaps};
use crate::line2d::template::{Template, TemplateLibrary};
use crate::line2d::{Line2dError, SIM_MAX};
use rayon::prelude::*;

/// The precomputed image side: response maps at level 0, linearized memories at level 1.
#[derive(Clone, Debug)]
pub struct PreparedImage {
    /// Original image width, pixels.
    pub width: usize,
    /// Original image height, pixels.
    pub height: usize,
    /// Level-0 response maps over the padded image (size a multiple of `2 t1`).
    pub resp0: ResponseMaps,
    /// Level-1 linearized memories (grid step `t1`).
    pub lm1: LinearMemories,
    /// Level-0 response maps with the re-ranking spreading (`rerank_t`), when enabled.
    pub resp_rerank: Option<ResponseMaps>,
}

/// A raw match before NMS: template, level-0 top-left position and score in percent.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RawMatch {
    /// Template id.
    pub template: u32,
    /// Column of the template's top-left pixel at level 0.
    pub x: i32,
    /// Row of the template's top-left pixel at level 0.
    pub y: i32,
    /// Similarity, percent.
    pub score: f32,
}

/// Computes the image side of the matcher (gradients, spreading, response maps, linearization).
pub fn prepare_image(rgb: &[u8], width: usize, height: usize, p: &MatchParams) -> Result<PreparedImage, Line2dError> {
    if rgb.len() != width * height * 3 {
        return Err(Line2dError::invalid("image", format!("RGB buffer has {} bytes, expected {}", rgb.len(), width * height * 3)));
    }
    if width < 2 * p.t1 || height < 2 * p.t1 || p.t0 == 0 || p.t1 == 0 {
        return Err(Line2dError::invalid("image", format!("{width}x{height} is too small for T = {}/{}", p.t0, p.t1)));
    }
    let m = 2 * p.t1;
    let (wp, hp) = (width.div_ceil(m) * m, height.div_ceil(m) * m);
    let q0 = quantize_rgb(rgb, width, height, &p.gradient);
    let resp0 = response_maps(&spread(&q0, p.t0, wp, hp));
    let resp_rerank = (p.rerank_t > 0).then(|| response_maps(&spread(&q0, p.rerank_t, wp, hp)));
    let (rgb1, w1, h1) = downsample_rgb(rgb, width, height);
    let q1 = quantize_rgb(&rgb1, w1, h1, &p.gradient);
    let lm1 = linearize(&response_maps(&spread(&q1, p.t1, wp / 2, hp / 2)), p.t1);
    Ok(PreparedImage { width, height, resp0, lm1, resp_rerank })
}

#[inline]
fn add_u8_scalar(acc: &mut [u8], src: &[u8]) {
    for (a, &s) in acc.iter_mut().zip(src) {
        *a = a.wrapping_add(s);
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn add_u8_avx2(acc: &mut [u8], src: &[u8]) {
    add_u8_scalar(acc, src)
}

#[inline]
fn widen_add_scalar(acc: &mut [u16], src: &[u8]) {
    for (a, &s) in acc.iter_mut().zip(src) {
        *a += s as u16;
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn widen_add_avx2(acc: &mut [u16], src: &[u8]) {
    widen_add_scalar(acc, src)
}

#[derive(Clone, Copy)]
struct Simd {
    avx2: bool,
}

impl Simd {
    fn detect() -> Simd {
        #[cfg(target_arch = "x86_64")]
        {
            Simd { avx2: std::is_x86_feature_detected!("avx2") }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            Simd { avx2: false }
        }
    }
    #[inline]
    fn add_u8(self, acc: &mut [u8], src: &[u8]) {
        #[cfg(target_arch = "x86_64")]
        if self.avx2 {
            // SAFETY: AVX2 availability checked at run time in `detect`.
            return unsafe { add_u8_avx2(acc, src) };
        }
        add_u8_scalar(acc, src)
    }
    #[inline]
    fn widen_add(self, acc: &mut [u16], src: &[u8]) {
        #[cfg(target_arch = "x86_64")]
        if self.avx2 {
            // SAFETY: as above.
            return unsafe { widen_add_avx2(acc, src) };
        }
        widen_add_scalar(acc, src)
    }
}

/// Level-1 score map (raw sums, `grid_h x grid_w`) of a template over the linearized memories.
/// Positions whose template would cross the right or bottom border hold sums that wrapped
/// across rows; callers must ignore them.
pub fn coarse_scores(lm: &LinearMemories, t: &Template, acc16: &mut Vec<u16>, acc8: &mut Vec<u8>) {
    coarse_scores_with(Simd::detect(), lm, t, acc16, acc8)
}

fn coarse_scores_with(simd: Simd, lm: &LinearMemories, t: &Template, acc16: &mut Vec<u16>, acc8: &mut Vec<u8>) {
    let n = lm.grid_w * lm.grid_h;
    acc16.clear();
    acc16.resize(n, 0);
    acc8.resize(n, 0);
    for block in t.levels[1].features.chunks(63) {
        acc8.fill(0);
        add_features_u8(simd, lm, block, acc8);
        simd.widen_add(acc16, acc8);
    }
}

/// Raw level-0 score `E(x, y)` of a template at one position (bounds-checked, no SIMD).
pub fn fine_score_at(resp: &ResponseMaps, t: &Template, x: usize, y: usize) -> u32 {
    t.levels[0].features.iter().map(|f| resp.maps[f.ori as usize][(y + f.y as usize) * resp.width + x + f.x as usize] as u32).sum()
}

/// Widest fine-search window handled in one pass of lanes (pixels).
pub const FINE_LANES: usize = 32;

/// Adds `src[..32]` into `acc` (u8, wrapping; callers keep sums <= 255), reading only what
/// exists of `src` (the rest counts 0).
#[inline(always)]
fn add_lanes(acc: &mut [u8; FINE_LANES], map: &[u8], base: usize) {
    match map.get(base..base + FINE_LANES) {
        Some(s) => {
            for (a, &v) in acc.iter_mut().zip(s) {
                *a = a.wrapping_add(v);
            }
        }
        None => {
            for (a, &v) in acc.iter_mut().zip(map.get(base..).unwrap_or(&[])) {
                *a = a.wrapping_add(v);
            }
        }
    }
}

/// Raw level-0 scores of 32 consecutive positions of one row: `out[i] = E(x_lo + i, y)`
/// (lanes whose template would cross the row end hold wrapped sums; callers ignore them).
#[inline(always)]
fn fine_lanes(resp: &ResponseMaps, t: &Template, x_lo: usize, y: usize, out: &mut [u16; FINE_LANES]) {
    let w = resp.width;
    *out = [0; FINE_LANES];
    for block in t.levels[0].features.chunks(63) {
        let mut acc = [0u8; FINE_LANES];
        for f in block {
            add_lanes(&mut acc, &resp.maps[f.ori as usize], (y + f.y as usize) * w + x_lo + f.x as usize);
        }
        for (o, &a) in out.iter_mut().zip(&acc) {
            *o += a as u16;
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[allow(clippy::too_many_arguments)]
unsafe fn fine_search_avx2(resp: &ResponseMaps, t: &Template, x_lo: usize, x_hi: usize, y_lo: usize, y_hi: usize, row_step: usize, need: u32) -> (u32, usize, usize) {
    use std::arch::x86_64::*;
    let w = resp.width;
    let feats = &t.levels[0].features;
    let n_map = resp.maps[0].len();
    // Fast path: every 32-byte load of the window lies inside the maps.
    let max_off = feats.iter().map(|f| (y_hi + f.y as usize) * w + x_lo + f.x as usize).max().unwrap_or(0);
    if x_hi - x_lo + 1 > FINE_LANES || max_off + FINE_LANES > n_map {
        return fine_search_scalar(resp, t, x_lo, x_hi, y_lo, y_hi, row_step, need);
    }
    let nx = x_hi - x_lo + 1;
    let maps: [*const u8; 8] = std::array::from_fn(|o| resp.maps[o].as_ptr());
    // Lanes of the window (the rest hold positions outside it and must not raise a bound).
    let lane_ids = _mm256_setr_epi8(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17, 18, 19, 20, 21, 22, 23, 24, 25, 26, 27, 28, 29, 30, 31);
    let in_window = _mm256_cmpgt_epi8(_mm256_set1_epi8(nx as i8), lane_ids);
    let n = feats.len() as u32;
    let mut row = [0u16; FINE_LANES];
    let score_row = |y: usize, best: &mut (u32, usize, usize)| {
        // A row that cannot reach `need`, nor the best so far, cannot hold the result.
        let bar = need.max(best.0);
        let mut lo16 = _mm256_setzero_si256();
        let mut hi16 = _mm256_setzero_si256();
        for (b, block) in feats.chunks(63).enumerate() {
            let mut acc = _mm256_setzero_si256();
            for (k, f) in block.iter().enumerate() {
                // SAFETY: offset + 32 <= n_map checked above for the largest row y_hi.
                let ptr = maps[f.ori as usize & 7].add((y + f.y as usize) * w + x_lo + f.x as usize);
                acc = _mm256_add_epi8(acc, _mm256_loadu_si256(ptr as *const __m256i));
                // Early exit within the first block: the row's best partial sum plus the most
                // the remaining features can add cannot reach `need`.
                if b == 0 && (k + 1) % PRUNE_EVERY == 0 && k + 1 >= PRUNE_FIRST && k + 1 < block.len() {
                    let part = max_u8(_mm256_and_si256(acc, in_window));
                    if part + SIM_MAX * (n - k as u32 - 1) < bar {
                        return;
                    }
                }
            }
            let z = _mm256_setzero_si256();
            // Widen: unpack interleaves within 128-bit lanes; undone when storing below.
            lo16 = _mm256_add_epi16(lo16, _mm256_unpacklo_epi8(acc, z));
            hi16 = _mm256_add_epi16(hi16, _mm256_unpackhi_epi8(acc, z));
        }
        // lo16 = bytes [0..8, 16..24], hi16 = bytes [8..16, 24..32].
        let a = _mm256_permute2x128_si256(lo16, hi16, 0x20);
        let b = _mm256_permute2x128_si256(lo16, hi16, 0x31);
        _mm256_storeu_si256(row.as_mut_ptr() as *mut __m256i, a);
        _mm256_storeu_si256(row.as_mut_ptr().add(16) as *mut __m256i, b);
        keep_best(&row[..nx], x_lo, y, best);
    };
    scan_rows(x_lo, y_lo, y_hi, row_step, need, score_row)
}

/// Features accumulated between two early-exit tests of a row in the fine search.
const PRUNE_EVERY: usize = 8;

/// Features accumulated before the first early-exit test (before it the bound rarely binds).
const PRUNE_FIRST: usize = 24;

/// Largest of the 32 unsigned bytes of `v`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn max_u8(v: std::arch::x86_64::__m256i) -> u32 {
    use std::arch::x86_64::*;
    let mut x = _mm_max_epu8(_mm256_castsi256_si128(v), _mm256_extracti128_si256(v, 1));
    x = _mm_max_epu8(x, _mm_srli_si128(x, 8));
    x = _mm_max_epu8(x, _mm_srli_si128(x, 4));
    x = _mm_max_epu8(x, _mm_srli_si128(x, 2));
    x = _mm_max_epu8(x, _mm_srli_si128(x, 1));
    (_mm_cvtsi128_si32(x) & 0xff) as u32
}

/// Keeps in `best` the higher of it and the scores `row[i]` at `(x0 + i, y)`; ties go to the
/// smaller `(y, x)`, so the result does not depend on the scan order.
#[inline(always)]
fn keep_best(row: &[u16], x0: usize, y: usize, best: &mut (u32, usize, usize)) {
    for (i, &v) in row.iter().enumerate() {
        let cand = (v as u32, x0 + i, y);
        if cand.0 > best.0 || (cand.0 == best.0 && (cand.2, cand.1) < (best.2, best.1)) {
            *best = cand;
        }
    }
}

/// Scores rows `y_lo..=y_hi` (every `row_step`-th) through `score_row` and returns the best
/// `(score, x, y)`; with `row_step = 2` the two skipped rows next to the best one are scored
/// too when it reaches `need`.
#[inline(always)]
fn scan_rows(x_lo: usize, y_lo: usize, y_hi: usize, row_step: usize, need: u32, mut score_row: impl FnMut(usize, &mut (u32, usize, usize))) -> (u32, usize, usize) {
    let mut best = (0u32, x_lo, y_lo);
    for y in (y_lo..=y_hi).step_by(row_step) {
        score_row(y, &mut best);
    }
    if row_step == 2 && best.0 >= need {
        let by = best.2;
        for y in [by.wrapping_sub(1), by + 1] {
            if y >= y_lo && y <= y_hi && (y - y_lo) % 2 == 1 {
                score_row(y, &mut best);
            }
        }
    }
    best
}

#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn fine_search_scalar(resp: &ResponseMaps, t: &Template, x_lo: usize, x_hi: usize, y_lo: usize, y_hi: usize, row_step: usize, need: u32) -> (u32, usize, usize) {
    let mut row = [0u16; FINE_LANES];
    let score_row = |y: usize, best: &mut (u32, usize, usize)| {
        let mut x0 = x_lo;
        while x0 <= x_hi {
            let nx = (x_hi - x0 + 1).min(FINE_LANES);
            fine_lanes(resp, t, x0, y, &mut row);
            keep_best(&row[..nx], x0, y, best);
            x0 += FINE_LANES;
        }
    };
    scan_rows(x_lo, y_lo, y_hi, row_step, need, score_row)
}

/// Best level-0 position in the window `[x_lo, x_hi] x [y_lo, y_hi]` (inclusive, valid).
/// Rows are scored whole, 32 consecutive positions at once (one contiguous 32-byte slice of
/// the response map per feature, u8 blocks of 63 features widened to u16). With
/// `row_step = 1` the search is exhaustive; with `row_step = 2` every second row is scored,
/// then the two rows next to the best one. Ties go to the first position in row-major order.
/// Returns `(E, x, y)`.
pub fn fine_search(resp: &ResponseMaps, t: &Template, x_lo: usize, x_hi: usize, y_lo: usize, y_hi: usize, row_step: usize) -> (u32, usize, usize) {
    fine_search_at_least(resp, t, x_lo, x_hi, y_lo, y_hi, row_step, 0).expect("every score reaches 0")
}

/// [`fine_search`] when only a score of at least `need` matters, with rows abandoned early: a
/// row whose best partial sum plus [`SIM_MAX`] per feature still to add stays below `need` and
/// below the best score so far cannot hold the result. With `row_step = 1` the result is
/// [`fine_search`]'s when it scores `>= need`, else None. With `row_step = 2` it is None when
/// no even row reaches `need` (the rows next to the best even row are scored only when it
/// does; [`fine_search`] would sometimes find an odd row reaching `need` there: 18 % of the
/// raw matches of a rendered paper frame, all near the threshold), else [`fine_search`]'s.
#[allow(clippy::too_many_arguments)]
pub fn fine_search_at_least(resp: &ResponseMaps, t: &Template, x_lo: usize, x_hi: usize, y_lo: usize, y_hi: usize, row_step: usize, need: u32) -> Option<(u32, usize, usize)> {
    let row_step = row_step.clamp(1, 2);
    #[cfg(target_arch = "x86_64")]
    let best = if std::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2 (checked at run time).
        unsafe { fine_search_avx2(resp, t, x_lo, x_hi, y_lo, y_hi, row_step, need) }
    } else {
        fine_search_scalar(resp, t, x_lo, x_hi, y_lo, y_hi, row_step, need)
    };
    #[cfg(not(target_arch = "x86_64"))]
    let best = fine_search_scalar(resp, t, x_lo, x_hi, y_lo, y_hi, row_step, need);
    (best.0 >= need).then_some(best)
}

/// Raw matches of one template (coarse candidates verified at level 0), before NMS.
pub fn match_template(img: &PreparedImage, t: &Template, p: &MatchParams, acc16: &mut Vec<u16>, acc8: &mut Vec<u8>) -> Vec<RawMatch> {
    match_template_impl(img, t, p, acc16, acc8, TAIL_MAX)
}

fn match_template_impl(img: &PreparedImage, t: &Template, p: &MatchParams, acc16: &mut Vec<u16>, acc8: &mut Vec<u8>, tail_max: usize) -> Vec<RawMatch> {
    coarse_candidates(img, t, p, acc16, acc8, tail_max).into_iter().filter_map(|(_, r, c)| fine_match(img, t, p, r as usize, c as usize)).collect()
}

/// The level-0 match of template `t` around the level-1 grid position `(r, c)` (the best in
/// the window, if it reaches the threshold).
fn fine_match(img: &PreparedImage, t: &Template, p: &MatchParams, r: usize, c: usize) -> Option<RawMatch> {
    let l0 = &t.levels[0];
    let (w0, h0) = (img.resp0.width, img.resp0.height);
    let tt = img.lm1.t;
    let rad = tt + 2;
    let n0 = l0.features.len() as f32;
    let need0 = (p.threshold / 100.0 * SIM_MAX as f32 * n0).ceil().max(1.0) as u32;
    let (gx, gy) = (2 * c * tt, 2 * r * tt);
    let x_lo = gx.saturating_sub(rad);
    let y_lo = gy.saturating_sub(rad);
    let x_hi = (gx + rad).min(w0 - l0.width as usize);
    let y_hi = (gy + rad).min(h0 - l0.height as usize);
    if x_lo > x_hi || y_lo > y_hi {
        return None;
    }
    fine_search_at_least(&img.resp0, t, x_lo, x_hi, y_lo, y_hi, 2, need0).map(|(e, x, y)| RawMatch { template: t.id, x: x as i32, y: y as i32, score: 100.0 * e as f32 / (SIM_MAX as f32 * n0) })
}

/// The level-1 grid positions `(coarse score, r, c)` of template `t` that go to the level-0
/// search: local maxima reaching the coarse threshold, at most [`MatchParams::max_candidates`]
/// (the best by coarse score), in row-major order. The score is the raw level-1 sum.
fn coarse_candidates(img: &PreparedImage, t: &Template, p: &MatchParams, acc16: &mut Vec<u16>, acc8: &mut Vec<u8>, tail_max: usize) -> Vec<(u16, u16, u16)> {
    let simd = Simd::detect();
    let lm = &img.lm1;
    let l1 = &t.levels[1];
    let l0 = &t.levels[0];
    let (w0, h0) = (img.resp0.width, img.resp0.height);
    if (l0.width as usize) > w0 || (l0.height as usize) > h0 {
        return vec![];
    }
    let (w1, h1) = (lm.grid_w * lm.t, lm.grid_h * lm.t);
    if (l1.width as usize) > w1 || (l1.height as usize) > h1 {
        return vec![];
    }
    let tt = lm.t;
    let cmax = (w1 - l1.width as usize) / tt;
    let rmax = (h1 - l1.height as usize) / tt;
    let n1 = l1.features.len();
    let coarse_thr = p.coarse_threshold.unwrap_or(p.threshold);
    let need1 = (coarse_thr / 100.0 * SIM_MAX as f32 * n1 as f32).ceil().max(1.0) as u16;
    let gw = lm.grid_w;
    let n = gw * lm.grid_h;
    // Coarse candidates `(score, r, c)` in row-major order.
    let mut cands: Vec<(u16, usize, usize)> = Vec::new();
    let head = n1.min(63);
    if n1 - head <= tail_max && n1 > 0 {
        // Head block in u8 over all grid positions; the tail only on rows where the head can
        // still reach `need1` (each tail feature adds at most SIM_MAX).
        let tail = &l1.features[head..];
        let Some(need_head) = need1.checked_sub((SIM_MAX as usize * tail.len()) as u16).map(|v| v.max(1)) else {
            return vec![];
        };
        if need_head > (SIM_MAX as usize * head) as u16 {
            return vec![];
        }
        let need_head = need_head as u8;
        acc8.clear();
        acc8.resize(n, 0);
        add_features_u8(simd, lm, &l1.features[..head], acc8);
        // Exact u16 scores, only on the rows where the head alone can reach `need_head` (the
        // other rows hold no candidate and stay 0 < need1): the row's head sums widened, plus
        // each tail feature's memory row, vectorized.
        acc16.clear();
        acc16.resize(n, 0);
        for r in 0..=rmax {
            let row = r * gw..r * gw + cmax + 1;
            if acc8[row.clone()].iter().copied().max().unwrap_or(0) < need_head {
                continue;
            }
            let out = &mut acc16[row.clone()];
            simd.widen_add(out, &acc8[row.clone()]);
            for f in tail {
                let start = (f.y as usize / tt) * gw + f.x as usize / tt;
                let m = lm.memory(f.ori as usize, f.x as usize % tt, f.y as usize % tt);
                simd.widen_add(out, &m[start + row.start..start + row.end]);
            }
        }
    } else {
        coarse_scores_with(simd, lm, t, acc16, acc8);
    }
    candidates(acc16, need1, rmax, cmax, gw, &mut |r, c, v| cands.push((v, r, c)));
    if p.max_candidates > 0 && cands.len() > p.max_candidates {
        // The best by coarse score (ties: row-major order), then back in row-major order
        // (positions are distinct, so the order is total and selection is exact).
        cands.select_nth_unstable_by(p.max_candidates - 1, |a, b| b.0.cmp(&a.0).then((a.1, a.2).cmp(&(b.1, b.2))));
        cands.truncate(p.max_candidates);
        cands.sort_unstable_by_key(|&(_, r, c)| (r, c));
    }
    cands.into_iter().map(|(v, r, c)| (v, r as u16, c as u16)).collect()
}

/// Level-1 features beyond the first u8 block of 63 that are added only on the grid rows whose
/// head block can still reach the threshold instead of over the whole grid; longer templates
/// use the u16 path.
const TAIL_MAX: usize = 8;

/// Sums `features` (at most 63) into the u8 grid accumulator `acc` over the linearized memories.
fn add_features_u8(simd: Simd, lm: &LinearMemories, features: &[crate::line2d::Feature], acc: &mut [u8]) {
    let n = acc.len();
    let tt = lm.t;
    for f in features {
        let (fx, fy) = (f.x as usize, f.y as usize);
        let start = (fy / tt) * lm.grid_w + fx / tt;
        if start >= n {
            continue;
        }
        simd.add_u8(&mut acc[..n - start], &lm.memory(f.ori as usize, fx % tt, fy % tt)[start..]);
    }
}

/// Calls `found(r, c, v)` for every grid position `(r <= rmax, c <= cmax)` whose score
/// `v = scores[r gw + c]` reaches `need` and is a strict local maximum among its valid
/// 8-neighbours (ties go to the first in row-major order): `v` exceeds the neighbours before
/// it in row-major order and is at least those after it. Branch-free per row: the three rows
/// are copied between zero borders (a missing neighbour counts 0 < need <= v, so it never
/// decides) and the test runs over the whole row in vector lanes; rows whose maximum stays
/// below `need` are skipped.
fn candidates(scores: &[u16], need: u16, rmax: usize, cmax: usize, gw: usize, found: &mut impl FnMut(usize, usize, u16)) {
    let wv = cmax + 1;
    let wp = wv + 2;
    // Rows r - 1, r, r + 1 with a zero on each side, then the per-position flags.
    let mut pad = vec![0u16; 3 * wp];
    let mut flags = vec![false; wv];
    let row_of = |r: usize| &scores[r * gw..r * gw + wv];
    for r in 0..=rmax {
        if row_of(r).iter().copied().max().unwrap_or(0) < need {
            continue;
        }
        let (up, rest) = pad.split_at_mut(wp);
        let (cur, dn) = rest.split_at_mut(wp);
        for (dst, src) in [(&mut *up, r.checked_sub(1)), (&mut *cur, Some(r)), (&mut *dn, (r < rmax).then_some(r + 1))] {
            match src {
                Some(rr) => dst[1..=wv].copy_from_slice(row_of(rr)),
                None => dst.fill(0),
            }
        }
        for (c, flag) in flags.iter_mut().enumerate() {
            let v = cur[c + 1];
            *flag = (v >= need) & (v > up[c]) & (v > up[c + 1]) & (v > up[c + 2]) & (v > cur[c]) & (v >= cur[c + 2]) & (v >= dn[c]) & (v >= dn[c + 1]) & (v >= dn[c + 2]);
        }
        for (c, _) in flags.iter().enumerate().filter(|(_, &f)| f) {
            found(r, c, cur[c + 1]);
        }
    }
}

/// All raw matches of a library (rayon across templates), sorted by decreasing score.
///
/// With a candidate budget ([`MatchParams::max_candidates_per_mpx`]) the coarse candidates
/// of all templates beyond `budget · max(1, width · height / 10⁶)` keep only the best by coarse
/// similarity (raw level-1 sum over `4 n`, the same scale for every template; ties in
/// template, row, column order) before the level-0 search: on a textured frame every template
/// reaches the coarse threshold in many places, and the budget bounds the level-0 work per
/// pixel whatever the texture.
pub fn match_all(img: &PreparedImage, lib: &TemplateLibrary, p: &MatchParams) -> Vec<RawMatch> {
    match_all_within(img, lib, p, (img.width * img.height) as f64)
}

/// [`match_all`] with the candidate budget counted over `budget_area` pixels instead of the
/// image's own (`budget · max(1, budget_area / 10⁶)` candidates): the far search of an
/// enlarged image keeps the budget of the image at the library's scale.
pub fn match_all_within(img: &PreparedImage, lib: &TemplateLibrary, p: &MatchParams, budget_area: f64) -> Vec<RawMatch> {
    let mut cands: Vec<Vec<(u16, u16, u16)>> = lib.templates.par_iter().map_init(|| (Vec::new(), Vec::new()), |(a16, a8), t| coarse_candidates(img, t, p, a16, a8, TAIL_MAX)).collect();
    let total: usize = cands.iter().map(Vec::len).sum();
    let budget = (p.max_candidates_per_mpx as f64 * (budget_area / 1e6).max(1.0)).ceil() as usize;
    if p.max_candidates_per_mpx > 0 && total > budget {
        // Coarse similarity in 1/65536 of the maximum, comparable across templates.
        let key = |t: &Template, v: u16| (v as u64 * 65536 / (SIM_MAX as u64 * t.levels[1].features.len().max(1) as u64)) as u32;
        let mut keys: Vec<u32> = cands.iter().zip(&lib.templates).flat_map(|(c, t)| c.iter().map(move |&(v, _, _)| key(t, v))).collect();
        let cut = *keys.select_nth_unstable_by(budget.max(1) - 1, |a, b| b.cmp(a)).1;
        // Above the cut all are kept; at the cut, the first in template order fill the budget.
        let mut at_cut = budget - keys.iter().filter(|&&k| k > cut).count();
        for (c, t) in cands.iter_mut().zip(&lib.templates) {
            c.retain(|&(v, _, _)| {
                let k = key(t, v);
                k > cut
                    || (k == cut && at_cut > 0 && {
                        at_cut -= 1;
                        true
                    })
            });
        }
    }
    let mut all: Vec<RawMatch> = cands.par_iter().zip(&lib.templates).flat_map_iter(|(c, t)| c.iter().filter_map(|&(_, r, cc)| fine_match(img, t, p, r as usize, cc as usize))).collect();
    // Matches equal in this order are equal in every field, so an unstable sort is exact.
    all.sort_unstable_by(|a, b| b.score.total_cmp(&a.score).then(a.template.cmp(&b.template)).then((a.y, a.x).cmp(&(b.y, b.x))));
    all
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::line2d::render::draw_tube_rgb;
    use crate::line2d::template::LibraryParams;
    use crate::line2d::ViewParams;
    use nalgebra::{Rotation3, Vector3};
    use rand::{Rng, SeedableRng};
    use tubeloc_core::{Pose, TubeModel};

    /// The candidate cap keeps each template's best coarse candidates: with a cap of 1 every
    /// template yields at most one raw match, one of those it yields uncapped; a cap above
    /// every template's candidate count changes nothing.
    #[test]
    fn candidate_cap_keeps_the_best_and_is_exact_when_it_does_not_bind() {
        let (w, h) = (320usize, 256usize);
        let mut lp = LibraryParams { views: ViewParams { dist_min: 1.6, dist_max: 1.6, step_deg: 30.0, ..ViewParams::default() }, ..LibraryParams::default() };
        lp.camera.cx = w as f64 / 2.0;
        lp.camera.cy = h as f64 / 2.0;
        let lib = TemplateLibrary::build(&TubeModel::default(), &lp, &|_| {}).unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        // Textured ground: random bright and dark bars give many coarse candidates.
        let mut img: Vec<u8> = (0..w * h * 3).map(|i| if (i / 3 / w / 6 + i / 3 % w / 9) % 2 == 0 { 150 } else { rng.random_range(40..=90u8) }).collect();
        let pose = Pose::from_parts(Rotation3::from_axis_angle(&Vector3::y_axis(), 1.2), Vector3::new(0.02, 0.01, 1.6));
        draw_tube_rgb(&mut img, w, h, &TubeModel::default(), &lp.camera, &pose);
        let base = MatchParams { threshold: 55.0, max_candidates: 0, ..MatchParams::default() };
        let prep = prepare_image(&img, w, h, &base).unwrap();
        let all = match_all(&prep, &lib, &base);
        let one = match_all(&prep, &lib, &MatchParams { max_candidates: 1, ..base.clone() });
        let wide = match_all(&prep, &lib, &MatchParams { max_candidates: 100_000, ..base.clone() });
        assert_eq!(wide, all);
        assert!(one.len() < all.len(), "a cap of 1 removed nothing ({} matches)", all.len());
        for t in &lib.templates {
            let mine: Vec<&RawMatch> = one.iter().filter(|m| m.template == t.id).collect();
            assert!(mine.len() <= 1, "template {} kept {} matches", t.id, mine.len());
            for m in mine {
                assert!(all.contains(m), "capped match {m:?} is not an uncapped match");
            }
        }
    }

    /// The candidate budget keeps the coarse candidates with the best coarse similarity over
    /// all templates: a budget above their number changes nothing; a small one keeps a strict
    /// subset of the unbudgeted matches.
    #[test]
    fn candidate_budget_keeps_the_best_coarse_candidates_over_all_templates() {
        let (w, h) = (320usize, 256usize);
        let mut lp = LibraryParams { views: ViewParams { dist_min: 1.6, dist_max: 1.6, step_deg: 30.0, ..ViewParams::default() }, ..LibraryParams::default() };
        lp.camera.cx = w as f64 / 2.0;
        lp.camera.cy = h as f64 / 2.0;
        let lib = TemplateLibrary::build(&TubeModel::default(), &lp, &|_| {}).unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        let mut img: Vec<u8> = (0..w * h * 3).map(|i| if (i / 3 / w / 5 + i / 3 % w / 7) % 2 == 0 { 160 } else { rng.random_range(30..=100u8) }).collect();
        let pose = Pose::from_parts(Rotation3::from_axis_angle(&Vector3::y_axis(), 1.1), Vector3::new(0.01, 0.02, 1.6));
        draw_tube_rgb(&mut img, w, h, &TubeModel::default(), &lp.camera, &pose);
        let base = MatchParams { threshold: 55.0, max_candidates: 0, max_candidates_per_mpx: 0, ..MatchParams::default() };
        let prep = prepare_image(&img, w, h, &base).unwrap();
        let (mut a16, mut a8) = (Vec::new(), Vec::new());
        let total: usize = lib.templates.iter().map(|t| coarse_candidates(&prep, t, &base, &mut a16, &mut a8, TAIL_MAX).len()).sum();
        assert!(total > 50, "{total} candidates");
        let all = match_all(&prep, &lib, &base);
        // Budgets are per megapixel, and images under 1 MP get the 1 MP budget.
        let wide = match_all(&prep, &lib, &MatchParams { max_candidates_per_mpx: total, ..base.clone() });
        assert_eq!(wide, all);
        let small = match_all(&prep, &lib, &MatchParams { max_candidates_per_mpx: total / 4, ..base.clone() });
        assert!(small.len() < all.len(), "a budget of {} of {total} candidates removed nothing", total / 4);
        for m in &small {
            assert!(all.contains(m), "budgeted match {m:?} is not an unbudgeted match");
        }
    }

    /// `candidates` returns exactly the strict local maxima (ties to the first in row-major
    /// order) reaching the threshold, found by brute force over random score grids with
    /// plateaus, including the positions on the last valid row and column.
    #[test]
    fn candidates_are_the_thresholded_local_maxima() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        for trial in 0..40 {
            let (gw, gh) = (rng.random_range(3..40usize), rng.random_range(3..30usize));
            let (cmax, rmax) = (rng.random_range(0..gw), rng.random_range(0..gh));
            let scores: Vec<u16> = (0..gw * gh).map(|_| rng.random_range(0..12u16)).collect();
            let need = rng.random_range(1..10u16);
            let mut found = Vec::new();
            candidates(&scores, need, rmax, cmax, gw, &mut |r, c, v| found.push((r, c, v)));
            let mut brute = Vec::new();
            for r in 0..=rmax {
                for c in 0..=cmax {
                    let v = scores[r * gw + c];
                    let beaten = (r.saturating_sub(1)..=(r + 1).min(rmax)).any(|rr| {
                        (c.saturating_sub(1)..=(c + 1).min(cmax)).any(|cc| {
                            (rr, cc) != (r, c) && {
                                let u = scores[rr * gw + cc];
                                u >= need && (u > v || (u == v && (rr, cc) < (r, c)))
                            }
                        })
                    });
                    if v >= need && !beaten {
                        brute.push((r, c, v));
                    }
                }
            }
            assert_eq!(found, brute, "trial {trial}: {gw}x{gh}, cmax {cmax}, rmax {rmax}, need {need}");
        }
    }

    /// The head-block + tail-rows path finds exactly the matches of the full u16 path.
    #[test]
    fn head_tail_path_equals_full_u16_path() {
        let (w, h) = (320usize, 256usize);
        for features in [40u32, 64, 70] {
            let mut lp = LibraryParams { features, ..LibraryParams::default() };
            lp.views = ViewParams { dist_min: 1.6, dist_max: 1.6, step_deg: 30.0, ..ViewParams::default() };
            lp.camera.cx = w as f64 / 2.0;
            lp.camera.cy = h as f64 / 2.0;
            let lib = TemplateLibrary::build(&TubeModel::default(), &lp, &|_| {}).unwrap();
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
            let mut img: Vec<u8> = (0..w * h * 3).map(|_| rng.random_range(90..=150u8)).collect();
            let pose = Pose::from_parts(Rotation3::from_axis_angle(&Vector3::y_axis(), 1.2), Vector3::new(0.02, 0.01, 1.6));
            draw_tube_rgb(&mut img, w, h, &TubeModel::default(), &lp.camera, &pose);
            let p = MatchParams { threshold: 55.0, ..MatchParams::default() };
            let prep = prepare_image(&img, w, h, &p).unwrap();
            let (mut a16, mut a8) = (Vec::new(), Vec::new());
            let mut total = 0;
            for t in &lib.templates {
                let fast = match_template_impl(&prep, t, &p, &mut a16, &mut a8, TAIL_MAX);
                let full = match_template_impl(&prep, t, &p, &mut a16, &mut a8, 0);
                assert_eq!(fast, full, "template {} ({} level-1 features)", t.id, t.levels[1].features.len());
                total += fast.len();
            }
            assert!(total > 0, "no match at all with {features} features");
        }
    }
}
