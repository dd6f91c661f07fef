//! Terrain kinds of the paper and their procedural height and albedo.
//!
//! Heights (metres) and albedo are functions of world `(x, y)` and a seed:
//! - flagstone: broken slabs (jittered Voronoi cells, ≈0.45 m) raised 1–3 cm with a small
//!   random offset, separated by cracks that drop to the regolith, under a patchy thin dust;
//! - CFA6 / CFA2 and the other kinds share a regolith relief
//!   `1.5 cm · fbm(x / 0.8 m) + 4 mm · fbm(x / 10 cm) + 1.5 mm · fbm(x / 2 cm)`;
//! - ditch: a ≈0.9 m wide, ≈15 cm deep trench with smooth walls crossing near the centre;
//! - riverbed: two meandering shallow channels (5–8 cm) with ripples in their beds.
//!
//! Rocks are added separately (see [`crate::scene`]).

use crate::noise::{fbm2, value2, worley2};
use serde::{Deserialize, Serialize};

/// Terrain type of a scene.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TerrainKind {
    /// Broken stone slabs under thin dust (fractured bedrock).
    Flagstone,
    /// Rock field with cumulative fractional area 6 %.
    Cfa6,
    /// Rock field with cumulative fractional area 2 % (pebbles).
    Cfa2,
    /// A depression crossing the scene.
    Ditch,
    /// Shallow meandering channels with pebbles.
    Riverbed,
}

impl TerrainKind {
    /// Name used in files and on the command line.
    pub fn name(&self) -> &'static str {
        match self {
            TerrainKind::Flagstone => "flagstone",
            TerrainKind::Cfa6 => "cfa6",
            TerrainKind::Cfa2 => "cfa2",
            TerrainKind::Ditch => "ditch",
            TerrainKind::Riverbed => "riverbed",
        }
    }

    /// Parses a name as written by [`TerrainKind::name`].
    pub fn parse(s: &str) -> Option<TerrainKind> {
        [TerrainKind::Flagstone, TerrainKind::Cfa6, TerrainKind::Cfa2, TerrainKind::Ditch, TerrainKind::Riverbed].into_iter().find(|k| k.name() == s)
    }
}

/// Linear (0-1, clipped) to sRGB (0-255, rounded): the inverse of [`srgb_to_linear`].
pub fn linear_to_srgb8(v: f32) -> u8 {
    let v = v.clamp(0.0, 1.0);
    let s = if v <= 0.0031308 { v * 12.92 } else { 1.055 * v.powf(1.0 / 2.4) - 0.055 };
    (s * 255.0 + 0.5) as u8
}

/// sRGB (0-255) to linear.
pub fn srgb_to_linear(c: [u8; 3]) -> [f32; 3] {
    c.map(|v| {
        let x = v as f32 / 255.0;
        if x <= 0.04045 {
            x / 12.92
        } else {
            ((x + 0.055) / 1.055).powf(2.4)
        }
    })
}

/// Regolith colour (sRGB) of the Mars yard.
pub const REGOLITH_SRGB: [u8; 3] = [158, 118, 88];
/// Loose sand (mounds, dunes) colour, sRGB.
pub const SAND_SRGB: [u8; 3] = [176, 136, 100];

fn mix(a: [f32; 3], b: [f32; 3], t: f32) -> [f32; 3] {
    [a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t, a[2] + (b[2] - a[2]) * t]
}

/// Parameters of one generated terrain that stay fixed over the scene.
#[derive(Clone, Debug)]
pub struct TerrainParams {
    /// Kind.
    pub kind: TerrainKind,
    /// Noise seed.
    pub seed: u32,
    /// Ditch: direction angle (rad) and offset of the trench centre line from the origin (m).
    pub ditch: (f64, f64),
    /// Riverbed: per channel (direction angle, offset, depth).
    pub channels: Vec<(f64, f64, f64)>,
}

impl TerrainParams {
    /// Regolith relief common to all kinds, metres.
    fn regolith(&self, x: f32, y: f32) -> f32 {
        let s = self.seed;
        0.015 * fbm2(x / 0.8, y / 0.8, 2, 0.5, s) + 0.004 * fbm2(x / 0.1, y / 0.1, 2, 0.5, s ^ 0x55) + 0.0015 * value2(x / 0.02, y / 0.02, s ^ 0xaa)
    }

    /// Channel profile for the riverbed: 0 outside, 1 at the bed centre, and the across
    /// coordinate used for ripples.
    fn channel(&self, x: f64, y: f64, angle: f64, offset: f64, width: f64) -> (f64, f64) {
        let (c, s) = (angle.cos(), angle.sin());
        let along = x * c + y * s;
        let across = -x * s + y * c - offset - 0.25 * (along * 1.3 + self.seed as f64 * 0.01).sin() - 0.1 * (along * 3.1).sin();
        let u = (across / (width / 2.0)).abs();
        let w = if u < 1.0 { 0.5 * (1.0 + (std::f64::consts::PI * u).cos()) } else { 0.0 };
        (w, along)
    }

