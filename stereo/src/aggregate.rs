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
//! and `S(p, d) = Σ_r L_r(p, d)`. `0 <= L_r <= C_max + P2`: path costs are kept in `u8` when
//! `C_max + max P2' <= 255` (64 lanes per AVX-512 vector; the defaults qualify), otherwise in
//! `i16`; `S` is `i16` and fits when `8 (C_max + P2) < 32768`.
//!
//! Order of work (two threads, no cost volume, every `S` value written once and read once):
//! a *forward* sweep runs rows top to bottom and, within a row, pixels left to right, computing
//! the paths from the left, top-left, top and top-right in one fused pass over the disparities;
//! a *backward* sweep runs bottom to top, right to left, with the four opposite paths. Each
//! sweep computes its row of matching costs on the fly. Phase 1: the forward sweep stores its
//! partial `S` for the top half of the image while the backward sweep stores its partial `S`
//! for the bottom half. Phase 2: each sweep continues into the other half, adds its paths to
//! the stored partial sums and, as each row of `S` is complete, selects disparities there.
//! Path state lives in two row buffers per sweep (previous and current row, swapped).

use tubeloc_core::Plane;

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
    /// Keep path costs in `u8` (requires `C_max + max P2' <= 255`).
    pub narrow: bool,
}

/// Element type of the path costs `L_r` (`u8` or `i16`); arithmetic is exact in the ranges
/// the callers guarantee (wrapping where an intermediate may leave the range).
pub(crate) trait Lane: Copy + Ord + Default + Send + Sync + 'static {
    /// Larger than any path cost: padding at `d = -1` and `d = D`.
    const SENT: Self;
    fn from_cost(c: u8) -> Self;
    fn from_i16(v: i16) -> Self;
    fn sat_add(self, o: Self) -> Self;
    fn wadd(self, o: Self) -> Self;
    fn wsub(self, o: Self) -> Self;
    fn widen(self) -> i16;
}

impl Lane for i16 {
    const SENT: i16 = i16::MAX;
    #[inline(always)]
    fn from_cost(c: u8) -> i16 {
        c as i16
    }
    #[inline(always)]
    fn from_i16(v: i16) -> i16 {
        v
    }
    #[inline(always)]
    fn sat_add(self, o: i16) -> i16 {
        self.saturating_add(o)
    }
    #[inline(always)]
    fn wadd(self, o: i16) -> i16 {
        self.wrapping_add(o)
    }
    #[inline(always)]
    fn wsub(self, o: i16) -> i16 {
        self.wrapping_sub(o)
    }
    #[inline(always)]
    fn widen(self) -> i16 {
        self
    }
}

impl Lane for u8 {
    const SENT: u8 = u8::MAX;
    #[inline(always)]
    fn from_cost(c: u8) -> u8 {
        c
    }
    #[inline(always)]
    fn from_i16(v: i16) -> u8 {
        v.clamp(0, 255) as u8
    }
    #[inline(always)]
    fn sat_add(self, o: u8) -> u8 {
        self.saturating_add(o)
    }
    #[inline(always)]
    fn wadd(self, o: u8) -> u8 {
        self.wrapping_add(o)
    }
    #[inline(always)]
    fn wsub(self, o: u8) -> u8 {
        self.wrapping_sub(o)
    }
    #[inline(always)]
    fn widen(self) -> i16 {
        self as i16
    }
}

/// Path state of one sweep in lane type `T`: `L_r` of the previous and current row
/// (`[x][path][1 + d + 1]`, sentinels at both ends), their minima `[x][path]`, and the
/// horizontal path's previous/current pixel (ping-pong halves).
#[derive(Default)]
pub(crate) struct PathState<T> {
    vert: Vec<T>,
    vcur: Vec<T>,
    vmin: Vec<T>,
    vcur_min: Vec<T>,
    hbuf: Vec<T>,
    zero: Vec<T>,
}

