//! Spreading, response maps and linearized memories (Hinterstoisser et al. 2012, section 3).
//!
//! - Spreading over `T`: `J(x) = OR_{d ∈ [-T/2, T - T/2)²} Q(x + d)`, where `Q` is the one-hot
//!   orientation bitmask of [`crate::line2d::gradient`]. It is separable (OR along rows, then
//!   along columns).
//! - Similarity of orientations `o` and `b` (bins of 22.5 degrees modulo 180):
//!   `s(o, b) = floor(4 |cos((o - b) 22.5°)|)`, i.e. 4, 3, 2, 1, 0 for a bin distance 0..4.
//! - Response maps: `S_o(x) = max_{b ∈ J(x)} s(o, b)` (0 for an empty mask), computed with two
//!   16-entry lookup tables per orientation, one for each 4-bit half of `J(x)`:
//!   `S_o = max(LUT_lo[o][J & 15], LUT_hi[o][J >> 4])` (one `pshufb` per half with SIMD).
//! - Linearized memories: for a grid step `T`, `L_o[dy][dx][r W/T + c] = S_o((r T + dy) W + c T + dx)`,
//!   so a feature at `(fx, fy)` contributes to all grid positions with one contiguous slice of
//!   `L_o[fy mod T][fx mod T]` starting at `(fy / T) W/T + fx / T`.

use crate::line2d::{N_ORI, SIM_MAX};
use rayon::prelude::*;
use tubeloc_core::Plane;

/// `s(o, b) = floor(4 |cos((o - b) · 22.5°)|)`.
#[inline]
pub fn similarity(o: u8, b: u8) -> u8 {
    let d = (o as i32 - b as i32).rem_euclid(N_ORI as i32);
    let d = d.min(N_ORI as i32 - d);
    [4u8, 3, 2, 1, 0][d as usize]
}

/// The two 16-entry lookup tables per orientation: `lo[o][m] = max_{b in m} s(o, b)` for bins
/// 0..4 and `hi[o][m]` for bins 4..8.
pub fn lut_halves() -> ([[u8; 16]; N_ORI], [[u8; 16]; N_ORI]) {
    let mut lo = [[0u8; 16]; N_ORI];
    let mut hi = [[0u8; 16]; N_ORI];
    for o in 0..N_ORI {
        for m in 0..16usize {
            for b in 0..4 {
                if m & (1 << b) != 0 {
                    lo[o][m] = lo[o][m].max(similarity(o as u8, b as u8));
                    hi[o][m] = hi[o][m].max(similarity(o as u8, b as u8 + 4));
                }
            }
        }
    }
    debug_assert!(lo.iter().flatten().all(|&v| v as u32 <= SIM_MAX));
    (lo, hi)
}

/// Spreads one-hot orientations over a `t x t` window centred as `[-t/2, t - t/2)`, into a plane
/// of size `out_w x out_h` (at least the input size; the extra area is empty).
pub fn spread(q: &Plane<u8>, t: usize, out_w: usize, out_h: usize) -> Plane<u8> {
    assert!(t >= 1 && out_w >= q.width && out_h >= q.height);
    let (w, h) = (q.width, q.height);
    let lo = (t / 2) as isize;
    // Horizontal OR into an out_w-wide buffer of h rows.
    let mut horiz = vec![0u8; out_w * h];
    horiz.par_chunks_mut(out_w).enumerate().for_each(|(y, row)| {
        let src = q.row(y);
        for d in -lo..(t as isize - lo) {
            // row[x] |= src[x + d] for valid x.
            let x_from = (-d).max(0) as usize;
            let x_to = ((w as isize - d).min(out_w as isize)).max(0) as usize;
            if x_from >= x_to {
                continue;
            }
            let s = &src[(x_from as isize + d) as usize..(x_to as isize + d) as usize];
            for (o, &v) in row[x_from..x_to].iter_mut().zip(s) {
                *o |= v;
            }
        }
    });
    let mut out = vec![0u8; out_w * out_h];
    out.par_chunks_mut(out_w).enumerate().for_each(|(y, row)| {
        for d in -lo..(t as isize - lo) {
            let yy = y as isize + d;
            if yy < 0 || yy >= h as isize {
                continue;
            }
            let s = &horiz[yy as usize * out_w..(yy as usize + 1) * out_w];
            for (o, &v) in row.iter_mut().zip(s) {
                *o |= v;
            }
        }
    });
    Plane::from_vec(out_w, out_h, out)
}

