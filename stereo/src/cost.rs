//! Pixel-wise matching costs `C(x, y, d)`, `u8`, one row at a time laid out `[x][d]`
//! (contiguous over d).
//!
//! `C = census_weight · popcount(cL(x) ^ cR(x - dmin - d)) + grad_weight · min(|gL(x) - gR(x - dmin - d)|, grad_trunc)`
//! where `c` are census signatures and `g` horizontal Sobel gradients divided by 4. Candidates
//! whose right pixel falls outside the image get `border_cost`.

use rayon::prelude::*;
use tubeloc_core::Plane;

/// Horizontal Sobel gradient divided by 4 (range -255..=255), border replicated.
pub(crate) fn sobel_x(img: &Plane<u8>) -> Plane<i16> {
    let (w, h) = (img.width, img.height);
    let mut out = Plane::<i16>::new(w, h);
    out.data.par_chunks_mut(w).enumerate().for_each(|(y, orow)| {
        let r0 = img.row(y.saturating_sub(1));
        let r1 = img.row(y);
        let r2 = img.row((y + 1).min(h - 1));
        for (x, o) in orow.iter_mut().enumerate() {
            let (xl, xr) = (x.saturating_sub(1), (x + 1).min(w - 1));
            let g = |r: &[u8]| r[xr] as i32 - r[xl] as i32;
            *o = ((g(r0) + 2 * g(r1) + g(r2)) / 4) as i16;
        }
    });
    out
}

/// Weights of the cost terms.
#[derive(Clone, Copy, Debug)]
pub(crate) struct CostWeights {
    pub census: u8,
    pub grad: u8,
    pub grad_trunc: u8,
    pub border: u8,
}

/// Fills `out` (`h * w * nd`) with the cost volume of census planes `cl`, `cr` and optional
/// gradient planes.
#[cfg(test)]
pub(crate) fn cost_volume(cl: &Plane<u64>, cr: &Plane<u64>, grads: Option<(&Plane<i16>, &Plane<i16>)>, dmin: i32, nd: usize, wt: CostWeights, out: &mut [u8]) {
    let w = cl.width;
    let mut cr_rev = cr.clone();
    reverse_rows(&mut cr_rev);
    out.par_chunks_mut(w * nd).enumerate().for_each(|(y, orow)| cost_row(y, cl, &cr_rev, grads, dmin, nd, wt, orow));
}

/// Reverses every row in place (the right census plane is stored this way, so that the
/// candidates of a left pixel, right pixels `x - dmin - d` for increasing `d`, are contiguous
/// and ascending in memory).
pub(crate) fn reverse_rows(p: &mut Plane<u64>) {
    let w = p.width.max(1);
    p.data.par_chunks_mut(w).for_each(|r| r.reverse());
}

crate::multiversion! {
/// Fills `orow` (`w * nd`, `[x][d]`) with the costs of row `y` (see the module doc); `cr_rev` is
/// the right census plane with reversed rows ([`reverse_rows`]).
pub(crate) fn cost_row(y: usize, cl: &Plane<u64>, cr_rev: &Plane<u64>, grads: Option<(&Plane<i16>, &Plane<i16>)>, dmin: i32, nd: usize, wt: CostWeights, orow: &mut [u8]) {
    let w = cl.width;
    let (lr, rr) = (cl.row(y), cr_rev.row(y));
    let g = grads.map(|(gl, gr)| (gl.row(y), gr.row(y)));
    for x in 0..w {
        let o = &mut orow[x * nd..(x + 1) * nd];
        // Valid candidates: 0 <= x - dmin - d <= w - 1.
        let hi = (x as i64 - dmin as i64).min(nd as i64 - 1);
        let lo = (x as i64 - dmin as i64 - (w as i64 - 1)).max(0);
        if hi < lo {
            o.fill(wt.border);
            continue;
        }
        let (lo, hi) = (lo as usize, hi as usize);
        o[..lo].fill(wt.border);
        o[hi + 1..].fill(wt.border);
        // Right pixels x - dmin - d for d in lo..=hi: reversed-row indices w-1-xr_hi..=w-1-xr_lo.
        let xr_hi = (x as i64 - dmin as i64 - lo as i64) as usize;
        let xr_lo = (x as i64 - dmin as i64 - hi as i64) as usize;
        let win = &rr[w - 1 - xr_hi..=w - 1 - xr_lo];
        census_row(&mut o[lo..=hi], lr[x], win, wt.census);
        if let Some((gl, gr)) = g {
            grad_row(&mut o[lo..=hi], gl[x], &gr[xr_lo..=xr_hi], wt.grad, wt.grad_trunc);
        }
    }
}
}

#[inline(always)]
fn census_row(o: &mut [u8], l: u64, win: &[u64], weight: u8) {
    // o[k] pairs with win[k].
    if weight == 1 {
        for (c, &r) in o.iter_mut().zip(win) {
            *c = (l ^ r).count_ones() as u8;
        }
    } else {
        for (c, &r) in o.iter_mut().zip(win) {
            *c = ((l ^ r).count_ones() as u8).saturating_mul(weight);
        }
    }
}

#[inline(always)]
fn grad_row(o: &mut [u8], l: i16, win: &[i16], weight: u8, trunc: u8) {
    for (c, &r) in o.iter_mut().zip(win.iter().rev()) {
        let diff = (l - r).unsigned_abs().min(trunc as u16) as u8;
        *c = c.saturating_add(diff.saturating_mul(weight));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cost_is_hamming_distance_and_border_outside() {
        let cl = Plane::from_vec(4, 1, vec![0b1111u64, 0, 0b1, 0b11]);
        let cr = Plane::from_vec(4, 1, vec![0u64, 0b1, 0b111, 0]);
        let wt = CostWeights { census: 2, grad: 0, grad_trunc: 0, border: 99 };
        let mut out = vec![0u8; 4 * 3];
        cost_volume(&cl, &cr, None, 0, 3, wt, &mut out);
        // x = 3, l = 0b11: d=0 -> cr[3]=0 (2 bits), d=1 -> cr[2]=0b111 (1 bit), d=2 -> cr[1]=0b1 (1 bit)
        assert_eq!(&out[9..12], &[4, 2, 2]);
        // x = 0: only d = 0 valid.
        assert_eq!(&out[0..3], &[8, 99, 99]);
    }
}
