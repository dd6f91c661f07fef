//! Census transform (Zabih & Woodfill 1994) into 64-bit signatures.
//!
//! For a window of `w x h` pixels (odd sizes, `w*h - 1 <= 64`) centred on `p`, bit `k` of the
//! signature is `I(q_k) < I(p)` for the k-th neighbour `q_k` in raster order (centre skipped).
//! Pixels outside the image are replaced by the nearest border pixel. The matching cost of two
//! signatures is their Hamming distance `popcount(a ^ b)`.

use crate::error::{param, Result};
use rayon::prelude::*;
use tubeloc_core::Plane;

/// Census signatures of `img` over a `win_w x win_h` window, one `u64` per pixel.
pub fn census_transform(img: &Plane<u8>, win_w: usize, win_h: usize) -> Result<Plane<u64>> {
    let mut out = Plane::<u64>::new(0, 0);
    census_into(img, win_w, win_h, &mut out)?;
    Ok(out)
}

/// As [`census_transform`], writing into `out` (resized to the image, its buffer reused).
pub fn census_into(img: &Plane<u8>, win_w: usize, win_h: usize, out: &mut Plane<u64>) -> Result<()> {
    if win_w % 2 == 0 || win_h % 2 == 0 || win_w * win_h < 9 || win_w * win_h > 65 {
        return Err(param("census window", format!("{win_w}x{win_h}: sizes must be odd, with 9 <= w*h <= 65")));
    }
    let (w, h) = (img.width, img.height);
    let (rx, ry) = (win_w / 2, win_h / 2);
    let pw = w + 2 * rx;
    // Border-replicated copy so the inner loop has no bounds logic.
    let mut padded = vec![0u8; pw * (h + 2 * ry)];
    for (py, prow) in padded.chunks_exact_mut(pw).enumerate() {
        let sy = (py as isize - ry as isize).clamp(0, h as isize - 1) as usize;
        let src = img.row(sy);
        for (px, v) in prow.iter_mut().enumerate() {
            *v = src[(px as isize - rx as isize).clamp(0, w as isize - 1) as usize];
        }
    }
    out.width = w;
    out.height = h;
    out.data.clear();
    out.data.resize(w * h, 0);
    out.data.par_chunks_mut(w).enumerate().for_each(|(y, orow)| {
        let centre = &padded[(y + ry) * pw + rx..][..w];
        for dy in 0..win_h {
            for dx in 0..win_w {
                if dy == ry && dx == rx {
                    continue;
                }
                let nb = &padded[(y + dy) * pw + dx..][..w];
                shift_in(orow, nb, centre);
            }
        }
    });
    Ok(())
}

crate::multiversion! {
    fn shift_in(acc: &mut [u64], nb: &[u8], centre: &[u8]) {
        for ((a, &n), &c) in acc.iter_mut().zip(nb).zip(centre) {
            *a = (*a << 1) | ((n < c) as u64);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn signature_counts_darker_neighbours() {
        // 3x3 image, centre 5: neighbours darker than the centre set their bit.
        let img = Plane::from_vec(3, 3, vec![1, 9, 2, 8, 5, 7, 3, 6, 4]);
        let c = census_transform(&img, 3, 3).unwrap();
        // raster order of neighbours: 1 9 2 8 | 7 3 6 4 -> bits 1 0 1 0 0 1 0 1
        assert_eq!(c.get(1, 1), 0b1010_0101);
        assert!(census_transform(&img, 4, 3).is_err());
        assert!(census_transform(&img, 11, 7).is_err());
    }
}
