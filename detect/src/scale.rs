//! Camera-aware working scale: detectors run at the pixel scale they were built for.
//!
//! A tube's body (diameter `D` = 17.1 mm) seen at range `r` by a camera of focal length `f`
//! pixels is `w = f D / r` pixels wide. The detectors were built for tubes about
//! [`WORKING_TUBE_WIDTH_PX`] wide (the paper rig's half-resolution crops at 1-2.5 m show
//! 12-25 px). An image is resampled by `s = WORKING_TUBE_WIDTH_PX / w(r)`, with `r` the
//! expected range of the tubes:
//! - with a ground plane `n · X = d` (camera frame, `n` up, metres): the median distance of the
//!   ground seen by a grid of pixels, over those pixels whose ground point lies within the
//!   range band (the band's far end when none does);
//! - without one: the geometric mean of the range band.
//!
//! Factors within [`DEAD_BAND`] of 1 are taken as 1 (the image is used as it is), and `s` is
//! clamped to `[1/4, 4]`. Results found on the resampled image are mapped back to the
//! original pixels: a point `p'` maps to `p = (p' + ½) / s - ½` (pixel centres at integers).

use nalgebra::Vector3;
use tubeloc_core::CameraModel;

/// Image width of a tube's body at the detectors' working scale, pixels.
pub const WORKING_TUBE_WIDTH_PX: f64 = 16.0;
/// Diameter of the tube's body, metres (`data/tube.toml`).
pub const TUBE_BODY_DIAMETER_M: f64 = 0.0171;
/// Scale factors in `[1 / DEAD_BAND, DEAD_BAND]` are treated as 1.
pub const DEAD_BAND: f64 = 1.4;

/// Distances from the camera at which tubes are expected, metres.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RangeBand {
    /// Nearest range, metres (> 0).
    pub near_m: f64,
    /// Farthest range, metres (> near).
    pub far_m: f64,
}

impl Default for RangeBand {
    /// 1-4 m: what a rover's arm camera or mast camera sees of the ground it can reach.
    fn default() -> Self {
        RangeBand { near_m: 1.0, far_m: 4.0 }
    }
}

impl RangeBand {
    /// Checks `0 < near < far`, both finite.
    pub fn validate(&self) -> Result<(), String> {
        if self.near_m.is_finite() && self.far_m.is_finite() && self.near_m > 0.0 && self.far_m > self.near_m {
            Ok(())
        } else {
            Err(format!("range band {}..{} m: need 0 < near < far, finite", self.near_m, self.far_m))
        }
    }
}

/// The expected range of tubes in the image, metres (see the module doc).
pub fn expected_range_m(cam: &CameraModel, ground: Option<(Vector3<f64>, f64)>, band: RangeBand) -> f64 {
    let Some((n, d)) = ground else { return (band.near_m * band.far_m).sqrt() };
    let nn = n.norm();
    if !(nn > 1e-12 && nn.is_finite() && d.is_finite()) {
        return (band.near_m * band.far_m).sqrt();
    }
    let (n, d) = (n / nn, d / nn);
    let mut ranges = Vec::with_capacity(32 * 32);
    for j in 0..32 {
        for i in 0..32 {
            let u = (i as f64 + 0.5) / 32.0 * cam.width as f64 - 0.5;
            let v = (j as f64 + 0.5) / 32.0 * cam.height as f64 - 0.5;
            let (x, y) = cam.normalize(&nalgebra::Point2::new(u, v));
            let ray = Vector3::new(x, y, 1.0).normalize();
            let den = n.dot(&ray);
            if den.abs() < 1e-9 {
                continue;
            }
            let t = d / den;
            if t > 0.0 && t >= band.near_m && t <= band.far_m {
                ranges.push(t);
            }
        }
    }
    if ranges.is_empty() {
        return band.far_m;
    }
    ranges.sort_by(f64::total_cmp);
    ranges[ranges.len() / 2]
}

