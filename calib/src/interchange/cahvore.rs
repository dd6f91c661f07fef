//! JPL's CAHVORE camera model (Gennery, "Generalized camera calibration including fish-eye
//! lenses", IJCV 2006): CAHVOR with an entrance pupil that moves along the axis `O` with the
//! ray's angle, and a lens type from perspective to fisheye.
//!
//! A point `P` (reference frame) with `p = P - C`, `ζ = p·O`, `λ = p - ζ O` enters the lens at
//! the angle `θ` from `O` that solves
//!
//! ```text
//! ζ sin θ - |λ| cos θ - (θ - sin θ) ε(θ) = 0,      ε(θ) = E0 + E1 θ² + E2 θ⁴
//! ```
//!
//! (the pupil sits `(θ / sin θ - 1) ε(θ)` along `O` from `C`). The lens maps `θ` to
//! `χ = tan(L θ) / L` (`L > 0`), `sin(L θ) / L` (`L < 0`) or `θ` (`L = 0`, fisheye) with the
//! linearity `L`: 1 for model type 1 (perspective), 0 for type 2 (fisheye), the model's
//! parameter `P` for type 3 (general). The radial terms then give
//! `p' = (|λ| / χ) O + (1 + μ) λ` with `μ = R0 + R1 χ² + R2 χ⁴`, imaged as CAHV images `p'`.
//! With `E = 0` and `L = 1` this is CAHVOR ([`super::cahv::Cahvor`]).

use super::cahv::Cahvor;
use nalgebra::Vector3;

/// Newton iterations allowed for either direction of the model.
const MAX_NEWTON: usize = 100;

/// A CAHVORE camera model in its reference frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cahvore {
    /// The CAHVOR part: `C, A, H, V`, the distortion axis `O` and the radial terms `R`.
    pub cahvor: Cahvor,
    /// The entrance-pupil terms `E0, E1, E2` (m).
    pub e: [f64; 3],
    /// The linearity `L`: 1 perspective, 0 fisheye, between for a general lens.
    pub linearity: f64,
}

impl Cahvore {
    /// The linearity of a model of `kind` (`MTYPE`: 1 perspective, 2 fisheye, 3 general) with
    /// the parameter `parm` (`MPARM`, used by type 3 only); `Err` for another type or a type 3
    /// model without its parameter.
    pub fn linearity_of(kind: f64, parm: Option<f64>) -> Result<f64, String> {
        match kind {
            1.0 => Ok(1.0),
            2.0 => Ok(0.0),
            3.0 => match parm {
                Some(p) if p.is_finite() && p.abs() <= 1.0 => Ok(p),
                Some(p) => Err(format!("the general model's parameter (MPARM) {p} is not within [-1, 1]")),
                None => Err("a general (type 3) model needs its parameter (MPARM)".into()),
            },
            k => Err(format!("model type (MTYPE) {k} is not 1, 2 or 3")),
        }
    }

    fn entrance(&self, theta: f64) -> (f64, f64) {
        let [e0, e1, e2] = self.e;
        let t2 = theta * theta;
        (e0 + e1 * t2 + e2 * t2 * t2, 2.0 * e1 * theta + 4.0 * e2 * theta * t2)
    }

    /// The lens's `χ` of the angle `θ`, `None` past a perspective-like lens's 90 degrees.
    fn chi_of(&self, theta: f64) -> Option<f64> {
        let l = self.linearity;
        match l {
            l if l > 1e-15 => (l * theta < std::f64::consts::FRAC_PI_2).then(|| (l * theta).tan() / l),
            l if l < -1e-15 => Some((l * theta).sin() / l),
            _ => Some(theta),
        }
    }

