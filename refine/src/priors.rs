//! The quadratic prior residuals of the fit ([`crate::fit`]) and their Jacobian rows, in the
//! order they follow the image and stereo residuals:
//! - with a ground plane `n·X = d` (tube resting on it): the centre height
//!   `g₁ = (n·c - d - r_max) / σ_g` (only when `priors.ground_height_known`; `None`
//!   otherwise) and the axis tilt `g₂ = (n·a) / σ_t` (axis parallel to the ground; `σ_t` from
//!   the seed kind's profile);
//! - with a detector's image axis ([`ImageAxisPrior`], `Scene::image_axis`), the axis's
//!   component out of that line's interpretation plane, `(a·n) / σ`.

use crate::contour::AxisState;
use crate::model::CylinderModel;
use crate::seed::GroundPlane;
use crate::seed_policy::FitSettings;
use nalgebra::{Vector3, Vector5};

/// The detector's image axis (a segmentation mask's principal axis) as a prior on the fitted
/// axis's direction in the image. The image line through the mask's centre along its axis
/// and the camera centre span the line's interpretation plane, unit normal `n` (camera frame);
/// an axis `a` whose image runs along the line lies in that plane, and an image rotation `δφ`
/// about the tube's centre gives `a·n ≈ |a⊥| sin δφ` (`a⊥`: the part of `a` across the viewing
/// ray). With the mask line's ends known to `s` pixels each, `σ_φ = √2 s / L` for an image
/// length `L ≈ f ℓ |a⊥| / |c|` (focal length `f` px, tube length `ℓ`, distance `|c|`), so the
/// residual `(a·n) / σ` takes `σ = √2 s |c| / (f ℓ)`, whatever the foreshortening.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImageAxisPrior {
    /// Unit normal of the image line's interpretation plane, camera frame.
    pub normal: Vector3<f64>,
    /// `σ` of `a·n` (dimensionless, a sine).
    pub sigma: f64,
}

impl ImageAxisPrior {
    /// The prior of an image line through `centre_px` along the unit image direction
    /// `direction_px` (pixels, distorted image), for a tube of length `length_m` whose seed
    /// lies `distance_m` from the camera and line ends known to `sigma_px` pixels; `None` for a
    /// degenerate line or non-positive inputs.
    pub fn from_image_line(camera: &tubeloc_core::CameraModel, centre_px: [f64; 2], direction_px: [f64; 2], sigma_px: f64, length_m: f64, distance_m: f64) -> Option<Self> {
        use nalgebra::Point2;
        if !(sigma_px > 0.0 && length_m > 0.0 && distance_m > 0.0) {
            return None;
        }
        let (c, d) = (Point2::new(centre_px[0], centre_px[1]), nalgebra::Vector2::new(direction_px[0], direction_px[1]).try_normalize(1e-12)?);
        let half = 10.0;
        let normal = camera.unproject(&(c - d * half)).cross(&camera.unproject(&(c + d * half))).try_normalize(1e-12)?;
        let sigma = std::f64::consts::SQRT_2 * sigma_px * distance_m / (camera.fx * length_m);
        (sigma.is_finite() && normal.iter().all(|v| v.is_finite())).then_some(ImageAxisPrior { normal, sigma })
    }
}

