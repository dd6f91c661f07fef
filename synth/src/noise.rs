//! Seeded value noise for procedural textures and terrain relief.
//!
//! `value2(x, y)` is lattice value noise: pseudo-random values in [-1, 1] at integer lattice
//! points (hashed from the coordinates and a seed), blended with the smoothstep
//! `s(t) = t²(3 − 2t)`. `fbm2` sums octaves `Σ gain^o · value2(2^o x, 2^o y)` normalised to [-1, 1].
//! Everything is a pure function of its inputs, so renders are deterministic and thread-safe.

/// 32-bit integer hash of a lattice point and a seed (a murmur-style finaliser).
#[inline]
pub fn hash2(x: i32, y: i32, seed: u32) -> u32 {
    let mut h = (x as u32).wrapping_mul(0x8da6_b343) ^ (y as u32).wrapping_mul(0xd816_3841) ^ seed.wrapping_mul(0xcb1a_b31f);
    h ^= h >> 16;
    h = h.wrapping_mul(0x7feb_352d);
    h ^= h >> 15;
    h = h.wrapping_mul(0x846c_a68b);
    h ^= h >> 16;
    h
}

/// Hash mapped to a float in [0, 1).
#[inline]
pub fn hash2f(x: i32, y: i32, seed: u32) -> f32 {
    (hash2(x, y, seed) >> 8) as f32 * (1.0 / 16_777_216.0)
}

#[inline]
fn smooth(t: f32) -> f32 {
    t * t * (3.0 - 2.0 * t)
}

/// Value noise in [-1, 1] at `(x, y)` (lattice units), continuous, seeded.
#[inline]
pub fn value2(x: f32, y: f32, seed: u32) -> f32 {
    let xf = x.floor();
    let yf = y.floor();
    let (ix, iy) = (xf as i32, yf as i32);
    let (tx, ty) = (smooth(x - xf), smooth(y - yf));
    let a = hash2f(ix, iy, seed);
    let b = hash2f(ix + 1, iy, seed);
    let c = hash2f(ix, iy + 1, seed);
    let d = hash2f(ix + 1, iy + 1, seed);
    let top = a + (b - a) * tx;
    let bot = c + (d - c) * tx;
    (top + (bot - top) * ty) * 2.0 - 1.0
}

/// Fractal sum of `octaves` value-noise layers, lacunarity 2, amplitude ratio `gain`;
/// result normalised to [-1, 1]. `(x, y)` in lattice units of the coarsest octave.
#[inline]
pub fn fbm2(x: f32, y: f32, octaves: u32, gain: f32, seed: u32) -> f32 {
    let (mut sum, mut amp, mut norm, mut f) = (0.0f32, 1.0f32, 0.0f32, 1.0f32);
    for o in 0..octaves {
        sum += amp * value2(x * f, y * f, seed.wrapping_add(o.wrapping_mul(0x9e37_79b9)));
        norm += amp;
        amp *= gain;
        f *= 2.0;
    }
    sum / norm.max(1e-6)
}

/// Cellular (Worley-style) noise on a jittered grid: returns `(d1, d2, id)`, the distances
/// (lattice units) to the nearest and second-nearest feature points and the nearest cell's hash.
/// `d2 - d1` is small along cell borders, which draws the cracks between flagstone slabs.
pub fn worley2(x: f32, y: f32, seed: u32) -> (f32, f32, u32) {
    let (ix, iy) = (x.floor() as i32, y.floor() as i32);
    let (mut d1, mut d2, mut id) = (f32::MAX, f32::MAX, 0u32);
    for j in -1..=1 {
        for i in -1..=1 {
            let (cx, cy) = (ix + i, iy + j);
            let h = hash2(cx, cy, seed);
            let px = cx as f32 + 0.1 + 0.8 * ((h & 0xffff) as f32 / 65536.0);
            let py = cy as f32 + 0.1 + 0.8 * ((h >> 16) as f32 / 65536.0);
            let d = ((px - x) * (px - x) + (py - y) * (py - y)).sqrt();
            if d < d1 {
                d2 = d1;
                d1 = d;
                id = h;
            } else if d < d2 {
                d2 = d;
            }
        }
    }
    (d1, d2, id)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn value_noise_is_bounded_continuous_and_seeded() {
        let mut prev = value2(0.0, 0.3, 7);
        for i in 1..2000 {
            let x = i as f32 * 0.01;
            let v = value2(x, 0.3, 7);
            assert!((-1.0..=1.0).contains(&v));
            assert!((v - prev).abs() < 0.05, "jump at {x}");
            prev = v;
        }
        assert_ne!(value2(3.5, 1.5, 1), value2(3.5, 1.5, 2));
        assert_eq!(fbm2(3.3, 1.1, 4, 0.5, 9), fbm2(3.3, 1.1, 4, 0.5, 9));
    }

    #[test]
    fn worley_distances_are_ordered() {
        for i in 0..100 {
            let (d1, d2, _) = worley2(i as f32 * 0.37, i as f32 * 0.11, 3);
            assert!(d1 <= d2 && d1 < 1.5);
        }
    }
}