    /// The image of the reference-frame point `p` (column, row); `None` behind the camera or
    /// outside the lens's field.
    pub fn project(&self, p: &Vector3<f64>) -> Option<(f64, f64)> {
        let m = &self.cahvor;
        let d = p - m.cahv.c;
        let zeta = d.dot(&m.o);
        let lambda = d - zeta * m.o;
        let lam = lambda.norm();
        let moved = if lam <= 1e-12 * d.norm() {
            d
        } else {
            let mut theta = lam.atan2(zeta);
            for _ in 0..MAX_NEWTON {
                let (s, c) = theta.sin_cos();
                let (eps, deps) = self.entrance(theta);
                let f = zeta * s - lam * c - (theta - s) * eps;
                let df = zeta * c + lam * s - (1.0 - c) * eps - (theta - s) * deps;
                if df.abs() < 1e-300 {
                    return None;
                }
                let step = f / df;
                theta -= step;
                if step.abs() < 1e-13 {
                    break;
                }
            }
            if !theta.is_finite() || theta <= 0.0 || theta >= std::f64::consts::PI {
                return None;
            }
            let chi = self.chi_of(theta)?;
            let mu = m.r[0] + m.r[1] * chi * chi + m.r[2] * chi.powi(4);
            (lam / chi) * m.o + (1.0 + mu) * lambda
        };
        let z = moved.dot(&m.cahv.a);
        (z > 0.0).then(|| (moved.dot(&m.cahv.h) / z, moved.dot(&m.cahv.v) / z))
    }

    /// The ray of the pixel `(x, y)` (column, row): the entrance pupil it passes through
    /// (reference frame, m) and its unit direction; `None` where the model has no ray.
    pub fn ray(&self, x: f64, y: f64) -> Option<(Vector3<f64>, Vector3<f64>)> {
        let m = &self.cahvor;
        let (a, h, v) = (m.cahv.a, m.cahv.h, m.cahv.v);
        let avh = a.dot(&v.cross(&h));
        if avh.abs() < 1e-300 {
            return None;
        }
        // The CAHV ray of (x, y), scaled so that its component along A is 1.
        let rp = (v - y * a).cross(&(h - x * a)) / avh;
        let zetap = rp.dot(&m.o);
        if zetap <= 0.0 {
            return None;
        }
        let lambdap = rp - zetap * m.o;
        let chip = lambdap.norm() / zetap;
        if chip < 1e-12 {
            return Some((m.cahv.c, m.o));
        }
        // Undo the radial terms: (1 + R0) χ + R1 χ³ + R2 χ⁵ = χ'.
        let [r0, r1, r2] = m.r;
        let mut chi = chip;
        for _ in 0..MAX_NEWTON {
            let c2 = chi * chi;
            let deriv = 1.0 + r0 + 3.0 * r1 * c2 + 5.0 * r2 * c2 * c2;
            if deriv <= 1e-15 {
                return None;
            }
            let step = ((1.0 + r0) * chi + r1 * chi * c2 + r2 * chi * c2 * c2 - chip) / deriv;
            chi -= step;
            if step.abs() < 1e-14 {
                break;
            }
        }
        let l = self.linearity;
        let theta = match l {
            l if l < -1e-15 => {
                let s = l * chi;
                if s.abs() > 1.0 {
                    return None;
                }
                s.asin() / l
            }
            l if l > 1e-15 => (l * chi).atan() / l,
            _ => chi,
        };
        if !theta.is_finite() || theta <= 0.0 {
            return None;
        }
        let (s, c) = theta.sin_cos();
        let shift = (theta / s - 1.0) * self.entrance(theta).0;
        Some((m.cahv.c + shift * m.o, s * lambdap.normalize() + c * m.o))
    }
}

#[cfg(test)]
mod tests {
    use super::super::cahv::Cahv;
    use super::*;

    /// A fisheye like MSL's hazard cameras: 1024 px, f 456 px, looking forward and down, its
    /// distortion axis a little off the optical axis, with their radial and entrance terms.
    fn hazcam(linearity: f64) -> Cahvore {
        let a = Vector3::new(0.7, 0.03, 0.71).normalize();
        let right = Vector3::new(0.0, 0.0, 1.0).cross(&a).normalize();
        let down = a.cross(&right);
        let (f, cx, cy) = (456.0, 511.2, 508.7);
        let cahv = Cahv { c: Vector3::new(0.61, 0.06, -0.23), a, h: f * right + cx * a, v: f * down + cy * a };
        let o = (a + 0.002 * right).normalize();
        Cahvore { cahvor: Cahvor { cahv, o, r: [8e-6, -0.0128, -0.0075] }, e: [0.0012, 0.0019, 0.0007], linearity }
    }

