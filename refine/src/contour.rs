//! The projected occluding contour of the cylinder stack.
//!
//! With the camera centre at the origin, a section of radius `r` around the axis line
//! `X(t) = c + t a` is seen from distance `d = |c⊥|`, `c⊥ = c - (c·a) a`. With the unit vectors
//! `e1 = c⊥ / d` (from the camera toward the axis, across it) and `e2 = a × e1`, the surface
//! point with outward normal `n` is on a limb when the viewing ray is tangent, `n · X = 0`, i.e.
//! `n·c⊥ = -r`, giving the two limb generators (straight lines parallel to the axis)
//!
//! ```text
//! L±(t) = c + t a + r (α e1 ± β e2),   α = -r/d,  β = sqrt(1 - α²).
//! ```
//!
//! End outlines are the rim circles `c + z a + r (cos φ e1 + sin φ e2)` of each section end
//! that is a free end or steps down to a narrower neighbour. A rim point is on the occluding
//! contour when exactly one of its two faces (side: normal `n`, end: normal `s = ±a`) faces the
//! camera (`n·X < 0` xor `s·X < 0`), and a visible crease when both do; both are image edges
//! and both are used. Visibility against the rest of the tube is checked by ray
//! tests ([`crate::model::CylinderModel::occludes`]), against the scene with a depth map.

use crate::model::CylinderModel;
use nalgebra::{Point2, Point3, Vector2, Vector3};
use tubeloc_core::CameraModel;

/// The pose parameters that are optimized: centre (metres, camera frame) and the unit axis
/// pointing toward the seal end. Rotation about the axis is not represented.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AxisState {
    /// Tube centre, camera frame, metres.
    pub c: Vector3<f64>,
    /// Unit axis toward the seal end.
    pub a: Vector3<f64>,
}

impl AxisState {
    /// Applies an update: `c += δc`, `a = normalize(a + δ1 u1 + δ2 u2)`.
    pub fn updated(&self, delta: &[f64; 5], u1: &Vector3<f64>, u2: &Vector3<f64>) -> AxisState {
        let a = self.a + u1 * delta[3] + u2 * delta[4];
        AxisState { c: self.c + Vector3::new(delta[0], delta[1], delta[2]), a: a.normalize() }
    }

    /// The axis frame `(e1, e2, d)` of the contour formulas; `None` when the camera is on the
    /// axis line (end-on through the centre) or values are not finite.
    pub fn frame(&self) -> Option<AxisFrame> {
        let cp = self.c - self.a * self.c.dot(&self.a);
        let d = cp.norm();
        if !(d.is_finite() && d > 1e-9) {
            return None;
        }
        let e1 = cp / d;
        Some(AxisFrame { c: self.c, a: self.a, e1, e2: self.a.cross(&e1), d })
    }

    /// Sixteen points around the tube of `model` at this state (camera frame, metres), whose
    /// projections bound its image: eight on each end's circle of the largest radius,
    /// `c ± (L/2) a + r_max (cos φ e1 + sin φ e2)`, `φ = k π/4` (the `-L/2` end first); `None`
    /// when the axis frame is degenerate.
    pub fn bounding_points(&self, model: &CylinderModel) -> Option<[Vector3<f64>; 16]> {
        self.prism_points(model, model.max_radius())
    }

    /// [`AxisState::bounding_points`] at radius `radius` (metres) instead of `r_max`: the
    /// corners of an octagonal prism along the tube (circumradius `radius`).
    pub fn prism_points(&self, model: &CylinderModel, radius: f64) -> Option<[Vector3<f64>; 16]> {
        let half = 0.5 * model.length;
        let f = self.frame()?;
        let mut out = [Vector3::zeros(); 16];
        for (i, z) in [-half, half].into_iter().enumerate() {
            for k in 0..8 {
                let phi = k as f64 * std::f64::consts::FRAC_PI_4;
                out[8 * i + k] = self.c + self.a * z + (f.e1 * phi.cos() + f.e2 * phi.sin()) * radius;
            }
        }
        Some(out)
    }
}

/// Derived axis frame, see the module docs.
#[derive(Clone, Copy, Debug)]
pub struct AxisFrame {
    /// Centre.
    pub c: Vector3<f64>,
    /// Unit axis toward the seal end.
    pub a: Vector3<f64>,
    /// Unit vector from the camera toward the axis, perpendicular to it.
    pub e1: Vector3<f64>,
    /// `a × e1`.
    pub e2: Vector3<f64>,
    /// Distance from the camera centre to the axis line, metres.
    pub d: f64,
}