/// The largest enlargement [`working_scale`] applies: tubes narrower than
/// `WORKING_TUBE_WIDTH_PX / MAX_ENLARGEMENT` (4 px) stay narrower than the working width.
pub const MAX_ENLARGEMENT: f64 = 4.0;

/// Width of a tube's body at range `range_m` (metres) in the image, pixels:
/// `w = sqrt(fx fy) D / r`.
pub fn tube_width_px(cam: &CameraModel, range_m: f64) -> f64 {
    (cam.fx * cam.fy).sqrt() * TUBE_BODY_DIAMETER_M / range_m
}

/// Tubes narrower at their expected range than the working scale can enlarge to the working
/// width: `w < WORKING_TUBE_WIDTH_PX / MAX_ENLARGEMENT` (4 px), with `w` the
/// [`tube_width_px`] at the [`expected_range_m`]. Few such tubes are found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NarrowTubes {
    /// The expected range of the tubes, metres.
    pub range_m: f64,
    /// Width of a tube's body at that range, pixels.
    pub width_px: f64,
}

impl NarrowTubes {
    /// `Some` when the tubes of an image of `cam` (on the plane `n · X = d`, camera frame, when
    /// known) in `band` are too narrow for the working scale.
    pub fn of(cam: &CameraModel, ground: Option<(Vector3<f64>, f64)>, band: RangeBand) -> Option<Self> {
        let range_m = expected_range_m(cam, ground, band);
        let width_px = tube_width_px(cam, range_m);
        (width_px < WORKING_TUBE_WIDTH_PX / MAX_ENLARGEMENT).then_some(NarrowTubes { range_m, width_px })
    }
}

impl std::fmt::Display for NarrowTubes {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "tubes at their expected range ({:.1} m) are about {:.1} px wide in this image, under the {:.0} px that the learned detector can enlarge to its working width ({WORKING_TUBE_WIDTH_PX:.0} px, at most {MAX_ENLARGEMENT:.0}x): expect most tubes to be missed (a camera with finer pixels, or a closer view, finds them)",
            self.range_m,
            self.width_px,
            WORKING_TUBE_WIDTH_PX / MAX_ENLARGEMENT
        )
    }
}

/// The factor by which to resample the image so that tubes are about
/// [`WORKING_TUBE_WIDTH_PX`] wide (see the module doc).
pub fn working_scale(cam: &CameraModel, ground: Option<(Vector3<f64>, f64)>, band: RangeBand) -> f64 {
    let s = WORKING_TUBE_WIDTH_PX / tube_width_px(cam, expected_range_m(cam, ground, band));
    if !s.is_finite() {
        return 1.0;
    }
    let s = s.clamp(1.0 / MAX_ENLARGEMENT, MAX_ENLARGEMENT);
    if (1.0 / DEAD_BAND..=DEAD_BAND).contains(&s) {
        1.0
    } else {
        s
    }
}

/// Size of an image of `width x height` resampled by `s` (at least 1 x 1).
pub fn scaled_size(width: usize, height: usize, s: f64) -> (usize, usize) {
    (((width as f64 * s).round() as usize).max(1), ((height as f64 * s).round() as usize).max(1))
}

