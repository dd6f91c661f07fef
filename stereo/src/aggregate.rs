//! Semi-global cost aggregation (Hirschmüller 2008, eq. 11-14) fused with winner-takes-all,
//! sub-pixel refinement and the left-right consistency check.
//!
//! Along a path direction `r` the cost is
//!
//! ```text
//! L_r(p, d) = C(p, d) + min(L_r(p-r, d), L_r(p-r, d±1) + P1, min_k L_r(p-r, k) + P2') - min_k L_r(p-r, k)
//! P2' = max(P1, P2 / (1 + |I(p) - I(p-r)| / k))
//! ```
//!
//! and `S(p, d) = Σ_r L_r(p, d)`. Costs are `i16` (SSE2/AVX2 have signed 16-bit min and
//! saturating add); each `L_r <= C_max + P2`, so `S` fits in `i16` when `8 (C_max + P2) < 32768`.
//!
//! Order of work: a forward sweep (rows top to bottom) computes the paths coming from the left,
//! top-left, top and top-right and stores their sum `S`; a backward sweep (bottom to top) adds
//! the paths from the right, bottom-right, bottom and bottom-left and, as soon as a row of `S`
//! is complete, selects disparities. Within a row the vertical and diagonal paths depend only
//! on the previous row, so they run in parallel over chunks of columns (rayon) while another
//! task runs the row's horizontal path. Inner loops run over the disparity axis.

use rayon::prelude::*;
use tubeloc_core::Plane;

const SENT: i16 = i16::MAX;
const CHUNK: usize = 32;

/// Parameters of the aggregation and selection stage (validated by the caller).
#[derive(Clone, Debug)]
pub(crate) struct AggParams {
    pub nd: usize,
    pub dmin: i32,
    pub p1: i16,
    /// `P2'` as a function of `|ΔI|` (0..=255).
    pub p2_lut: [i16; 256],
    pub eight_paths: bool,
    pub uniqueness: u32,
    /// Maximum left-right disagreement in pixels; negative disables the check.
    pub lr_max_diff: i32,
    pub subpixel: bool,
}

/// Aggregates `cost` (`[y][x][d]`) of left image `img`, writes disparities into `out`
/// (`NaN` = invalid). `sum` is a reusable buffer.
pub(crate) fn aggregate_select(cost: &[u8], img: &Plane<u8>, ap: &AggParams, sum: &mut Vec<i16>, out: &mut [f32]) {
    let (w, h, nd) = (img.width, img.height, ap.nd);
    let pp = nd + 2;
    let dirs: &[isize] = if ap.eight_paths { &[0, -1, 1] } else { &[0] };
    let np = dirs.len();
    let row_len = w * nd;
    sum.resize(h * row_len, 0);
    let new_lr = || {
        let mut v = vec![0i16; w * np * pp];
        for px in v.chunks_exact_mut(pp) {
            px[0] = SENT;
            px[pp - 1] = SENT;
        }
        v
    };
    let (mut prev, mut cur) = (new_lr(), new_lr());
    let (mut prev_min, mut cur_min) = (vec![0i16; w * np], vec![0i16; w * np]);
    let mut h_row = vec![0i16; row_len];
    let mut h_bufs = vec![0i16; 2 * pp];
    let mut zero = vec![0i16; pp];
    zero[0] = SENT;
    zero[pp - 1] = SENT;
    let ctx = RowCtx { w, nd, np, dirs, p1: ap.p1, p2_lut: &ap.p2_lut, zero: &zero };

    // Forward sweep: paths from the left, top, top-left, top-right; S is set, not added.
    for y in 0..h {
        let c_row = &cost[y * row_len..(y + 1) * row_len];
        let s_row = &mut sum[y * row_len..(y + 1) * row_len];
        let img_row = img.row(y);
        let img_prev = if y > 0 { Some(img.row(y - 1)) } else { None };
        let (prev_ref, prev_min_ref) = (&prev, &prev_min);
        rayon::join(
            || horizontal(c_row, img_row, &ctx, true, &mut h_row, &mut h_bufs),
            || {
                s_row
                    .par_chunks_mut(CHUNK * nd)
                    .zip(cur.par_chunks_mut(CHUNK * np * pp))
                    .zip(cur_min.par_chunks_mut(CHUNK * np))
                    .enumerate()
                    .for_each(|(ci, ((s, cu), cm))| {
                        let rows = RowsIn { c_row, img_row, img_prev, prev: prev_ref, prev_min: prev_min_ref };
                        vertical_chunk(ci * CHUNK, &rows, &ctx, cu, cm, s, true);
                    });
            },
        );
        add_rows(s_row, &h_row);
        std::mem::swap(&mut prev, &mut cur);
        std::mem::swap(&mut prev_min, &mut cur_min);
    }

    // Backward sweep: paths from the right, bottom, bottom-left, bottom-right, then selection.
    let mut best = vec![0i16; w];
    let mut sub = vec![0f32; w];
    let mut r_cost = vec![0i16; w + nd];
    let mut r_idx = vec![0i16; w + nd];
    let mut rev_buf = vec![0i16; nd];
    for y in (0..h).rev() {
        let c_row = &cost[y * row_len..(y + 1) * row_len];
        let s_row = &mut sum[y * row_len..(y + 1) * row_len];
        let img_row = img.row(y);
        let img_prev = if y + 1 < h { Some(img.row(y + 1)) } else { None };
        let (prev_ref, prev_min_ref) = (&prev, &prev_min);
        rayon::join(
            || horizontal(c_row, img_row, &ctx, false, &mut h_row, &mut h_bufs),
            || {
                s_row
                    .par_chunks_mut(CHUNK * nd)
                    .zip(cur.par_chunks_mut(CHUNK * np * pp))
                    .zip(cur_min.par_chunks_mut(CHUNK * np))
                    .enumerate()
                    .for_each(|(ci, ((s, cu), cm))| {
                        let rows = RowsIn { c_row, img_row, img_prev, prev: prev_ref, prev_min: prev_min_ref };
                        vertical_chunk(ci * CHUNK, &rows, &ctx, cu, cm, s, false);
                    });
            },
        );
        std::mem::swap(&mut prev, &mut cur);
        std::mem::swap(&mut prev_min, &mut cur_min);
        s_row
            .par_chunks_mut(CHUNK * nd)
            .zip(h_row.par_chunks(CHUNK * nd))
            .zip(best.par_chunks_mut(CHUNK))
            .zip(sub.par_chunks_mut(CHUNK))
            .for_each(|(((s, hr), b), sb)| select_chunk(s, hr, nd, ap.uniqueness, ap.subpixel, b, sb));
        let out_row = &mut out[y * w..(y + 1) * w];
        if ap.lr_max_diff >= 0 {
            right_min(s_row, nd, &mut r_cost, &mut r_idx, &mut rev_buf);
        }
        for x in 0..w {
            let b = best[x];
            let xr = x as i64 - ap.dmin as i64 - b as i64;
            let mut ok = b >= 0 && xr >= 0 && xr < w as i64;
            if ok && ap.lr_max_diff >= 0 {
                let j = x + nd - 1 - b as usize;
                ok = (r_idx[j] as i32 - b as i32).abs() <= ap.lr_max_diff;
            }
            out_row[x] = if ok { ap.dmin as f32 + sub[x] } else { f32::NAN };
        }
    }
}