/// The derivative of an [`AxisFrame`] along one fit parameter, in a frame's fields: each the
/// derivative of the field of the same name (`∂c`, `∂a`, `∂e₁`, `∂e₂` per unit of the
/// parameter, `∂d` in metres per unit); the vectors are not unit vectors.
pub type FrameDerivative = AxisFrame;

/// Which contour curve a sample lies on.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SampleKind {
    /// Limb generator of `section` on side `side` (±1) at axial coordinate `t`.
    Limb {
        /// Side of the limb, ±1 (sign of the `e2` component).
        side: f64,
        /// Axial coordinate in the tube frame, metres.
        t: f64,
    },
    /// Rim circle of `section` at end `end` (-1: lower `z0`, +1: upper `z1`) at angle `phi`.
    Rim {
        /// End of the section, ±1.
        end: f64,
        /// Angle in the `(e1, e2)` basis, radians.
        phi: f64,
        /// `cos(phi)` (precomputed).
        cos: f64,
        /// `sin(phi)` (precomputed).
        sin: f64,
    },
}

/// One point of the contour model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContourSample {
    /// Index into [`CylinderModel::sections`].
    pub section: usize,
    /// Curve and parameter.
    pub kind: SampleKind,
}

/// A contour sample evaluated at a pose: 3D point, its outward 3D normal and tangent.
#[derive(Clone, Copy, Debug)]
pub struct SamplePoint {
    /// Point on the surface, camera frame, metres.
    pub x: Point3<f64>,
    /// Outward direction off the silhouette (radial, plus axial for rims), unit.
    pub out: Vector3<f64>,
    /// Unit tangent of the contour curve.
    pub tangent: Vector3<f64>,
}

/// The limb's outward normal `n = α e₁ ± β e₂` of a section of radius `r` whose axis passes
/// `d` from the camera: `α = -r/d`, `β = √(1 - α²)`; `None` when the camera is inside the
/// cylinder (`|α| ≥ 1`).
#[inline]
fn limb_coefficients(r: f64, d: f64) -> Option<(f64, f64)> {
    let alpha = -r / d;
    (alpha.abs() < 1.0).then(|| (alpha, (1.0 - alpha * alpha).sqrt()))
}

impl ContourSample {
    /// Evaluates the sample at the axis frame `f` of the given model.
    #[inline]
    pub fn eval(&self, model: &CylinderModel, f: &AxisFrame) -> Option<SamplePoint> {
        let s = model.sections[self.section];
        match self.kind {
            SampleKind::Limb { side, t } => {
                let (alpha, beta) = limb_coefficients(s.r, f.d)?;
                let n = f.e1 * alpha + f.e2 * (side * beta);
                Some(SamplePoint { x: Point3::from(f.c + f.a * t + n * s.r), out: n, tangent: f.a })
            }
            SampleKind::Rim { end, cos: cs, sin: sn, .. } => {
                let z = if end < 0.0 { s.z0 } else { s.z1 };
                let n = f.e1 * cs + f.e2 * sn;
                let x = f.c + f.a * z + n * s.r;
                Some(SamplePoint { x: Point3::from(x), out: (n + f.a * end).normalize(), tangent: f.e2 * cs - f.e1 * sn })
            }
        }
    }

    /// `∂X/∂θ_k`, the derivative of the sample's point `X` at frame `f` along one parameter,
    /// from the frame's derivative `df` along it. `X` is linear in the frame's vectors:
    /// - limb: `X = c + t a + r (α e₁ + s β e₂)`, `α = -r/d`, `β = √(1 - α²)`, side `s`, so
    ///   `∂X = ∂c + t ∂a + r (α ∂e₁ + s β ∂e₂ + (e₁ - s (α/β) e₂) ∂α)` with `∂α = (r/d²) ∂d`;
    /// - rim: `X = c + z a + r (cos φ e₁ + sin φ e₂)`, so
    ///   `∂X = ∂c + z ∂a + r (cos φ ∂e₁ + sin φ ∂e₂)`.
    ///
    /// `None` where [`ContourSample::eval`] has no point.
    #[inline]
    pub fn point_derivative(&self, model: &CylinderModel, f: &AxisFrame, df: &FrameDerivative) -> Option<Vector3<f64>> {
        let s = model.sections[self.section];
        match self.kind {
            SampleKind::Limb { side, t } => {
                let (alpha, beta) = limb_coefficients(s.r, f.d)?;
                let d_alpha = s.r / (f.d * f.d) * df.d;
                let dn = df.e1 * alpha + df.e2 * (side * beta) + (f.e1 - f.e2 * (side * alpha / beta)) * d_alpha;
                Some(df.c + df.a * t + dn * s.r)
            }
            SampleKind::Rim { end, cos: cs, sin: sn, .. } => {
                let z = if end < 0.0 { s.z0 } else { s.z1 };
                Some(df.c + df.a * z + (df.e1 * cs + df.e2 * sn) * s.r)
            }
        }
    }

