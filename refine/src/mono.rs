//! The mono keep-depth subspace of the fit ([`crate::fit`]).
//!
//! A narrow tube's width fixes its distance poorly (0.1 px of a 12 px body is ~1 % of the
//! distance) and shading biases its limb edges inward, so a mono fit of such a tube keeps the
//! seed's distance along the centre's viewing ray: the damped step is solved in the subspace
//! spanned by [`mono_basis`] (centre across the ray, axis turned about it and, with a ground
//! plane, the tilt), and with a ground plane the distance is finally set by
//! [`mono_ground_depth`].

use crate::contour::AxisState;
use crate::model::CylinderModel;
use crate::scene::Scene;
use crate::seed_policy::FitSettings;
use nalgebra::{Matrix5, Vector3, Vector5};
use tubeloc_core::CameraModel;

/// Whether the fit runs in mono keep-depth mode: `mono_depth.keep_depth`, neither stereo
/// points nor a mask, and either the seed profile's `keep_depth` or a tube so narrow that its
/// width fixes the distance worse than the seed does: `width_sigma_px / w > depth_sigma_frac`,
/// with `w = 2 r_body f / |c|` the body width in full-resolution pixels.
pub(crate) fn mono_mode(cfg: &FitSettings, scene: &Scene, model: &CylinderModel, seed: &AxisState, cam: &CameraModel) -> bool {
    let w = 2.0 * model.body_radius() * 0.5 * (cam.fx + cam.fy) / seed.c.norm().max(1e-9);
    let narrow = cfg.seed.keep_depth || cfg.mono_depth.width_sigma_px / w > cfg.seed.depth_sigma_frac;
    cfg.mono_depth.keep_depth && scene.stereo_points.is_empty() && scene.mask.is_none() && narrow
}

/// Columns of the mono subspace of the 5-parameter step `(δc, δ1, δ2)` at `st` for the axis
/// tangent basis `(u1, u2)`: the centre across its viewing ray `ĉ` (two columns), the axis
/// turned about the ray (`ĉ × a`), and with `tilt` the axis tilted toward the camera
/// (`a × (ĉ × a)`). The distance along the ray is left out.
pub(crate) fn mono_basis(st: &AxisState, u1: &Vector3<f64>, u2: &Vector3<f64>, tilt: bool) -> Option<Vec<Vector5<f64>>> {
    let ch = st.c.try_normalize(1e-12)?;
    let w1 = ch.cross(&st.a).try_normalize(1e-9)?;
    let l1 = (st.a - ch * st.a.dot(&ch)).try_normalize(1e-9)?;
    let l2 = ch.cross(&l1);
    let mut b = vec![Vector5::new(l1.x, l1.y, l1.z, 0.0, 0.0), Vector5::new(l2.x, l2.y, l2.z, 0.0, 0.0), Vector5::new(0.0, 0.0, 0.0, w1.dot(u1), w1.dot(u2))];
    if tilt {
        let w2 = st.a.cross(&w1);
        b.push(Vector5::new(0.0, 0.0, 0.0, w2.dot(u1), w2.dot(u2)));
    }
    Some(b)
}

/// Damped step of the normal equations `(H, g)` restricted to the columns `basis` (all five
/// parameters when `None`): `(BᵀHB + λ diag) p = -Bᵀg`, `δ = B p`.
pub(crate) fn damped_step(h: &Matrix5<f64>, g: &Vector5<f64>, lambda: f64, basis: Option<&[Vector5<f64>]>) -> Option<Vector5<f64>> {
    match basis {
        None => {
            let mut hd = *h;
            for k in 0..5 {
                hd[(k, k)] += lambda * h[(k, k)].max(1e-12);
            }
            Some(hd.cholesky()?.solve(&(-g)))
        }
        Some(b) => {
            let k = b.len();
            let bm = nalgebra::DMatrix::from_fn(5, k, |i, j| b[j][i]);
            let mut hr = bm.transpose() * h * &bm;
            let gr = bm.transpose() * g;
            for i in 0..k {
                hr[(i, i)] += lambda * hr[(i, i)].max(1e-12);
            }
            let p = hr.cholesky()?.solve(&(-gr));
            let d = bm * p;
            Some(Vector5::new(d[0], d[1], d[2], d[3], d[4]))
        }
    }
}

/// Mono depth from the ground: moves the centre along its viewing ray by the
/// inverse-variance weighted combination of the seed's distance (σ = the profile's
/// `depth_sigma_frac` of it) and the distance that puts the tube's lowest point on the ground
/// (σ = `priors.ground_sigma_m` when the ground height is known, else the profile's
/// `ground_relief_sigma_m`; the height changes by `n·ĉ` per metre along the ray).
pub(crate) fn mono_ground_depth(model: &CylinderModel, cfg: &FitSettings, scene: &Scene, st: AxisState, seed_dist: f64) -> AxisState {
    let Some(g) = &scene.ground else { return st };
    let sigma_g = if cfg.priors.ground_height_known { cfg.priors.ground_sigma_m } else { cfg.seed.ground_relief_sigma_m };
    let Some(ch) = st.c.try_normalize(1e-12) else { return st };
    let k = g.normal.dot(&ch);
    if sigma_g <= 0.0 || k.abs() < 0.05 {
        return st;
    }
    // Lowest surface point above the ground for a tube of radius r_max tilted by the axis.
    let height = g.normal.dot(&st.c) - g.offset - model.max_radius() * (1.0 - g.normal.dot(&st.a).powi(2)).max(0.0).sqrt() - 0.5 * model.length * g.normal.dot(&st.a).abs();
    let s_ground = -height / k;
    let var_g = (sigma_g / k).powi(2);
    let var_s = (cfg.seed.depth_sigma_frac * seed_dist).powi(2);
    let s = s_ground * var_s / (var_s + var_g);
    AxisState { c: st.c + ch * s, a: st.a }
}