impl<T: Lane> PathState<T> {
    fn reset(&mut self, w: usize, nd: usize, np: usize) {
        let pp = nd + 2;
        let padded = |v: &mut Vec<T>, n: usize| {
            v.clear();
            v.resize(n * pp, T::default());
            for px in v.chunks_exact_mut(pp) {
                px[0] = T::SENT;
                px[pp - 1] = T::SENT;
            }
        };
        padded(&mut self.vert, w * np);
        padded(&mut self.vcur, w * np);
        padded(&mut self.hbuf, 2);
        padded(&mut self.zero, 1);
        for v in [&mut self.vmin, &mut self.vcur_min] {
            v.clear();
            v.resize(w * np, T::default());
        }
    }
}

/// Reusable buffers: the partial-sum volume `S` (`W·H·D` i16) and the two sweeps' row state.
#[derive(Default)]
pub(crate) struct AggBuffers {
    sum: Vec<i16>,
    fwd: Sweep,
    bwd: Sweep,
}

/// State of one sweep direction (one thread): the cost row, the previous row's `L_r` for the
/// vertical and diagonal paths, the horizontal path's previous pixel, and selection scratch.
#[derive(Default)]
pub(crate) struct Sweep {
    /// Matching costs of the current row, `[x][d]`.
    pub cost: Vec<u8>,
    /// Path state when `L_r` is kept in `i16`.
    wide: PathState<i16>,
    /// Path state when `L_r` is kept in `u8`.
    narrow: PathState<u8>,
    best: Vec<i16>,
    sub: Vec<f32>,
    r_cost: Vec<i16>,
    r_idx: Vec<i16>,
    rev: Vec<i16>,
    desc: Vec<i16>,
}

impl Sweep {
    fn reset(&mut self, w: usize, nd: usize, np: usize, narrow: bool) {
        self.cost.resize(w * nd, 0);
        if narrow {
            self.narrow.reset(w, nd, np);
        } else {
            self.wide.reset(w, nd, np);
        }
        self.best.resize(w, 0);
        self.sub.resize(w, 0.0);
        self.r_cost.resize(w + nd, 0);
        self.r_idx.resize(w + nd, 0);
        self.rev.resize(nd, 0);
        self.desc.clear();
        self.desc.extend((0..nd as i16).rev());
    }
}

/// Shared read-only context of the sweeps.
pub(crate) struct Ctx<'a> {
    w: usize,
    nd: usize,
    eight: bool,
    p1: i16,
    p2_lut: &'a [i16; 256],
}

/// Aggregates the costs that `fill_cost(y, row)` writes (`row[x * nd + d]`), selects
/// disparities of left image `img` into `out` (`NaN` = invalid).
pub(crate) fn aggregate_select<F>(img: &Plane<u8>, ap: &AggParams, bufs: &mut AggBuffers, out: &mut [f32], fill_cost: F)
where
    F: Fn(usize, &mut [u8]) + Sync,
{
    let w = img.width;
    sweep_all(img, ap, bufs, out, w, fill_cost, |sw, s_row, out_row| select_row(sw, ap, w, s_row, out_row));
}