    /// True when a rim sample is a visible model edge: on the occluding contour (exactly one
    /// face toward the camera) or a crease with both faces toward it; always true for limbs.
    pub fn on_silhouette(&self, model: &CylinderModel, f: &AxisFrame, p: &SamplePoint) -> bool {
        match self.kind {
            SampleKind::Limb { .. } => true,
            SampleKind::Rim { end, .. } => {
                let radial = (p.x.coords - f.c - f.a * f.a.dot(&(p.x.coords - f.c))).normalize();
                let _ = model;
                let side_front = radial.dot(&p.x.coords) < 0.0;
                let end_front = (f.a * end).dot(&p.x.coords) < 0.0;
                // Occluding contour (one face toward the camera) or a visible crease (both):
                // the rim between a section and its end face is an image edge in both cases.
                side_front || end_front
            }
        }
    }
}

/// Builds the sample set for a pose seen by `camera`: limb samples every `spacing_px` pixels
/// along each section (at least 3 per limb, at most 80) and rim samples every `spacing_px`
/// around each exterior rim (8 to 64 per rim). Rims hidden inside a wider neighbour are left out.
pub fn build_samples(model: &CylinderModel, state: &AxisState, camera: &CameraModel, spacing_px: f64) -> Vec<ContourSample> {
    let f_px = 0.5 * (camera.fx + camera.fy);
    let depth = state.c.z.max(1e-3);
    let px_per_m = f_px / depth;
    let along = (state.a - state.c.normalize() * state.a.dot(&state.c.normalize())).norm().max(0.05);
    let mut out = Vec::new();
    for (i, s) in model.sections.iter().enumerate() {
        let len_px = (s.z1 - s.z0) * px_per_m * along;
        let n = ((len_px / spacing_px).ceil() as usize).clamp(3, 80);
        for side in [-1.0, 1.0] {
            for k in 0..n {
                let t = s.z0 + (s.z1 - s.z0) * (k as f64 + 0.5) / n as f64;
                out.push(ContourSample { section: i, kind: SampleKind::Limb { side, t } });
            }
        }
        let circ_px = std::f64::consts::TAU * s.r * px_per_m;
        let m = ((circ_px / spacing_px).ceil() as usize).clamp(8, 64);
        for end in [-1.0, 1.0] {
            if model.neighbour_radius(i, end as i8) >= s.r {
                continue;
            }
            for k in 0..m {
                let phi = std::f64::consts::TAU * (k as f64 + 0.5) / m as f64;
                let (sin, cos) = phi.sin_cos();
                out.push(ContourSample { section: i, kind: SampleKind::Rim { end, phi, cos, sin } });
            }
        }
    }
    out
}

/// [`build_samples`] with the spacing widened so that at most about `max_samples` samples
/// result (the per-curve minimum counts may exceed it slightly).
pub fn build_samples_capped(model: &CylinderModel, state: &AxisState, camera: &CameraModel, spacing_px: f64, max_samples: usize) -> Vec<ContourSample> {
    let s = build_samples(model, state, camera, spacing_px);
    if s.len() <= max_samples.max(1) {
        return s;
    }
    build_samples(model, state, camera, spacing_px * s.len() as f64 / max_samples.max(1) as f64)
}