/// One prior row of the fit, in the order of the module doc.
#[derive(Clone, Copy, Debug, PartialEq)]
enum PriorRow<'a> {
    /// Centre height over the ground (`None` residual unless `ground_height_known`).
    GroundHeight(&'a GroundPlane),
    /// Axis parallel to the ground.
    GroundTilt(&'a GroundPlane),
    /// Axis in the detector's image line's interpretation plane.
    ImageAxis(&'a ImageAxisPrior),
}

/// The prior rows that apply, in order: the single list both [`push_residuals`] and
/// [`jacobian_row`] follow.
fn prior_rows<'a>(ground: Option<&'a GroundPlane>, image_axis: Option<&'a ImageAxisPrior>) -> impl Iterator<Item = PriorRow<'a>> {
    let ground_rows = ground.into_iter().flat_map(|g| [PriorRow::GroundHeight(g), PriorRow::GroundTilt(g)]);
    ground_rows.chain(image_axis.map(PriorRow::ImageAxis))
}

/// Appends the prior residuals at `st` to `out` (order: see the module doc).
pub(crate) fn push_residuals(model: &CylinderModel, st: &AxisState, ground: Option<&GroundPlane>, image_axis: Option<&ImageAxisPrior>, cfg: &FitSettings, out: &mut Vec<Option<f64>>) {
    for row in prior_rows(ground, image_axis) {
        out.push(match row {
            PriorRow::GroundHeight(g) => cfg.priors.ground_height_known.then(|| (g.normal.dot(&st.c) - g.offset - model.max_radius()) / cfg.priors.ground_sigma_m),
            PriorRow::GroundTilt(g) => Some(g.normal.dot(&st.a) / cfg.seed.ground_tilt_sigma_deg.to_radians()),
            PriorRow::ImageAxis(p) => Some(st.a.dot(&p.normal) / p.sigma),
        });
    }
}

/// Jacobian row of prior residual `k` (its index among the priors, order of [`push_residuals`])
/// for the perturbation basis `u = (u1, u2)` of the axis (parameters: centre x, y, z, axis
/// along u1, u2); zero for an index past the last prior.
pub(crate) fn jacobian_row(k: usize, ground: Option<&GroundPlane>, image_axis: Option<&ImageAxisPrior>, cfg: &FitSettings, u: (&Vector3<f64>, &Vector3<f64>)) -> Vector5<f64> {
    let axis_row = |n: &Vector3<f64>, sigma: f64| Vector5::new(0.0, 0.0, 0.0, n.dot(u.0), n.dot(u.1)) / sigma;
    match prior_rows(ground, image_axis).nth(k) {
        Some(PriorRow::GroundHeight(g)) => Vector5::new(g.normal.x, g.normal.y, g.normal.z, 0.0, 0.0) / cfg.priors.ground_sigma_m,
        Some(PriorRow::GroundTilt(g)) => axis_row(&g.normal, cfg.seed.ground_tilt_sigma_deg.to_radians()),
        Some(PriorRow::ImageAxis(p)) => axis_row(&p.normal, p.sigma),
        None => Vector5::zeros(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tubeloc_core::TubeModel;

    /// Each prior's Jacobian row matches central differences of its residual.
    #[test]
    fn jacobian_rows_match_finite_differences() {
        let model = CylinderModel::new(&TubeModel::default()).unwrap();
        let cfg = crate::RefineConfig::default().resolve(crate::SeedKind::Explicit);
        let ground = GroundPlane { normal: Vector3::new(0.0, -0.8, -0.6), offset: -1.0 };
        let st = AxisState { c: Vector3::new(0.12, 0.28, 2.05), a: Vector3::new(0.25, -0.1, 0.9).normalize() };
        let (u1, u2) = (st.a.cross(&Vector3::x()).normalize(), st.a.cross(&st.a.cross(&Vector3::x())).normalize());
        let image_axis = ImageAxisPrior { normal: Vector3::new(0.2, 0.9, -0.1).normalize(), sigma: 0.004 };
        let eval = |p: &Vector5<f64>| {
            let s = AxisState { c: st.c + Vector3::new(p[0], p[1], p[2]), a: (st.a + u1 * p[3] + u2 * p[4]).normalize() };
            let mut out = Vec::new();
            push_residuals(&model, &s, Some(&ground), Some(&image_axis), &cfg, &mut out);
            out.into_iter().map(|r| r.unwrap()).collect::<Vec<f64>>()
        };
        let n = eval(&Vector5::zeros()).len();
        assert_eq!(n, 3);
        for k in 0..n {
            let row = jacobian_row(k, Some(&ground), Some(&image_axis), &cfg, (&u1, &u2));
            for j in 0..5 {
                let mut e = Vector5::zeros();
                e[j] = 1e-6;
                let fd = (eval(&e)[k] - eval(&(-e))[k]) / 2e-6;
                assert!((fd - row[j]).abs() < 1e-4 * (1.0 + fd.abs()), "prior {k} parameter {j}: {fd} vs {}", row[j]);
            }
        }
    }

    #[test]
    fn image_axis_prior_contains_the_imaged_axis_and_scales_with_distance() {
        let cam = tubeloc_core::CameraModel::from_hfov(640, 480, 50.0);
        let (c, a) = (Vector3::new(0.1, -0.05, 1.5), Vector3::new(0.6, 0.3, 0.74).normalize());
        let p0 = cam.project(&nalgebra::Point3::from(c)).unwrap();
        let d = (cam.project(&nalgebra::Point3::from(c + a * 0.05)).unwrap() - p0).normalize();
        let prior = ImageAxisPrior::from_image_line(&cam, [p0.x, p0.y], [d.x, d.y], 0.5, 0.15, c.norm()).unwrap();
        assert!(a.dot(&prior.normal).abs() < 1e-9, "the axis lies in the line's interpretation plane");
        assert!(c.dot(&prior.normal).abs() < 1e-9 * c.norm());
        let expect = std::f64::consts::SQRT_2 * 0.5 * c.norm() / (cam.fx * 0.15);
        assert!((prior.sigma - expect).abs() < 1e-12);
        // An image rotation of δ about the centre: a·n ≈ |a⊥| sin δ.
        let delta = 1f64.to_radians();
        let dr = nalgebra::Vector2::new(d.x * delta.cos() - d.y * delta.sin(), d.x * delta.sin() + d.y * delta.cos());
        let turned = ImageAxisPrior::from_image_line(&cam, [p0.x, p0.y], [dr.x, dr.y], 0.5, 0.15, c.norm()).unwrap();
        let a_perp = (a - c.normalize() * a.dot(&c.normalize())).norm();
        let got = a.dot(&turned.normal).abs();
        assert!((got / (a_perp * delta.sin()) - 1.0).abs() < 0.1, "a·n {got} vs {}", a_perp * delta.sin());
        assert!(ImageAxisPrior::from_image_line(&cam, [p0.x, p0.y], [0.0, 0.0], 0.5, 0.15, 1.0).is_none());
        assert!(ImageAxisPrior::from_image_line(&cam, [p0.x, p0.y], [d.x, d.y], 0.0, 0.15, 1.0).is_none());
    }
}