/// Runs both sweeps; `finish(sweep, S_row, out_row)` is called once per row with its complete
/// `S` (`out` has `out_stride` values per row).
fn sweep_all<T, F, G>(img: &Plane<u8>, ap: &AggParams, bufs: &mut AggBuffers, out: &mut [T], out_stride: usize, fill_cost: F, finish: G)
where
    T: Send,
    F: Fn(usize, &mut [u8]) + Sync,
    G: Fn(&mut Sweep, &[i16], &mut [T]) + Sync,
{
    let (w, h, nd) = (img.width, img.height, ap.nd);
    let np = if ap.eight_paths { 3 } else { 1 };
    let row_len = w * nd;
    bufs.sum.resize(h * row_len, 0);
    bufs.fwd.reset(w, nd, np, ap.narrow);
    bufs.bwd.reset(w, nd, np, ap.narrow);
    let ctx = Ctx { w, nd, eight: ap.eight_paths, p1: ap.p1, p2_lut: &ap.p2_lut };
    let mid = h / 2;
    let (s_top, s_bot) = bufs.sum.split_at_mut(mid * row_len);
    let (o_top, o_bot) = out.split_at_mut(mid * out_stride);
    let (fwd, bwd) = (&mut bufs.fwd, &mut bufs.bwd);
    let prev_row = |y: usize| if y > 0 { Some(img.row(y - 1)) } else { None };
    let next_row = |y: usize| if y + 1 < h { Some(img.row(y + 1)) } else { None };
    // Phase 1: partial sums of the forward paths (top half), backward paths (bottom half).
    rayon::join(
        || {
            for (y, s) in s_top.chunks_exact_mut(row_len).enumerate() {
                fill_cost(y, &mut fwd.cost);
                sweep_row(fwd, &ctx, ap.narrow, img.row(y), prev_row(y), s, true, true);
            }
        },
        || {
            for (i, s) in s_bot.chunks_exact_mut(row_len).enumerate().rev() {
                let y = mid + i;
                fill_cost(y, &mut bwd.cost);
                sweep_row(bwd, &ctx, ap.narrow, img.row(y), next_row(y), s, true, false);
            }
        },
    );
    // Phase 2: each sweep completes the other half's sums and selects.
    rayon::join(
        || {
            for (i, (s, o)) in s_bot.chunks_exact_mut(row_len).zip(o_bot.chunks_exact_mut(out_stride)).enumerate() {
                let y = mid + i;
                fill_cost(y, &mut fwd.cost);
                sweep_row(fwd, &ctx, ap.narrow, img.row(y), prev_row(y), s, false, true);
                finish(fwd, s, o);
            }
        },
        || {
            for (y, (s, o)) in s_top.chunks_exact_mut(row_len).zip(o_top.chunks_exact_mut(out_stride)).enumerate().rev() {
                fill_cost(y, &mut bwd.cost);
                sweep_row(bwd, &ctx, ap.narrow, img.row(y), next_row(y), s, false, false);
                finish(bwd, s, o);
            }
        },
    );
}

/// Pixels ahead for which the stored partial sums are prefetched.
const PREFETCH: usize = 6;