    /// Height (m), linear albedo and whether the point is loose sand, at world `(x, y)`.
    pub fn sample(&self, x: f64, y: f64) -> (f32, [f32; 3]) {
        let (xf, yf) = (x as f32, y as f32);
        let s = self.seed;
        let regolith = srgb_to_linear(REGOLITH_SRGB);
        let tint = 0.10 * fbm2(xf / 0.6, yf / 0.6, 3, 0.5, s ^ 0x1234);
        let mut alb = regolith.map(|c| c * (1.0 + tint));
        let mut h = self.regolith(xf, yf);
        match self.kind {
            TerrainKind::Flagstone => {
                let scale = 0.45f32;
                let wx = xf + 0.05 * fbm2(xf / 0.3, yf / 0.3, 2, 0.5, s ^ 7);
                let wy = yf + 0.05 * fbm2(xf / 0.3, yf / 0.3, 2, 0.5, s ^ 8);
                let (d1, d2, id) = worley2(wx / scale, wy / scale, s ^ 0xf1a9);
                let edge = (d2 - d1) * scale; // ≈ twice the distance to the slab border, m
                let crack_w = 0.010 + 0.010 * (0.5 + 0.5 * value2(xf / 0.2, yf / 0.2, s ^ 3));
                let rise = 0.012 + 0.018 * ((id & 0xff) as f32 / 255.0);
                // Each slab has its own gentle warp (noise seeded by the slab id): no seams inside a slab.
                let slab_h = rise + 0.006 * value2(xf / 0.35, yf / 0.35, id) + 0.0015 * fbm2(xf / 0.05, yf / 0.05, 2, 0.5, s ^ 9);
                let t = ((edge - crack_w * 0.5) / crack_w).clamp(0.0, 1.0);
                let t = t * t * (3.0 - 2.0 * t);
                h = h * 0.3 + slab_h * t;
                let shade = 0.8 + 0.4 * ((id >> 24) as f32 / 255.0);
                let slab = srgb_to_linear([150, 134, 118]).map(|c| c * shade);
                let dust = (0.45 + 0.35 * fbm2(xf / 0.15, yf / 0.15, 3, 0.55, s ^ 0x77)).clamp(0.0, 1.0);
                let top = mix(slab, regolith, dust);
                let crack = regolith.map(|c| c * 0.45);
                alb = mix(crack, top, t);
            }
            TerrainKind::Cfa6 | TerrainKind::Cfa2 => {}
            TerrainKind::Ditch => {
                let (angle, offset) = self.ditch;
                let (c, sn) = (angle.cos(), angle.sin());
                let along = x * c + y * sn;
                let across = -x * sn + y * c - offset - 0.15 * (along * 0.9).sin();
                let half = 0.45 + 0.08 * value2((along / 0.7) as f32, 0.5, s ^ 11) as f64;
                let u = (across / half).abs();
                if u < 1.3 {
                    let depth = 0.15;
                    let prof = if u < 1.0 { 0.5 * (1.0 + (std::f64::consts::PI * u).cos()) } else { 0.0 };
                    // Smooth wall plus a small lip of thrown-out soil.
                    let lip = if u > 0.8 { 0.015 * (1.0 - ((u - 1.05) / 0.25).powi(2)).max(0.0) } else { 0.0 };
                    h += (-depth * prof + lip) as f32;
                    let darker = (0.12 * prof) as f32;
                    alb = alb.map(|c| c * (1.0 - darker));
                }
            }
            TerrainKind::Riverbed => {
                for &(angle, offset, depth) in &self.channels {
                    let (w, along) = self.channel(x, y, angle, offset, 0.55);
                    if w > 0.0 {
                        let ripple = 0.004 * (along * 45.0 + 2.0 * fbm2(xf / 0.2, yf / 0.2, 2, 0.5, s ^ 5) as f64).sin();
                        h += (-depth * w + ripple * w) as f32;
                        let sand = srgb_to_linear(SAND_SRGB);
                        alb = mix(alb, sand.map(|c| c * 0.92), (w as f32 * 1.5).min(1.0));
                    }
                }
            }
        }
        (h, alb)
    }

    /// Weight in [0, 1] of the riverbed channel floor at `(x, y)` (pebbles gather there).
    pub fn channel_weight(&self, x: f64, y: f64) -> f64 {
        self.channels.iter().map(|&(a, o, _)| self.channel(x, y, a, o, 0.55).0).fold(0.0, f64::max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kinds_round_trip_names_and_ditch_is_deep() {
        for k in [TerrainKind::Flagstone, TerrainKind::Cfa6, TerrainKind::Cfa2, TerrainKind::Ditch, TerrainKind::Riverbed] {
            assert_eq!(TerrainKind::parse(k.name()), Some(k));
        }
        assert_eq!(TerrainKind::parse("moon"), None);
        let p = TerrainParams { kind: TerrainKind::Ditch, seed: 1, ditch: (0.0, 0.0), channels: vec![] };
        let (h_mid, _) = p.sample(0.0, 0.0);
        let (h_out, _) = p.sample(0.0, 1.5);
        assert!(h_out - h_mid > 0.1, "ditch depth {}", h_out - h_mid);
    }
}