/// Bilinear resampling of `channels` channel-major planes from `width x height` to
/// `nw x nh`: output pixel `(x', y')` reads the source at `((x' + ½) w / nw - ½, ...)`,
/// clamped to the border. When shrinking by more than 2 the source is first box-averaged so
/// that every source pixel contributes ([`box_factors`], [`box_average`]).
pub fn resample_planes(src: &[f32], channels: usize, width: usize, height: usize, nw: usize, nh: usize) -> Vec<f32> {
    use rayon::prelude::*;
    let n = width * height;
    let (sx, sy) = (width as f32 / nw as f32, height as f32 / nh as f32);
    let (kx, ky) = box_factors(width, height, nw, nh);
    if kx > 1 || ky > 1 {
        // Box-average to at most twice the target first.
        let boxed = box_average(channels, width, height, kx, ky, |c, y, row| row.copy_from_slice(&src[c * n + y * width..c * n + (y + 1) * width]));
        return resample_planes(&boxed, channels, width / kx, height / ky, nw, nh);
    }
    let xs: Vec<(usize, usize, f32)> = (0..nw)
        .map(|x| {
            let fx = ((x as f32 + 0.5) * sx - 0.5).clamp(0.0, (width - 1) as f32);
            let x0 = fx.floor() as usize;
            (x0, (x0 + 1).min(width - 1), fx - x0 as f32)
        })
        .collect();
    let mut out = vec![0f32; channels * nw * nh];
    for c in 0..channels {
        let p = &src[c * n..(c + 1) * n];
        out[c * nw * nh..(c + 1) * nw * nh].par_chunks_mut(nw).enumerate().for_each(|(y, row)| {
            let fy = ((y as f32 + 0.5) * sy - 0.5).clamp(0.0, (height - 1) as f32);
            let y0 = fy.floor() as usize;
            let (y1, ty) = ((y0 + 1).min(height - 1), fy - y0 as f32);
            let (r0, r1) = (&p[y0 * width..(y0 + 1) * width], &p[y1 * width..(y1 + 1) * width]);
            for (o, &(x0, x1, tx)) in row.iter_mut().zip(&xs) {
                let a = r0[x0] + (r0[x1] - r0[x0]) * tx;
                let b = r1[x0] + (r1[x1] - r1[x0]) * tx;
                *o = a + (b - a) * ty;
            }
        });
    }
    out
}

/// The box of [`resample_planes`]'s first step from `width x height` to `nw x nh`:
/// `(kx, ky) = (max(1, ⌊w / 2nw⌋), max(1, ⌊h / 2nh⌋))` source pixels per averaged pixel; `(1, 1)`
/// when no box step is needed.
pub fn box_factors(width: usize, height: usize, nw: usize, nh: usize) -> (usize, usize) {
    let (sx, sy) = (width as f32 / nw as f32, height as f32 / nh as f32);
    ((sx / 2.0).floor().max(1.0) as usize, (sy / 2.0).floor().max(1.0) as usize)
}

/// Box average of `channels` planes of `width x height` over `kx x ky` blocks: planes of
/// `⌊w / kx⌋ x ⌊h / ky⌋`, channel-major, each value the mean of its block (sums row by row,
/// left to right). The source is read a row at a time: `source_row(c, y, row)` fills `row`
/// (`width` values) with row `y` of channel `c`, so a per-pixel transform of the input (e.g.
/// [`crate::learned::Preprocess::apply_resampled`]) never needs a full-resolution plane.
pub fn box_average(channels: usize, width: usize, height: usize, kx: usize, ky: usize, source_row: impl Fn(usize, usize, &mut [f32]) + Sync) -> Vec<f32> {
    use rayon::prelude::*;
    let (bw, bh) = (width / kx, height / ky);
    let mut boxed = vec![0f32; channels * bw * bh];
    for c in 0..channels {
        boxed[c * bw * bh..(c + 1) * bw * bh].par_chunks_mut(bw.max(1)).enumerate().for_each_init(
            || vec![0f32; ky * width],
            |rows, (y, out)| {
                for (k, row) in rows.chunks_exact_mut(width).enumerate() {
                    source_row(c, y * ky + k, row);
                }
                for (x, o) in out.iter_mut().enumerate() {
                    let mut acc = 0.0;
                    for row in rows.chunks_exact(width) {
                        acc += row[x * kx..(x + 1) * kx].iter().sum::<f32>();
                    }
                    *o = acc / (kx * ky) as f32;
                }
            },
        );
    }
    boxed
}