/// Hints the CPU to load `v` into cache (no effect on other architectures).
#[inline(always)]
fn prefetch(v: &[i16]) {
    #[cfg(target_arch = "x86_64")]
    for line in v.chunks(32) {
        // SAFETY: prefetching is a hint; the address lies inside a live slice.
        #[allow(unused_unsafe)]
        unsafe {
            std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(line.as_ptr() as *const i8)
        };
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = v;
}

#[inline(always)]
fn absdiff(a: u8, b: u8) -> usize {
    a.abs_diff(b) as usize
}

/// `L_r(p, d)` from the previous pixel's `same = L(d)`, `lo = L(d-1)`, `hi = L(d+1)`;
/// `base = min_k L + P2'`, `pm = min_k L`.
#[inline(always)]
fn lr<T: Lane>(c: u8, same: T, lo: T, hi: T, p1: T, base: T, pm: T) -> T {
    T::from_cost(c).wadd(same.min(lo.sat_add(p1)).min(hi.sat_add(p1)).min(base)).wsub(pm)
}

/// One pixel, two paths (horizontal and vertical): writes `L` into `o[k][1..=nd]`, sets or adds
/// their sum into `s`, returns each path's `min_d L`.
#[inline(always)]
fn pixel2<T: Lane, const SET: bool>(c: &[u8], p: [&[T]; 2], pm: [T; 2], p2: [T; 2], p1: T, o: [&mut [T]; 2], s: &mut [i16]) -> [T; 2] {
    let n = c.len();
    let [o0, o1] = o;
    let (o0, o1) = (&mut o0[1..n + 1], &mut o1[1..n + 1]);
    let (a0, a1, a2) = (&p[0][0..n], &p[0][1..n + 1], &p[0][2..n + 2]);
    let (b0, b1, b2) = (&p[1][0..n], &p[1][1..n + 1], &p[1][2..n + 2]);
    let (ba, bb) = (pm[0].sat_add(p2[0]), pm[1].sat_add(p2[1]));
    let s = &mut s[..n];
    let (mut ma, mut mb) = (T::SENT, T::SENT);
    for d in 0..n {
        let va = lr(c[d], a1[d], a0[d], a2[d], p1, ba, pm[0]);
        let vb = lr(c[d], b1[d], b0[d], b2[d], p1, bb, pm[1]);
        o0[d] = va;
        o1[d] = vb;
        ma = ma.min(va);
        mb = mb.min(vb);
        let t = va.widen().wrapping_add(vb.widen());
        s[d] = if SET { t } else { s[d].wrapping_add(t) };
    }
    [ma, mb]
}

/// One pixel, four paths (horizontal, vertical, two diagonals); as [`pixel2`].
#[inline(always)]
fn pixel4<T: Lane, const SET: bool>(c: &[u8], p: [&[T]; 4], pm: [T; 4], p2: [T; 4], p1: T, o: [&mut [T]; 4], s: &mut [i16]) -> [T; 4] {
    let n = c.len();
    let [o0, o1, o2, o3] = o;
    let (o0, o1, o2, o3) = (&mut o0[1..n + 1], &mut o1[1..n + 1], &mut o2[1..n + 1], &mut o3[1..n + 1]);
    let (a0, a1, a2) = (&p[0][0..n], &p[0][1..n + 1], &p[0][2..n + 2]);
    let (b0, b1, b2) = (&p[1][0..n], &p[1][1..n + 1], &p[1][2..n + 2]);
    let (c0, c1, c2) = (&p[2][0..n], &p[2][1..n + 1], &p[2][2..n + 2]);
    let (e0, e1, e2) = (&p[3][0..n], &p[3][1..n + 1], &p[3][2..n + 2]);
    let base = [pm[0].sat_add(p2[0]), pm[1].sat_add(p2[1]), pm[2].sat_add(p2[2]), pm[3].sat_add(p2[3])];
    let s = &mut s[..n];
    let (mut ma, mut mb, mut mc, mut me) = (T::SENT, T::SENT, T::SENT, T::SENT);
    for d in 0..n {
        let va = lr(c[d], a1[d], a0[d], a2[d], p1, base[0], pm[0]);
        let vb = lr(c[d], b1[d], b0[d], b2[d], p1, base[1], pm[1]);
        let vc = lr(c[d], c1[d], c0[d], c2[d], p1, base[2], pm[2]);
        let ve = lr(c[d], e1[d], e0[d], e2[d], p1, base[3], pm[3]);
        o0[d] = va;
        o1[d] = vb;
        o2[d] = vc;
        o3[d] = ve;
        ma = ma.min(va);
        mb = mb.min(vb);
        mc = mc.min(vc);
        me = me.min(ve);
        let t = va.widen().wrapping_add(vb.widen()).wrapping_add(vc.widen()).wrapping_add(ve.widen());
        s[d] = if SET { t } else { s[d].wrapping_add(t) };
    }
    [ma, mb, mc, me]
}

crate::multiversion! {
    fn sweep_row_wide(st: &mut PathState<i16>, cost: &[u8], ctx: &Ctx, img_row: &[u8], img_prev: Option<&[u8]>, s_row: &mut [i16], set: bool, forward: bool) {
        sweep_row_impl(st, cost, ctx, img_row, img_prev, s_row, set, forward)
    }
}

crate::multiversion! {
    fn sweep_row_narrow(st: &mut PathState<u8>, cost: &[u8], ctx: &Ctx, img_row: &[u8], img_prev: Option<&[u8]>, s_row: &mut [i16], set: bool, forward: bool) {
        sweep_row_impl(st, cost, ctx, img_row, img_prev, s_row, set, forward)
    }
}

/// One row of one sweep: updates the path state and sets (`set`) or adds the row's path sum
/// into `s_row`. `forward`: pixels left to right, predecessor row `img_prev` above;
/// otherwise right to left with the row below.
#[allow(clippy::too_many_arguments)]
fn sweep_row(sw: &mut Sweep, ctx: &Ctx, narrow: bool, img_row: &[u8], img_prev: Option<&[u8]>, s_row: &mut [i16], set: bool, forward: bool) {
    if narrow {
        sweep_row_narrow(&mut sw.narrow, &sw.cost, ctx, img_row, img_prev, s_row, set, forward);
    } else {
        sweep_row_wide(&mut sw.wide, &sw.cost, ctx, img_row, img_prev, s_row, set, forward);
    }
}

#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn sweep_row_impl<T: Lane>(st: &mut PathState<T>, cost: &[u8], ctx: &Ctx, img_row: &[u8], img_prev: Option<&[u8]>, s_row: &mut [i16], set: bool, forward: bool) {
    let (w, nd) = (ctx.w, ctx.nd);
    let pp = nd + 2;
    let mut lut = [T::default(); 256];
    for (l, &v) in lut.iter_mut().zip(ctx.p2_lut.iter()) {
        *l = T::from_i16(v);
    }
    let p1 = T::from_i16(ctx.p1);
    let PathState { vert, vcur, vmin, vcur_min, hbuf, zero } = st;
    let zero = &zero[..];
    let (prev, prev_min) = (&vert[..], &vmin[..]);
    let mut hmin = T::default();
    for i in 0..w {
        let x = if forward { i } else { w - 1 - i };
        // Visited-side and unvisited-side neighbours (valid when i > 0, resp. i + 1 < w).
        let xv = if forward { x.wrapping_sub(1) } else { x + 1 };
        let xu = if forward { x + 1 } else { x.wrapping_sub(1) };
        if !set && i + PREFETCH < w {
            // The stored partial sums come from memory: fetch a few pixels ahead.
            let xa = if forward { x + PREFETCH } else { x - PREFETCH };
            prefetch(&s_row[xa * nd..(xa + 1) * nd]);
        }
        let c = &cost[x * nd..(x + 1) * nd];
        let s = &mut s_row[x * nd..(x + 1) * nd];
        let (ha, hb) = hbuf.split_at_mut(pp);
        let (hp, ho) = if i % 2 == 0 { (&*hb, ha) } else { (&*ha, hb) };
        let z = (zero, T::default(), lut[0]);
        let (ph, pmh, p2h) = if i == 0 { z } else { (hp, hmin, lut[absdiff(img_row[x], img_row[xv])]) };
        if !ctx.eight {
            let (pv, pmv, p2v) = match img_prev {
                Some(ip) => (&prev[x * pp..(x + 1) * pp], prev_min[x], lut[absdiff(img_row[x], ip[x])]),
                None => z,
            };
            let ov = &mut vcur[x * pp..(x + 1) * pp];
            let m = if set { pixel2::<T, true>(c, [ph, pv], [pmh, pmv], [p2h, p2v], p1, [ho, ov], s) } else { pixel2::<T, false>(c, [ph, pv], [pmh, pmv], [p2h, p2v], p1, [ho, ov], s) };
            hmin = m[0];
            vcur_min[x] = m[1];
            continue;
        }
        // Paths: 0 straight (x), 1 visited-side diagonal (xv), 2 unvisited-side diagonal (xu).
        let (k0, k1, k2) = (x * 3, xv.wrapping_mul(3).wrapping_add(1), xu.wrapping_mul(3).wrapping_add(2));
        let (q0, q1, q2) = match img_prev {
            Some(ip) => {
                let a = (&prev[k0 * pp..(k0 + 1) * pp], prev_min[k0], lut[absdiff(img_row[x], ip[x])]);
                let b = if i > 0 { (&prev[k1 * pp..(k1 + 1) * pp], prev_min[k1], lut[absdiff(img_row[x], ip[xv])]) } else { z };
                let c = if i + 1 < w { (&prev[k2 * pp..(k2 + 1) * pp], prev_min[k2], lut[absdiff(img_row[x], ip[xu])]) } else { z };
                (a, b, c)
            }
            None => (z, z, z),
        };
        let (oa, r) = vcur[k0 * pp..(k0 + 3) * pp].split_at_mut(pp);
        let (ob, oc) = r.split_at_mut(pp);
        let args = ([ph, q0.0, q1.0, q2.0], [pmh, q0.1, q1.1, q2.1], [p2h, q0.2, q1.2, q2.2], [ho, oa, ob, oc]);
        let m = if set { pixel4::<T, true>(c, args.0, args.1, args.2, p1, args.3, s) } else { pixel4::<T, false>(c, args.0, args.1, args.2, p1, args.3, s) };
        hmin = m[0];
        vcur_min[k0..k0 + 3].copy_from_slice(&m[1..4]);
    }
    std::mem::swap(vert, vcur);
    std::mem::swap(vmin, vcur_min);
}

