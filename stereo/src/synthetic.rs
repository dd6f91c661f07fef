//! Synthetic rectified stereo pairs with exact disparity, for tests and benchmarks.
//!
//! The scene is a slanted background plane with disparity `d(x, y) = a + b x + c y` (affine in
//! left-image pixels, as for any 3D plane) and fronto-parallel boxes at constant disparities in
//! front of it. Every surface carries its own procedural texture `T_k(u, v)` (three octaves of
//! smoothly interpolated lattice noise) attached to right-image coordinates, so both views are
//! rendered exactly: `L(x, y) = T_k(x - d_k(x, y), y)` for the front-most surface at the left
//! pixel, `R(x_r, y) = T_k(x_r, y)` for the front-most surface at the right pixel.

use serde::{Deserialize, Serialize};
use tubeloc_core::Plane;

/// A fronto-parallel box: left-image rectangle `[x0, x1) x [y0, y1)` at disparity `d` pixels.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SyntheticBox {
    /// Left column (inclusive).
    pub x0: f64,
    /// Top row (inclusive).
    pub y0: f64,
    /// Right column (exclusive).
    pub x1: f64,
    /// Bottom row (exclusive).
    pub y1: f64,
    /// Disparity, pixels; must exceed the background's so the box is in front.
    pub d: f64,
}

/// A rendered pair with its ground truth.
#[derive(Clone, Debug)]
pub struct SyntheticPair {
    /// Left image.
    pub left: Plane<u8>,
    /// Right image.
    pub right: Plane<u8>,
    /// Exact left disparity, pixels.
    pub disparity: Plane<f32>,
    /// 1 where the left pixel is visible in the right image (non-occluded, inside it).
    pub visible: Plane<u8>,
}

#[inline]
fn hash(i: i64, j: i64, seed: u64) -> f64 {
    let mut h = (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ (j as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F) ^ seed.wrapping_mul(0x1656_67B1_9E37_79F9);
    h ^= h >> 31;
    h = h.wrapping_mul(0xD6E8_FEB8_6659_FD93);
    h ^= h >> 29;
    (h >> 11) as f64 / (1u64 << 53) as f64
}

/// Procedural texture value in `[0, 255]` at continuous coordinates `(u, v)`.
fn texture(u: f64, v: f64, seed: u64) -> f64 {
    let mut sum = 0.0;
    for (k, (cell, amp)) in [(2.0, 0.5), (5.0, 0.3), (13.0, 0.2)].into_iter().enumerate() {
        let (x, y) = (u / cell, v / cell);
        let (i, j) = (x.floor(), y.floor());
        let (fx, fy) = (x - i, y - j);
        let (sx, sy) = (fx * fx * (3.0 - 2.0 * fx), fy * fy * (3.0 - 2.0 * fy));
        let s = seed.wrapping_add(k as u64 * 7919);
        let (i, j) = (i as i64, j as i64);
        let a = hash(i, j, s) * (1.0 - sx) + hash(i + 1, j, s) * sx;
        let b = hash(i, j + 1, s) * (1.0 - sx) + hash(i + 1, j + 1, s) * sx;
        sum += amp * (a * (1.0 - sy) + b * sy);
    }
    20.0 + 215.0 * sum
}

/// Renders a `width x height` pair: background plane `d = plane.0 + plane.1 x + plane.2 y`
/// (requires `|plane.1| < 1`) and `boxes` in front of it; `seed` picks the textures.
pub fn render_scene(width: usize, height: usize, plane: (f64, f64, f64), boxes: &[SyntheticBox], seed: u64) -> SyntheticPair {
    let (a, b, c) = plane;
    // Front-most surface at a left pixel: (surface id, disparity); id 0 = background.
    let left_surface = |x: f64, y: f64| {
        let mut best = (0usize, a + b * x + c * y);
        for (k, bx) in boxes.iter().enumerate() {
            if x >= bx.x0 && x < bx.x1 && y >= bx.y0 && y < bx.y1 && bx.d > best.1 {
                best = (k + 1, bx.d);
            }
        }
        best
    };
    let right_surface = |xr: f64, y: f64| {
        let mut best = (0usize, a + b * ((xr + a + c * y) / (1.0 - b)) + c * y);
        for (k, bx) in boxes.iter().enumerate() {
            let x = xr + bx.d;
            if x >= bx.x0 && x < bx.x1 && y >= bx.y0 && y < bx.y1 && bx.d > best.1 {
                best = (k + 1, bx.d);
            }
        }
        best
    };
    let tex = |k: usize, u: f64, v: f64| texture(u, v, seed.wrapping_mul(31).wrapping_add(k as u64 * 104_729)).round().clamp(0.0, 255.0) as u8;
    let mut left = Plane::<u8>::new(width, height);
    let mut right = Plane::<u8>::new(width, height);
    let mut disparity = Plane::<f32>::new(width, height);
    let mut visible = Plane::<u8>::new(width, height);
    for y in 0..height {
        let yf = y as f64;
        for x in 0..width {
            let xf = x as f64;
            let (k, d) = left_surface(xf, yf);
            *left.get_mut(x, y) = tex(k, xf - d, yf);
            *disparity.get_mut(x, y) = d as f32;
            let xr = xf - d;
            *visible.get_mut(x, y) = (xr >= 0.0 && right_surface(xr, yf).0 == k) as u8;
            let (kr, _) = right_surface(xf, yf);
            *right.get_mut(x, y) = tex(kr, xf, yf);
        }
    }
    SyntheticPair { left, right, disparity, visible }
}

/// The benchmark scene used by `benches/sgm.rs` and `scripts/stereo_bench.sh`: a slanted plane
/// (disparity 20 to about 95) with four boxes at 100 to 124 pixels.
pub fn bench_scene(width: usize, height: usize, seed: u64) -> SyntheticPair {
    let (w, h) = (width as f64, height as f64);
    let boxes = [
        SyntheticBox { x0: 0.2 * w, y0: 0.2 * h, x1: 0.4 * w, y1: 0.45 * h, d: 100.0 },
        SyntheticBox { x0: 0.55 * w, y0: 0.15 * h, x1: 0.8 * w, y1: 0.35 * h, d: 110.5 },
        SyntheticBox { x0: 0.3 * w, y0: 0.6 * h, x1: 0.5 * w, y1: 0.85 * h, d: 117.25 },
        SyntheticBox { x0: 0.65 * w, y0: 0.55 * h, x1: 0.9 * w, y1: 0.8 * h, d: 124.0 },
    ];
    render_scene(width, height, (20.0, 0.05, 0.03), &boxes, seed)
}