    #[test]
    fn every_pixel_lies_on_its_own_ray_for_each_lens_type() {
        for l in [1.0, 0.37, 0.0, -0.4] {
            let m = hazcam(l);
            let (mut worst, mut rays): (f64, usize) = (0.0, 0);
            for (x, y) in (0..=16).flat_map(|i| (0..=16).map(move |j| (i as f64 * 64.0, j as f64 * 64.0))) {
                let (origin, dir) = m.ray(x, y).unwrap_or_else(|| panic!("L {l}: no ray at ({x}, {y})"));
                rays += 1;
                for range in [0.4, 2.0, 30.0] {
                    let (u, v) = m.project(&(origin + range * dir)).unwrap_or_else(|| panic!("L {l}: ({x}, {y}) at {range} m did not project"));
                    worst = worst.max((u - x).abs()).max((v - y).abs());
                }
            }
            assert!(worst < 1e-6 && rays == 289, "L {l}: largest round-trip error {worst} px over {rays} rays");
        }
    }

    #[test]
    fn without_entrance_terms_a_perspective_cahvore_is_its_cahvor() {
        let m = Cahvore { e: [0.0; 3], ..hazcam(1.0) };
        for k in 0..40 {
            let s = k as f64;
            let p = m.cahvor.cahv.c + 2.0 * m.cahvor.cahv.a + Vector3::new((0.7 * s).sin(), (0.3 * s).cos(), 0.5 * (0.9 * s).sin());
            let (x0, y0) = m.cahvor.project(&p).unwrap();
            let (x1, y1) = m.project(&p).unwrap();
            assert!((x0 - x1).abs() < 1e-7 && (y0 - y1).abs() < 1e-7, "({x0}, {y0}) vs ({x1}, {y1})");
        }
    }

    #[test]
    fn a_fisheye_images_rays_past_ninety_degrees_that_a_pinhole_cannot() {
        let m = Cahvore { e: [0.0; 3], cahvor: Cahvor { r: [0.0; 3], ..hazcam(0.0).cahvor }, ..hazcam(0.0) };
        let (c, o) = (m.cahvor.cahv.c, m.cahvor.o);
        let side = o.cross(&Vector3::new(0.0, 1.0, 0.0)).normalize();
        // An equidistant fisheye: the image radius grows with the angle itself, f θ.
        let at = |deg: f64| m.project(&(c + deg.to_radians().cos() * o + deg.to_radians().sin() * side)).unwrap();
        let centre = at(0.0);
        let radius = |p: (f64, f64)| ((p.0 - centre.0).powi(2) + (p.1 - centre.1).powi(2)).sqrt();
        assert!((radius(at(60.0)) / radius(at(30.0)) - 2.0).abs() < 1e-3, "{} {}", radius(at(30.0)), radius(at(60.0)));
        assert!(at(100.0).0.is_finite());
        assert!(hazcam(1.0).project(&(c + 100f64.to_radians().cos() * o + 100f64.to_radians().sin() * side)).is_none());
    }

    #[test]
    fn model_types_give_their_linearity_and_unknown_ones_are_refused() {
        assert_eq!(Cahvore::linearity_of(1.0, None), Ok(1.0));
        assert_eq!(Cahvore::linearity_of(2.0, Some(0.5)), Ok(0.0));
        assert_eq!(Cahvore::linearity_of(3.0, Some(0.37)), Ok(0.37));
        assert!(Cahvore::linearity_of(3.0, None).unwrap_err().contains("MPARM"));
        assert!(Cahvore::linearity_of(4.0, None).unwrap_err().contains("MTYPE"));
        assert!(Cahvore::linearity_of(3.0, Some(2.0)).unwrap_err().contains("[-1, 1]"));
    }
}