/// Winner-takes-all, uniqueness, sub-pixel and left-right check of one complete row of `S`.
fn select_row(sw: &mut Sweep, ap: &AggParams, w: usize, s_row: &[i16], out_row: &mut [f32]) {
    let nd = ap.nd;
    select_kernel(s_row, nd, ap.uniqueness, ap.subpixel, &mut sw.best, &mut sw.sub);
    if ap.lr_max_diff >= 0 {
        right_min(s_row, nd, &mut sw.r_cost, &mut sw.r_idx, &mut sw.rev, &sw.desc);
    }
    for (x, out) in out_row[..w].iter_mut().enumerate() {
        let b = sw.best[x];
        let xr = x as i64 - ap.dmin as i64 - b as i64;
        let mut ok = b >= 0 && xr >= 0 && xr < w as i64;
        if ok && ap.lr_max_diff >= 0 {
            let j = x + nd - 1 - b as usize;
            ok = (sw.r_idx[j] as i32 - b as i32).abs() <= ap.lr_max_diff;
        }
        *out = if ok { ap.dmin as f32 + sw.sub[x] } else { f32::NAN };
    }
}

crate::multiversion! {
    /// Picks the best disparity of each pixel of a row of `S`.
    fn select_kernel(s: &[i16], nd: usize, uniqueness: u32, subpixel: bool, best: &mut [i16], sub: &mut [f32]) {
        for (i, sp) in s.chunks_exact(nd).enumerate() {
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
    fn right_min(s_row: &[i16], nd: usize, r_cost: &mut [i16], r_idx: &mut [i16], rev: &mut [i16], desc: &[i16]) {
        r_cost.fill(i16::MAX);
        r_idx.fill(-1);
        let rev = &mut rev[..nd];
        for (x, sp) in s_row.chunks_exact(nd).enumerate() {
            // Reverse the pixel's costs so the window update is a straight vector blend.
            for (r, &v) in rev.iter_mut().zip(sp.iter().rev()) {
                *r = v;
            }
            let wc = &mut r_cost[x..x + nd];
            let wi = &mut r_idx[x..x + nd];
            for (((c, i), &v), &d) in wc.iter_mut().zip(wi.iter_mut()).zip(rev.iter()).zip(desc) {
                // Branch-free select so the loop vectorizes (min + bit blend).
                let (oc, oi) = (*c, *i);
                let m = ((v < oc) as i16).wrapping_neg();
                *c = oc.min(v);
                *i = (d & m) | (oi & !m);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Textbook SGM sums `S(p, d)` in `i32`, one path direction at a time.
    fn reference_sum(cost: &[u8], img: &Plane<u8>, nd: usize, p1: i32, lut: &[i16; 256], eight: bool) -> Vec<i32> {
        let (w, h) = (img.width as i64, img.height as i64);
        let mut dirs = vec![(1i64, 0i64), (-1, 0), (0, 1), (0, -1)];
        if eight {
            dirs.extend([(1, 1), (-1, 1), (1, -1), (-1, -1)]);
        }
        let mut sum = vec![0i32; cost.len()];
        for (dx, dy) in dirs {
            let mut l = vec![0i32; cost.len()];
            let ys: Vec<i64> = if dy < 0 { (0..h).rev().collect() } else { (0..h).collect() };
            let xs: Vec<i64> = if dx < 0 { (0..w).rev().collect() } else { (0..w).collect() };
            for &y in &ys {
                for &x in &xs {
                    let at = ((y * w + x) as usize) * nd;
                    let (qx, qy) = (x - dx, y - dy);
                    if qx < 0 || qy < 0 || qx >= w || qy >= h {
                        for d in 0..nd {
                            l[at + d] = cost[at + d] as i32;
                        }
                        continue;
                    }
                    let qa = ((qy * w + qx) as usize) * nd;
                    let prev = l[qa..qa + nd].to_vec();
                    let pm = *prev.iter().min().unwrap();
                    let di = (img.get(x as usize, y as usize) as i32 - img.get(qx as usize, qy as usize) as i32).unsigned_abs() as usize;
                    let p2 = lut[di] as i32;
                    for d in 0..nd {
                        let mut best = prev[d].min(pm + p2);
                        if d > 0 {
                            best = best.min(prev[d - 1] + p1);
                        }
                        if d + 1 < nd {
                            best = best.min(prev[d + 1] + p1);
                        }
                        l[at + d] = cost[at + d] as i32 + best - pm;
                    }
                }
            }
            for (s, v) in sum.iter_mut().zip(&l) {
                *s += v;
            }
        }
        sum
    }

    fn params(nd: usize, eight: bool, narrow: bool) -> AggParams {
        let mut p2_lut = [0i16; 256];
        for (di, v) in p2_lut.iter_mut().enumerate() {
            *v = ((150.0 / (1.0 + di as f32 / 12.0)).round() as i16).max(9);
        }
        AggParams { nd, dmin: 0, p1: 9, p2_lut, eight_paths: eight, uniqueness: 0, lr_max_diff: -1, subpixel: false, narrow }
    }

    #[test]
    fn fused_sweeps_equal_textbook_sums_in_both_lane_types() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let (w, h, nd) = (29usize, 13usize, 32usize);
        let img = Plane::from_vec(w, h, (0..w * h).map(|_| rng.random_range(0..=255u8)).collect());
        let cost: Vec<u8> = (0..w * h * nd).map(|_| rng.random_range(0..=100u8)).collect();
        for eight in [true, false] {
            for narrow in [true, false] {
                let ap = params(nd, eight, narrow);
                let want = reference_sum(&cost, &img, nd, ap.p1 as i32, &ap.p2_lut, eight);
                let mut got = vec![0i32; w * h * nd];
                let mut bufs = AggBuffers::default();
                let fill = |y: usize, row: &mut [u8]| row.copy_from_slice(&cost[y * w * nd..(y + 1) * w * nd]);
                sweep_all(&img, &ap, &mut bufs, &mut got, w * nd, fill, |_, s, o| {
                    for (a, &b) in o.iter_mut().zip(s) {
                        *a = b as i32;
                    }
                });
                let bad = got.iter().zip(&want).filter(|(a, b)| a != b).count();
                assert_eq!(bad, 0, "eight={eight} narrow={narrow}: {bad} of {} sums differ", got.len());
            }
        }
    }

    #[test]
    fn selection_picks_the_textbook_winner() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let (w, h, nd) = (40usize, 9usize, 16usize);
        let img = Plane::from_vec(w, h, (0..w * h).map(|_| rng.random_range(0..=255u8)).collect());
        let cost: Vec<u8> = (0..w * h * nd).map(|_| rng.random_range(0..=60u8)).collect();
        let ap = params(nd, true, true);
        let want = reference_sum(&cost, &img, nd, ap.p1 as i32, &ap.p2_lut, true);
        let mut out = vec![0f32; w * h];
        let fill = |y: usize, row: &mut [u8]| row.copy_from_slice(&cost[y * w * nd..(y + 1) * w * nd]);
        aggregate_select(&img, &ap, &mut AggBuffers::default(), &mut out, fill);
        for (i, &o) in out.iter().enumerate() {
            let s = &want[i * nd..(i + 1) * nd];
            let best = (0..nd).min_by_key(|&d| (s[d], d)).unwrap();
            if best > i % w {
                assert!(o.is_nan(), "pixel {i}: match outside the right image must be invalid");
            } else {
                assert_eq!(o, best as f32, "pixel {i}");
            }
        }
    }
}