/// [`resample_planes`] of an interleaved RGB8 image from `width x height` to `nw x nh`,
/// rounded back to interleaved RGB8. The same values as converting the image to three f32
/// planes first, without those full-size planes: the box step reads the bytes row by row, and
/// a bilinear step at full size reads them in place (an 80-megapixel frame would need 960 MB
/// of planes).
pub fn resample_rgb8(rgb: &[u8], width: usize, height: usize, nw: usize, nh: usize) -> Vec<u8> {
    use rayon::prelude::*;
    let (kx, ky) = box_factors(width, height, nw, nh);
    if kx > 1 || ky > 1 {
        let boxed = box_average(3, width, height, kx, ky, |c, y, row| {
            for (o, p) in row.iter_mut().zip(rgb[3 * y * width..3 * (y + 1) * width].chunks_exact(3)) {
                *o = p[c] as f32;
            }
        });
        let out = resample_planes(&boxed, 3, width / kx, height / ky, nw, nh);
        let m = nw * nh;
        let mut rgb_out = vec![0u8; 3 * m];
        rgb_out.par_chunks_mut(3 * nw).enumerate().for_each(|(y, row)| {
            for (x, px) in row.chunks_exact_mut(3).enumerate() {
                for c in 0..3 {
                    px[c] = out[c * m + y * nw + x].round().clamp(0.0, 255.0) as u8;
                }
            }
        });
        return rgb_out;
    }
    let (sx, sy) = (width as f32 / nw as f32, height as f32 / nh as f32);
    let xs: Vec<(usize, usize, f32)> = (0..nw)
        .map(|x| {
            let fx = ((x as f32 + 0.5) * sx - 0.5).clamp(0.0, (width - 1) as f32);
            let x0 = fx.floor() as usize;
            (3 * x0, 3 * (x0 + 1).min(width - 1), fx - x0 as f32)
        })
        .collect();
    let mut rgb_out = vec![0u8; 3 * nw * nh];
    rgb_out.par_chunks_mut(3 * nw).enumerate().for_each(|(y, row)| {
        let fy = ((y as f32 + 0.5) * sy - 0.5).clamp(0.0, (height - 1) as f32);
        let y0 = fy.floor() as usize;
        let (y1, ty) = ((y0 + 1).min(height - 1), fy - y0 as f32);
        let (r0, r1) = (&rgb[3 * y0 * width..3 * (y0 + 1) * width], &rgb[3 * y1 * width..3 * (y1 + 1) * width]);
        for (px, &(x0, x1, tx)) in row.chunks_exact_mut(3).zip(&xs) {
            for c in 0..3 {
                let (a0, a1, b0, b1) = (r0[x0 + c] as f32, r0[x1 + c] as f32, r1[x0 + c] as f32, r1[x1 + c] as f32);
                let a = a0 + (a1 - a0) * tx;
                let b = b0 + (b1 - b0) * tx;
                px[c] = (a + (b - a) * ty).round().clamp(0.0, 255.0) as u8;
            }
        }
    });
    rgb_out
}

/// The camera of a `width x height` image resampled to `nw x nh`: focal lengths times
/// `(sx, sy) = (nw / width, nh / height)`, principal point mapped as pixel centres
/// (`c' = (c + ½) s - ½`), distortion unchanged (it acts on normalized coordinates).
pub fn scaled_camera(cam: &CameraModel, width: usize, height: usize, nw: usize, nh: usize) -> CameraModel {
    let (sx, sy) = (nw as f64 / width as f64, nh as f64 / height as f64);
    CameraModel { width: nw as u32, height: nh as u32, fx: cam.fx * sx, fy: cam.fy * sy, cx: (cam.cx + 0.5) * sx - 0.5, cy: (cam.cy + 0.5) * sy - 0.5, distortion: cam.distortion }
}