/// Shared read-only context of one row.
struct RowCtx<'a> {
    w: usize,
    nd: usize,
    np: usize,
    dirs: &'a [isize],
    p1: i16,
    p2_lut: &'a [i16; 256],
    zero: &'a [i16],
}

/// Rows a vertical/diagonal chunk reads.
struct RowsIn<'a> {
    c_row: &'a [u8],
    img_row: &'a [u8],
    img_prev: Option<&'a [u8]>,
    prev: &'a [i16],
    prev_min: &'a [i16],
}

/// One path step for one pixel: writes `L_r(p, ·)` into `cur[1..=nd]`, adds (or sets) it
/// into `acc`, returns `min_d L_r(p, d)`. `prev` is padded with sentinels at 0 and nd+1.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn step(c: &[u8], prev: &[i16], prev_min: i16, p1: i16, p2: i16, cur: &mut [i16], acc: &mut [i16], set: bool) -> i16 {
    let n = c.len();
    let (same, lo, hi) = (&prev[1..n + 1], &prev[0..n], &prev[2..n + 2]);
    let cur = &mut cur[1..n + 1];
    let acc = &mut acc[..n];
    let base = prev_min.saturating_add(p2);
    let mut m = SENT;
    if set {
        for d in 0..n {
            let best = same[d].min(lo[d].saturating_add(p1)).min(hi[d].saturating_add(p1)).min(base);
            let v = c[d] as i16 + best - prev_min;
            cur[d] = v;
            acc[d] = v;
            m = m.min(v);
        }
    } else {
        for d in 0..n {
            let best = same[d].min(lo[d].saturating_add(p1)).min(hi[d].saturating_add(p1)).min(base);
            let v = c[d] as i16 + best - prev_min;
            cur[d] = v;
            acc[d] = acc[d].wrapping_add(v);
            m = m.min(v);
        }
    }
    m
}

crate::multiversion! {
    fn vertical_chunk(x0: usize, rows: &RowsIn, ctx: &RowCtx, cur: &mut [i16], cur_min: &mut [i16], s: &mut [i16], set: bool) {
        let (nd, np, pp) = (ctx.nd, ctx.np, ctx.nd + 2);
        let len = s.len() / nd;
        for i in 0..len {
            let x = x0 + i;
            let c = &rows.c_row[x * nd..(x + 1) * nd];
            let acc = &mut s[i * nd..(i + 1) * nd];
            for (k, &dx) in ctx.dirs.iter().enumerate() {
                let xp = x as isize + dx;
                let (pv, pm, p2) = match rows.img_prev {
                    Some(ip) if xp >= 0 && (xp as usize) < ctx.w => {
                        let j = xp as usize * np + k;
                        let di = (rows.img_row[x] as i16 - ip[xp as usize] as i16).unsigned_abs() as usize;
                        (&rows.prev[j * pp..(j + 1) * pp], rows.prev_min[j], ctx.p2_lut[di])
                    }
                    _ => (ctx.zero, 0, ctx.p2_lut[0]),
                };
                let cv = &mut cur[(i * np + k) * pp..(i * np + k + 1) * pp];
                cur_min[i * np + k] = step(c, pv, pm, ctx.p1, p2, cv, acc, set && k == 0);
            }
        }
    }
}

