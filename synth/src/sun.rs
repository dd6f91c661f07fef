//! Sun position from local solar time with a simple declination formula.
//!
//! Declination `δ = 23.44° · sin(2π (284 + N) / 365)` for day of year `N`, hour angle
//! `H = 15° · (t − 12)` for solar time `t` in hours; at latitude `φ`:
//! `sin(el) = sin φ sin δ + cos φ cos δ cos H` and the azimuth (from north, clockwise toward
//! east) `az = atan2(−sin H · cos δ, cos φ sin δ − sin φ cos δ cos H)`.
//! World frame: x east, y north, z up.

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// Latitude of the JPL Mars Yard, degrees north.
pub const JPL_LATITUDE_DEG: f64 = 34.2;

/// Sun direction as elevation and azimuth, degrees.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Sun {
    /// Elevation above the horizon, degrees.
    pub elevation_deg: f64,
    /// Azimuth from north toward east, degrees.
    pub azimuth_deg: f64,
}

impl Sun {
    /// Sun for latitude (degrees), day of year (1-365) and local solar time (hours).
    pub fn at(latitude_deg: f64, day_of_year: f64, solar_hour: f64) -> Sun {
        let phi = latitude_deg.to_radians();
        let decl = (23.44f64).to_radians() * (2.0 * std::f64::consts::PI * (284.0 + day_of_year) / 365.0).sin();
        let h = (15.0 * (solar_hour - 12.0)).to_radians();
        let sin_el = phi.sin() * decl.sin() + phi.cos() * decl.cos() * h.cos();
        let el = sin_el.clamp(-1.0, 1.0).asin();
        let az = (-h.sin() * decl.cos()).atan2(phi.cos() * decl.sin() - phi.sin() * decl.cos() * h.cos());
        Sun { elevation_deg: el.to_degrees(), azimuth_deg: az.to_degrees().rem_euclid(360.0) }
    }

    /// Unit vector toward the sun in the world frame (x east, y north, z up).
    pub fn direction(&self) -> Vector3<f64> {
        let (el, az) = (self.elevation_deg.to_radians(), self.azimuth_deg.to_radians());
        Vector3::new(el.cos() * az.sin(), el.cos() * az.cos(), el.sin())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noon_and_afternoon_positions() {
        // Summer solstice noon at 34.2 N: elevation 90 - 34.2 + 23.44, due south.
        let s = Sun::at(JPL_LATITUDE_DEG, 172.0, 12.0);
        assert!((s.elevation_deg - (90.0 - 34.2 + 23.44)).abs() < 0.1, "{s:?}");
        assert!((s.azimuth_deg - 180.0).abs() < 0.5);
        // Morning sun is in the east, afternoon in the west, symmetric.
        let am = Sun::at(JPL_LATITUDE_DEG, 100.0, 10.0);
        let pm = Sun::at(JPL_LATITUDE_DEG, 100.0, 14.0);
        assert!(am.azimuth_deg < 180.0 && pm.azimuth_deg > 180.0);
        assert!((am.elevation_deg - pm.elevation_deg).abs() < 1e-9);
        assert!((am.azimuth_deg + pm.azimuth_deg - 360.0).abs() < 1e-9);
        assert!((s.direction().norm() - 1.0).abs() < 1e-12);
    }
}