/// Projects a sample point and returns the pixel and the unit image normal, oriented outward
/// (away from the tube). `None` when behind the camera or degenerate.
#[inline]
pub fn project_with_normal(camera: &CameraModel, p: &SamplePoint) -> Option<(Point2<f64>, Vector2<f64>)> {
    let u = camera.project(&p.x)?;
    let h = 1e-3 * p.x.coords.norm().max(1e-3);
    let ut = camera.project(&(p.x + p.tangent * h))?;
    let uo = camera.project(&(p.x + p.out * h))?;
    let t = ut - u;
    let tn = t.norm();
    if tn.is_nan() || tn <= 1e-12 {
        return None;
    }
    let mut n = Vector2::new(-t.y, t.x) / tn;
    if n.dot(&(uo - u)) < 0.0 {
        n = -n;
    }
    Some((u, n))
}

#[cfg(test)]
mod tests {
    use super::*;
    use tubeloc_core::TubeModel;

    #[test]
    fn limb_rays_are_tangent_to_the_surface() {
        let model = CylinderModel::new(&TubeModel::default()).unwrap();
        let st = AxisState { c: Vector3::new(0.1, 0.05, 0.8), a: Vector3::new(1.0, 0.2, 0.3).normalize() };
        let f = st.frame().unwrap();
        for side in [-1.0, 1.0] {
            let s = ContourSample { section: 1, kind: SampleKind::Limb { side, t: 0.0 } };
            let p = s.eval(&model, &f).unwrap();
            // On the surface: distance to the axis equals the radius.
            let rel = p.x.coords - st.c;
            let rho = (rel - st.a * st.a.dot(&rel)).norm();
            assert!((rho - model.sections[1].r).abs() < 1e-12);
            // Tangent: the surface normal is perpendicular to the viewing ray.
            assert!(p.out.dot(&p.x.coords).abs() < 1e-12);
        }
    }

    #[test]
    fn rim_edges_hide_only_the_back_facing_half() {
        let model = CylinderModel::plain(0.1, 0.01).unwrap();
        // Axis along x, off to the side: the camera sees the -x end face (toward it) and the
        // side; the +x end face points away.
        let st = AxisState { c: Vector3::new(0.2, 0.0, 1.0), a: Vector3::x() };
        let f = st.frame().unwrap();
        let cam = CameraModel::from_hfov(640, 480, 60.0);
        let samples = build_samples(&model, &st, &cam, 2.0);
        let mut on = [0usize; 2];
        let mut all = [0usize; 2];
        for s in &samples {
            if let SampleKind::Rim { end, .. } = s.kind {
                let k = (end > 0.0) as usize;
                all[k] += 1;
                let p = s.eval(&model, &f).unwrap();
                if s.on_silhouette(&model, &f, &p) {
                    on[k] += 1;
                }
            }
        }
        // The -x rim is entirely a visible edge (silhouette half + crease half); of the +x rim
        // only the half whose side faces the camera is an edge.
        assert_eq!(on[0], all[0], "{on:?} of {all:?}");
        let frac = on[1] as f64 / all[1] as f64;
        assert!((frac - 0.5).abs() < 0.1, "{on:?} of {all:?}");
    }
}

#[cfg(test)]
mod vis_tests {
    use super::*;
    use tubeloc_core::TubeModel;

    /// Brute force: is any point of the segment from the camera to `x` inside the solid?
    fn brute(model: &CylinderModel, st: &AxisState, x: &Point3<f64>) -> bool {
        (0..20000).any(|k| {
            let rel = x.coords * (k as f64 / 20000.0) - st.c;
            let z = rel.dot(&st.a);
            (rel - st.a * z).norm() < model.radius_at(z) - 1e-9
        })
    }

    #[test]
    fn self_occlusion_matches_brute_force() {
        let model = CylinderModel::new(&TubeModel::default()).unwrap();
        for st in [AxisState { c: Vector3::new(0.1, 0.05, 0.8), a: Vector3::new(1.0, 0.2, 0.3).normalize() }, AxisState { c: Vector3::new(-0.05, 0.1, 0.5), a: Vector3::new(0.2, -0.3, 1.0).normalize() }] {
            let f = st.frame().unwrap();
            let mut disagree = 0;
            let mut n = 0;
            for s in build_samples(&model, &st, &CameraModel::from_hfov(1000, 800, 40.0), 4.0) {
                let p = s.eval(&model, &f).unwrap();
                let xp = p.x + p.out * 2e-4;
                n += 1;
                disagree += (model.occludes(&st.c, &st.a, &xp) != brute(&model, &st, &xp)) as usize;
            }
            assert!(disagree * 50 <= n, "{disagree} of {n} disagree");
        }
    }
}