/// The 8 response maps `S_o` of one pyramid level, each `width x height`, row-major.
#[derive(Clone, Debug)]
pub struct ResponseMaps {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `maps[o][y * width + x]`, values 0..=4.
    pub maps: Vec<Vec<u8>>,
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn lookup_avx2(src: &[u8], dst: &mut [u8], lo: &[u8; 16], hi: &[u8; 16]) {
    use std::arch::x86_64::*;
    let n = src.len().min(dst.len());
    let lo_t = _mm256_broadcastsi128_si256(_mm_loadu_si128(lo.as_ptr() as *const __m128i));
    let hi_t = _mm256_broadcastsi128_si256(_mm_loadu_si128(hi.as_ptr() as *const __m128i));
    let nib = _mm256_set1_epi8(0x0f);
    let mut i = 0;
    while i + 32 <= n {
        // SAFETY: i + 32 <= n bounds both slices; unaligned loads/stores.
        let v = _mm256_loadu_si256(src.as_ptr().add(i) as *const __m256i);
        let l = _mm256_and_si256(v, nib);
        let h = _mm256_and_si256(_mm256_srli_epi16(v, 4), nib);
        let r = _mm256_max_epu8(_mm256_shuffle_epi8(lo_t, l), _mm256_shuffle_epi8(hi_t, h));
        _mm256_storeu_si256(dst.as_mut_ptr().add(i) as *mut __m256i, r);
        i += 32;
    }
    for k in i..n {
        dst[k] = lo[(src[k] & 15) as usize].max(hi[(src[k] >> 4) as usize]);
    }
}

fn lookup(src: &[u8], dst: &mut [u8], lo: &[u8; 16], hi: &[u8; 16]) {
    #[cfg(target_arch = "x86_64")]
    {
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2 (checked at run time).
            unsafe { lookup_avx2(src, dst, lo, hi) };
            return;
        }
    }
    for (d, &s) in dst.iter_mut().zip(src) {
        *d = lo[(s & 15) as usize].max(hi[(s >> 4) as usize]);
    }
}

/// Computes the 8 response maps of a spread plane with the two 4-bit lookup tables.
pub fn response_maps(spread: &Plane<u8>) -> ResponseMaps {
    let (lo, hi) = lut_halves();
    let n = spread.data.len();
    let mut maps: Vec<Vec<u8>> = (0..N_ORI).map(|_| vec![0u8; n]).collect();
    const CHUNK: usize = 1 << 14;
    maps.par_iter_mut().enumerate().for_each(|(o, m)| {
        m.par_chunks_mut(CHUNK).enumerate().for_each(|(ci, dst)| {
            let src = &spread.data[ci * CHUNK..ci * CHUNK + dst.len()];
            lookup(src, dst, &lo[o], &hi[o]);
        });
    });
    ResponseMaps { width: spread.width, height: spread.height, maps }
}

/// Linearized memories of a level for grid step `t` (the level size must be a multiple of `t`).
#[derive(Clone, Debug)]
pub struct LinearMemories {
    /// Grid step `T`, pixels.
    pub t: usize,
    /// Grid width `W / T`.
    pub grid_w: usize,
    /// Grid height `H / T`.
    pub grid_h: usize,
    /// `mem[((o T + dy) T + dx) grid_w grid_h + r grid_w + c]`.
    pub mem: Vec<u8>,
}

impl LinearMemories {
    /// The memory of orientation `o` and in-cell offset `(dx, dy)`.
    #[inline]
    pub fn memory(&self, o: usize, dx: usize, dy: usize) -> &[u8] {
        let n = self.grid_w * self.grid_h;
        let k = (o * self.t + dy) * self.t + dx;
        &self.mem[k * n..(k + 1) * n]
    }
}

/// Builds the linearized memories of response maps for grid step `t`.
pub fn linearize(resp: &ResponseMaps, t: usize) -> LinearMemories {
    assert!(resp.width % t == 0 && resp.height % t == 0, "level size must be a multiple of T");
    let (gw, gh) = (resp.width / t, resp.height / t);
    let n = gw * gh;
    let mut mem = vec![0u8; N_ORI * t * t * n];
    mem.par_chunks_mut(n).enumerate().for_each(|(k, dst)| {
        let o = k / (t * t);
        let dy = (k / t) % t;
        let dx = k % t;
        let src = &resp.maps[o];
        for r in 0..gh {
            let row = &src[(r * t + dy) * resp.width..];
            for c in 0..gw {
                dst[r * gw + c] = row[c * t + dx];
            }
        }
    });
    LinearMemories { t, grid_w: gw, grid_h: gh, mem }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lut_halves_equal_direct_max() {
        let (lo, hi) = lut_halves();
        for o in 0..8u8 {
            for m in 0..=255u8 {
                let direct = (0..8u8).filter(|b| m & (1 << b) != 0).map(|b| similarity(o, b)).max().unwrap_or(0);
                assert_eq!(lo[o as usize][(m & 15) as usize].max(hi[o as usize][(m >> 4) as usize]), direct);
            }
        }
        // SIMD path agrees with the scalar formula on every mask value.
        let src: Vec<u8> = (0..=255u8).cycle().take(1000).collect();
        let mut dst = vec![0u8; 1000];
        lookup(&src, &mut dst, &lo[3], &hi[3]);
        for (s, d) in src.iter().zip(&dst) {
            assert_eq!(*d, (0..8u8).filter(|b| s & (1 << b) != 0).map(|b| similarity(3, b)).max().unwrap_or(0));
        }
    }

    #[test]
    fn spread_covers_centred_window() {
        let mut q = Plane::new(20, 20);
        *q.get_mut(10, 10) = 4;
        let s = spread(&q, 4, 24, 20);
        // Pixel (10,10) is seen from x with x + d = 10, d in [-2, 2): x in 9..=12.
        for y in 0..20 {
            for x in 0..24 {
                let inside = (9..=12).contains(&x) && (9..=12).contains(&y);
                assert_eq!(s.get(x, y) == 4, inside, "({x},{y})");
            }
        }
    }
}