/// Maps a mask found on a `nw x nh` resampled image back to the original `width x height`:
/// each original pixel takes the mask value at its centre's position in the resampled image
/// (nearest), so the mask keeps its area up to the resampling.
pub fn mask_back(mask: &[u8], nw: usize, nh: usize, width: usize, height: usize) -> Vec<u8> {
    let (sx, sy) = (nw as f64 / width as f64, nh as f64 / height as f64);
    let xs: Vec<usize> = (0..width).map(|x| (((x as f64 + 0.5) * sx - 0.5).round().max(0.0) as usize).min(nw - 1)).collect();
    let mut out = vec![0u8; width * height];
    for y in 0..height {
        let yy = (((y as f64 + 0.5) * sy - 0.5).round().max(0.0) as usize).min(nh - 1);
        let src = &mask[yy * nw..(yy + 1) * nw];
        for (o, &xx) in out[y * width..(y + 1) * width].iter_mut().zip(&xs) {
            *o = src[xx];
        }
    }
    out
}

/// [`mask_back`] straight to the original image's COCO RLE and tight bounding box, without the
/// original-size mask: original pixel `(x, y)` takes the value of resampled pixel
/// `(xs(x), ys(y))` (nearest, as in [`mask_back`]). The RLE equals
/// `Rle::from_mask(&mask_back(..))` and the box its `BinaryMask::bbox`; memory is
/// `O(width + height)` besides the runs.
pub fn mask_back_rle(mask: &[u8], nw: usize, nh: usize, width: usize, height: usize) -> (tubeloc_core::Rle, [f64; 4]) {
    let bbox = tubeloc_core::BinaryMask { width: nw, height: nh, data: mask.to_vec() }.bbox();
    mask_back_rle_in(mask, nw, nh, width, height, bbox)
}

/// [`mask_back_rle`] of a resampled mask whose set pixels' bounding box `bbox` (COCO
/// `[x, y, w, h]`, [`tubeloc_core::BinaryMask::bbox`]) is known, e.g. from
/// [`tubeloc_core::Rle::to_bounded_mask`]: only the box is read.
pub fn mask_back_rle_in(mask: &[u8], nw: usize, nh: usize, width: usize, height: usize, bbox: [f64; 4]) -> (tubeloc_core::Rle, [f64; 4]) {
    let (sx, sy) = (nw as f64 / width as f64, nh as f64 / height as f64);
    let xs: Vec<usize> = (0..width).map(|x| (((x as f64 + 0.5) * sx - 0.5).round().max(0.0) as usize).min(nw - 1)).collect();
    let ys: Vec<usize> = (0..height).map(|y| (((y as f64 + 0.5) * sy - 0.5).round().max(0.0) as usize).min(nh - 1)).collect();
    // The rows and columns of the resampled mask that hold a pixel (`r0..=r1`, `c0..=c1`):
    // everything outside maps to runs of zeros without reading the mask.
    if bbox[2] == 0.0 {
        return (tubeloc_core::Rle { size: [height as u32, width as u32], counts: vec![(width * height) as u32] }, [0.0; 4]);
    }
    let (c0, r0) = (bbox[0] as usize, bbox[1] as usize);
    let (c1, r1) = (c0 + bbox[2] as usize - 1, r0 + bbox[3] as usize - 1);
    // Original rows before / after the set rows (ys is non-decreasing).
    let (y_lo, y_hi) = (ys.partition_point(|&yy| yy < r0), ys.partition_point(|&yy| yy <= r1));
    // Column-major runs: each original column is the resampled column xs[x] read at rows ys.
    let (mut counts, mut prev, mut run) = (Vec::new(), false, 0u32);
    let mut push = |v: bool, len: u32| {
        if v != prev {
            counts.push(run);
            run = 0;
            prev = v;
        }
        run += len;
    };
    for &xx in &xs {
        if xx < c0 || xx > c1 {
            push(false, height as u32);
            continue;
        }
        if y_lo > 0 {
            push(false, y_lo as u32);
        }
        let mut y = y_lo;
        while y < y_hi {
            let yy = ys[y];
            let mut len = 1;
            while y + len < y_hi && ys[y + len] == yy {
                len += 1;
            }
            push(mask[yy * nw + xx] != 0, len as u32);
            y += len;
        }
        if y_hi < height {
            push(false, (height - y_hi) as u32);
        }
    }
    counts.push(run);
    // Tight box over the sampled rows and columns only.
    let (mut row_hit, mut col_hit) = (vec![false; nh], vec![false; nw]);
    ys.iter().for_each(|&yy| row_hit[yy] = true);
    xs.iter().for_each(|&xx| col_hit[xx] = true);
    let (mut row_any, mut col_any) = (vec![false; nh], vec![false; nw]);
    for yy in (r0..=r1).filter(|&yy| row_hit[yy]) {
        for xx in (c0..=c1).filter(|&xx| col_hit[xx] && mask[yy * nw + xx] != 0) {
            row_any[yy] = true;
            col_any[xx] = true;
        }
    }
    let span = |idx: &[usize], any: &[bool]| {
        let first = idx.iter().position(|&i| any[i])?;
        let last = idx.iter().rposition(|&i| any[i])?;
        Some((first, last))
    };
    let bbox = match (span(&xs, &col_any), span(&ys, &row_any)) {
        (Some((x0, x1)), Some((y0, y1))) => [x0 as f64, y0 as f64, (x1 - x0 + 1) as f64, (y1 - y0 + 1) as f64],
        _ => [0.0; 4],
    };
    (tubeloc_core::Rle { size: [height as u32, width as u32], counts }, bbox)
}