crate::multiversion! {
    fn horizontal(c_row: &[u8], img_row: &[u8], ctx: &RowCtx, left_to_right: bool, out: &mut [i16], bufs: &mut [i16]) {
        let (w, nd, pp) = (ctx.w, ctx.nd, ctx.nd + 2);
        let (mut a, mut b) = bufs.split_at_mut(pp);
        a.copy_from_slice(ctx.zero);
        b[0] = SENT;
        b[pp - 1] = SENT;
        let mut pm = 0i16;
        let mut last = 0usize;
        for i in 0..w {
            let x = if left_to_right { i } else { w - 1 - i };
            let p2 = if i == 0 { ctx.p2_lut[0] } else { ctx.p2_lut[(img_row[x] as i16 - img_row[last] as i16).unsigned_abs() as usize] };
            pm = step(&c_row[x * nd..(x + 1) * nd], a, pm, ctx.p1, p2, b, &mut out[x * nd..(x + 1) * nd], true);
            std::mem::swap(&mut a, &mut b);
            last = x;
        }
    }
}

crate::multiversion! {
    fn add_rows(s: &mut [i16], h: &[i16]) {
        for (a, &b) in s.iter_mut().zip(h) {
            *a = a.wrapping_add(b);
        }
    }
}

crate::multiversion! {
    /// Adds the horizontal path into S and picks the best disparity of each pixel of a chunk.
    fn select_chunk(s: &mut [i16], h: &[i16], nd: usize, uniqueness: u32, subpixel: bool, best: &mut [i16], sub: &mut [f32]) {
        for (i, (sp, hp)) in s.chunks_exact_mut(nd).zip(h.chunks_exact(nd)).enumerate() {
            for (a, &b) in sp.iter_mut().zip(hp) {
                *a = a.wrapping_add(b);
            }
            let sp = &*sp;
            // Arg-min as a vector min over packed keys (cost << 16 | d): the smallest cost wins,
            // ties go to the smallest disparity.
            let key = sp.iter().enumerate().map(|(d, &v)| ((v as i32) << 16) | d as i32).fold(i32::MAX, i32::min);
            let (m, bi) = ((key >> 16) as i16, (key & 0xFFFF) as usize);
            let mut ok = true;
            if uniqueness > 0 {
                let second = sp[..bi.saturating_sub(1)]
                    .iter()
                    .chain(sp.get(bi + 2..).unwrap_or(&[]))
                    .copied()
                    .fold(i16::MAX, i16::min);
                ok = (second as i64) * (100 - uniqueness as i64) >= (m as i64) * 100;
            }
            best[i] = if ok { bi as i16 } else { -1 };
            let mut d = bi as f32;
            if subpixel && bi > 0 && bi + 1 < nd {
                let (l, c, r) = (sp[bi - 1] as f32, m as f32, sp[bi + 1] as f32);
                let denom = l + r - 2.0 * c;
                if denom > 0.0 {
                    d += (l - r) / (2.0 * denom);
                }
            }
            sub[i] = d;
        }
    }
}

crate::multiversion! {
    /// Right-image winners from the left cost row: `r_idx[x + nd - 1 - d]` holds the `d`
    /// minimising `S(x_r + dmin + d, d)` over left pixels, for the right pixel `x_r = x - dmin - d`.
    fn right_min(s_row: &[i16], nd: usize, r_cost: &mut [i16], r_idx: &mut [i16], rev: &mut [i16]) {
        r_cost.fill(i16::MAX);
        r_idx.fill(-1);
        let rev = &mut rev[..nd];
        let desc: Vec<i16> = (0..nd as i16).rev().collect();
        for (x, sp) in s_row.chunks_exact(nd).enumerate() {
            // Reverse the pixel's costs so the window update is a straight vector blend.
            for (r, &v) in rev.iter_mut().zip(sp.iter().rev()) {
                *r = v;
            }
            let wc = &mut r_cost[x..x + nd];
            let wi = &mut r_idx[x..x + nd];
            for (((c, i), &v), &d) in wc.iter_mut().zip(wi.iter_mut()).zip(rev.iter()).zip(&desc) {
                // Branch-free select so the loop vectorizes (min + bit blend).
                let (oc, oi) = (*c, *i);
                let m = ((v < oc) as i16).wrapping_neg();
                *c = oc.min(v);
                *i = (d & m) | (oi & !m);
            }
        }
    }
}
