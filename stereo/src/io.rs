//! Disparity file formats and previews (pure functions; PNG encoding is left to the caller).
//!
//! - PFM (`Pf`, little-endian, rows stored bottom to top, the Middlebury float format):
//!   disparity in pixels, invalid pixels written as `+inf` (Middlebury convention) and read
//!   back as `NaN`.
//! - 16-bit fixed point: `round(16 · d)`, 0 = invalid (negative disparities are invalid).
//! - Preview: RGB colour ramp from `d_min` (blue) to `d_max` (red), invalid black.

use crate::error::{param, Result};
use tubeloc_core::Plane;

/// Encodes a disparity map as a little-endian PFM file.
pub fn encode_pfm(disp: &Plane<f32>) -> Vec<u8> {
    let mut out = format!("Pf\n{} {}\n-1.0\n", disp.width, disp.height).into_bytes();
    out.reserve(disp.data.len() * 4);
    for y in (0..disp.height).rev() {
        for &v in disp.row(y) {
            let v = if v.is_nan() { f32::INFINITY } else { v };
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    out
}

/// Decodes a single-channel PFM (either endianness); infinities become `NaN`.
pub fn decode_pfm(bytes: &[u8]) -> Result<Plane<f32>> {
    let bad = |m: &str| param("PFM", m.to_string());
    let mut fields = Vec::new();
    let mut pos = 0;
    while fields.len() < 4 {
        while pos < bytes.len() && bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        let start = pos;
        while pos < bytes.len() && !bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        if start == pos {
            return Err(bad("truncated header"));
        }
        fields.push(std::str::from_utf8(&bytes[start..pos]).map_err(|_| bad("header is not text"))?.to_string());
    }
    pos += 1; // the single whitespace byte after the scale
    if fields[0] != "Pf" {
        return Err(bad(&format!("expected a greyscale 'Pf' file, found {:?}", fields[0])));
    }
    let w: usize = fields[1].parse().map_err(|_| bad("bad width"))?;
    let h: usize = fields[2].parse().map_err(|_| bad("bad height"))?;
    let scale: f32 = fields[3].parse().map_err(|_| bad("bad scale"))?;
    let n = w.checked_mul(h).ok_or_else(|| bad("size overflow"))?;
    let body = bytes.get(pos..pos + 4 * n).ok_or_else(|| bad("truncated pixel data"))?;
    let mut plane = Plane::<f32>::new(w, h);
    for (i, c) in body.chunks_exact(4).enumerate() {
        let a = [c[0], c[1], c[2], c[3]];
        let v = if scale < 0.0 { f32::from_le_bytes(a) } else { f32::from_be_bytes(a) };
        let (x, y) = (i % w, h - 1 - i / w);
        *plane.get_mut(x, y) = if v.is_finite() { v } else { f32::NAN };
    }
    Ok(plane)
}

/// Disparity as 16-bit fixed point `round(16 d)`, 0 where invalid or negative.
pub fn to_u16_x16(disp: &Plane<f32>) -> Vec<u16> {
    disp.data.iter().map(|&d| if d.is_nan() || d <= 0.0 { 0 } else { (d * 16.0).round().min(65535.0) as u16 }).collect()
}

/// RGB preview (3 bytes per pixel): a blue-cyan-green-yellow-red ramp over `[d_min, d_max]`.
pub fn colorize(disp: &Plane<f32>, d_min: f32, d_max: f32) -> Vec<u8> {
    let span = (d_max - d_min).max(1e-6);
    let mut out = Vec::with_capacity(disp.data.len() * 3);
    for &d in &disp.data {
        if d.is_nan() {
            out.extend_from_slice(&[0, 0, 0]);
            continue;
        }
        let t = ((d - d_min) / span).clamp(0.0, 1.0) * 4.0;
        let (r, g, b) = match t {
            t if t < 1.0 => (0.0, t, 1.0),
            t if t < 2.0 => (0.0, 1.0, 2.0 - t),
            t if t < 3.0 => (t - 2.0, 1.0, 0.0),
            t => (1.0, 4.0 - t, 0.0),
        };
        out.extend_from_slice(&[(r * 255.0) as u8, (g * 255.0) as u8, (b * 255.0) as u8]);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pfm_round_trip_keeps_values_and_invalid() {
        let d = Plane::from_vec(3, 2, vec![1.5f32, f32::NAN, 0.0, -2.0, 7.25, 100.0]);
        let back = decode_pfm(&encode_pfm(&d)).unwrap();
        assert_eq!((back.width, back.height), (3, 2));
        for (a, b) in d.data.iter().zip(&back.data) {
            assert!(a == b || (a.is_nan() && b.is_nan()));
        }
        assert!(decode_pfm(b"PF\n1 1\n-1\n").unwrap_err().to_string().contains("Pf"));
        assert!(decode_pfm(b"Pf\n2 2\n-1\n\0\0").unwrap_err().to_string().contains("truncated"));
    }
}