/// Maps a point `(u', v')` of the image resampled by `(sx, sy)` back to original pixels.
pub fn point_back(p: [f64; 2], sx: f64, sy: f64) -> [f64; 2] {
    [(p[0] + 0.5) / sx - 0.5, (p[1] + 0.5) / sy - 0.5]
}

#[cfg(test)]
mod tests {
    /// The streamed RGB8 resampling gives exactly the bytes of resampling three full-size f32
    /// planes: shrinking by more than 2 (box step), by less, enlarging, odd and mixed factors.
    #[test]
    fn resample_rgb8_equals_resampling_full_size_planes() {
        let mut state = 99u64;
        let mut next = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 56) as u8
        };
        for &(w, h, nw, nh) in &[(97usize, 61usize, 20usize, 13usize), (64, 48, 40, 30), (31, 17, 55, 30), (50, 9, 11, 17), (8, 8, 8, 8), (1, 1, 3, 2), (300, 200, 37, 101)] {
            let rgb: Vec<u8> = (0..3 * w * h).map(|_| next()).collect();
            let n = w * h;
            let mut planes = vec![0f32; 3 * n];
            for (i, px) in rgb.chunks_exact(3).enumerate() {
                for c in 0..3 {
                    planes[c * n + i] = px[c] as f32;
                }
            }
            let out = super::resample_planes(&planes, 3, w, h, nw, nh);
            let m = nw * nh;
            let want: Vec<u8> = (0..3 * m).map(|i| out[(i % 3) * m + i / 3].round().clamp(0.0, 255.0) as u8).collect();
            assert_eq!(super::resample_rgb8(&rgb, w, h, nw, nh), want, "{w}x{h} -> {nw}x{nh}");
        }
    }

    #[test]
    fn mask_back_rle_equals_the_rle_of_mask_back() {
        use tubeloc_core::{BinaryMask, Rle};
        // Shrinking, enlarging and mixed factors; masks with seeded random blobs and edges.
        let mut state = 12345u64;
        let mut next = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 33) as usize
        };
        for &(nw, nh, w, h) in &[(10usize, 7usize, 37usize, 23usize), (40, 30, 13, 9), (16, 16, 16, 16), (5, 50, 20, 11), (1, 1, 4, 3)] {
            // Random fills, and a compact blob away from the borders (rows and columns outside
            // it are skipped without reading the mask).
            for fill in [0usize, 1, 30, 100, 1000] {
                let blob = |i: usize| (i % nw) * 3 >= nw && (i % nw) * 3 < 2 * nw && (i / nw) * 3 >= nh && (i / nw) * 3 < 2 * nh;
                let mask: Vec<u8> = (0..nw * nh).map(|i| if fill == 1000 { blob(i) as u8 } else { (next() % 100 < fill) as u8 }).collect();
                let back = mask_back(&mask, nw, nh, w, h);
                let bm = BinaryMask { width: w, height: h, data: back };
                let (rle, bbox) = mask_back_rle(&mask, nw, nh, w, h);
                assert_eq!(rle, Rle::from_mask(&bm), "{nw}x{nh} -> {w}x{h}, fill {fill}");
                assert_eq!(bbox, bm.bbox(), "{nw}x{nh} -> {w}x{h}, fill {fill}");
            }
        }
    }

    use super::*;

    fn navcam() -> CameraModel {
        CameraModel { width: 1024, height: 1024, fx: 1226.0, fy: 1226.0, cx: 511.5, cy: 511.5, distortion: Default::default() }
    }

    #[test]
    fn navcam_tubes_are_scaled_up_to_the_working_width() {
        // Camera 1.97 m above the ground, looking 30 degrees down.
        let p = 30f64.to_radians();
        let up = Vector3::new(0.0, -p.cos(), -p.sin());
        let cam = navcam();
        let r = expected_range_m(&cam, Some((up, -1.97)), RangeBand::default());
        // The image centre sees the ground at 1.97 / sin 30 = 3.94 m; the median over the band is nearer.
        assert!(r > 2.5 && r < 4.0, "{r}");
        let s = working_scale(&cam, Some((up, -1.97)), RangeBand::default());
        let w = 1226.0 * TUBE_BODY_DIAMETER_M / r;
        assert!((tube_width_px(&cam, r) - w).abs() < 1e-9);
        assert!((s * w - WORKING_TUBE_WIDTH_PX).abs() < 1e-9, "s {s} w {w}");
        assert!(s > 2.0);
        // A 256 px frame of the same camera (4x4 binned): tubes about 2 px wide, enlarged by at
        // most 4.
        let binned = CameraModel { width: 256, height: 256, fx: cam.fx / 4.0, fy: cam.fy / 4.0, cx: 127.5, cy: 127.5, ..cam };
        let r_binned = expected_range_m(&binned, Some((up, -1.97)), RangeBand::default());
        assert!((tube_width_px(&binned, r_binned) - w / 4.0).abs() < 0.05);
        assert_eq!(working_scale(&binned, Some((up, -1.97)), RangeBand::default()), MAX_ENLARGEMENT);
    }

    #[test]
    fn paper_half_resolution_crops_stay_at_scale_one() {
        let cam = CameraModel { width: 1024, height: 1024, fx: 1722.0, fy: 1722.0, cx: 511.5, cy: 511.5, distortion: Default::default() };
        assert_eq!(working_scale(&cam, None, RangeBand::default()), 1.0);
    }

    #[test]
    fn resampling_a_ramp_keeps_it_linear_and_masks_map_back() {
        let (w, h) = (8, 4);
        let src: Vec<f32> = (0..w * h).map(|i| (i % w) as f32).collect();
        let up = resample_planes(&src, 1, w, h, 24, 12);
        // Output pixel x' reads source (x' + 0.5) / 3 - 0.5.
        for x in 3..20 {
            let expect = (x as f32 + 0.5) / 3.0 - 0.5;
            assert!((up[5 * 24 + x] - expect).abs() < 1e-5, "{x}: {}", up[5 * 24 + x]);
        }
        let mut mask = vec![0u8; 24 * 12];
        for y in 0..12 {
            for x in 6..12 {
                mask[y * 24 + x] = 1;
            }
        }
        let back = mask_back(&mask, 24, 12, w, h);
        assert_eq!(&back[0..8], &[0, 0, 1, 1, 0, 0, 0, 0]);
        assert_eq!(point_back([7.0, 1.0], 3.0, 3.0), [2.0, 0.0]);
        let down = resample_planes(&up, 1, 24, 12, 8, 4);
        for x in 1..7 {
            assert!((down[2 * 8 + x] - x as f32).abs() < 0.2, "{x}: {}", down[2 * 8 + x]);
        }
    }
}
