//! Template viewpoints: a subdivided icosahedron (upper hemisphere), in-plane rotations and
//! distances, deduplicated with the tube's rotational symmetry.
//!
//! Scene of the views: the tube lies on flat ground along world `x`, centred at the origin,
//! world `z` up. A viewpoint `v` (unit vector, `v_z >= 0`) puts the camera at `d v`, looking at
//! the tube centre with image "up" toward world `z` (a level camera), then rolled by each in-plane
//! angle about its optical axis. The tube centre is therefore always on the optical axis.
//!
//! Symmetry: the tube is a solid of revolution about its axis, so with the centre on the optical
//! axis its image depends only on the distance and on the axis direction in the camera frame,
//! `a = R_cam_tube e_z` (a point of the unit sphere). Views whose `a` differ by less than
//! `dedupe_tol_deg` are the same view up to a rotation about the tube axis and only the first
//! is kept.

use crate::line2d::Line2dError;
use nalgebra::{Point3, Rotation3, Vector3};
use tubeloc_core::Pose;

/// Knobs of the view sampling (all angles in degrees, distances in metres).
#[derive(Clone, Debug, PartialEq)]
pub struct ViewParams {
    /// Target angle between adjacent icosahedron viewpoints. Each of the 20 faces is split into
    /// `n²` triangles with `n = round(63.43 / step_deg)` (`n = 2^L` is the classic recursive
    /// midpoint subdivision; other `n` let the spacing match the step).
    pub step_deg: f64,
    /// In-plane (camera roll) step.
    pub inplane_step_deg: f64,
    /// In-plane angles span `[-inplane_range_deg, +inplane_range_deg]`.
    pub inplane_range_deg: f64,
    /// Views whose axis directions differ by less than this are duplicates.
    pub dedupe_tol_deg: f64,
    /// Nearest distance, metres.
    pub dist_min: f64,
    /// Farthest distance, metres (included when on the step grid).
    pub dist_max: f64,
    /// Distance step, metres.
    pub dist_step: f64,
}

impl Default for ViewParams {
    fn default() -> Self {
        ViewParams { step_deg: 10.0, inplane_step_deg: 10.0, inplane_range_deg: 10.0, dedupe_tol_deg: 6.0, dist_min: 1.0, dist_max: 4.0, dist_step: 0.1 }
    }
}

/// One template view: the pose of the tube in the camera frame and its parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewSpec {
    /// `T_cam_tube`; the tube centre is on the optical axis at `distance`.
    pub t_cam_tube: Pose,
    /// Angle between the tube axis and the line of sight, degrees (0 = seal end toward camera).
    pub alpha_deg: f64,
    /// Image direction of the projected tube `+z` axis, degrees, `atan2(a_y, a_x)`.
    pub psi_deg: f64,
    /// Camera-to-centre distance, metres.
    pub distance: f64,
}

/// Vertices of the icosahedron with each face split into `n²` triangles, on the unit sphere.
pub fn geodesic_sphere(n: usize) -> Vec<Vector3<f64>> {
    let p = (1.0 + 5f64.sqrt()) / 2.0;
    let v: Vec<Vector3<f64>> = [(-1.0, p, 0.0), (1.0, p, 0.0), (-1.0, -p, 0.0), (1.0, -p, 0.0), (0.0, -1.0, p), (0.0, 1.0, p), (0.0, -1.0, -p), (0.0, 1.0, -p), (p, 0.0, -1.0), (p, 0.0, 1.0), (-p, 0.0, -1.0), (-p, 0.0, 1.0)]
        .iter()
        .map(|&(x, y, z)| Vector3::new(x, y, z).normalize())
        .collect();
    let faces = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]];
    let n = n.max(1);
    let mut out: Vec<Vector3<f64>> = Vec::new();
    // Vertices shared by faces are found through a grid of 1e-6 cells (the 27 cells around a
    // point hold every earlier point within 1e-9 of it): the same points, in the same order, as
    // comparing with every earlier vertex, without the quadratic cost.
    let cell = |q: &Vector3<f64>| [(q.x * 1e6).floor() as i64, (q.y * 1e6).floor() as i64, (q.z * 1e6).floor() as i64];
    let mut grid: std::collections::HashMap<[i64; 3], Vec<usize>> = std::collections::HashMap::new();
    for f in faces {
        for i in 0..=n {
            for j in 0..=(n - i) {
                let k = n - i - j;
                let q = (v[f[0]] * i as f64 + v[f[1]] * j as f64 + v[f[2]] * k as f64).normalize();
                let c = cell(&q);
                let mut seen = false;
                'near: for dx in -1..=1 {
                    for dy in -1..=1 {
                        for dz in -1..=1 {
                            if let Some(ids) = grid.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) {
                                if ids.iter().any(|&o| (out[o] - q).norm() < 1e-9) {
                                    seen = true;
                                    break 'near;
                                }
                            }
                        }
                    }
                }
                if !seen {
                    grid.entry(c).or_default().push(out.len());
                    out.push(q);
                }
            }
        }
    }
    out
}

/// What a [`ViewParams`] asks for, computed from the numbers alone (nothing is generated), so
/// that a library too large to build can be refused before any work. Counts are `f64` because
/// absurd parameters give counts beyond any integer type.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewEstimate {
    /// Subdivision `n` of the icosahedron's faces.
    pub subdivision: f64,
    /// Vertices of the whole subdivided sphere, `10 n² + 2`.
    pub sphere_vertices: f64,
    /// Upper bound of the candidate views (upper-hemisphere vertices times in-plane angles)
    /// that the symmetry deduplication examines.
    pub candidates: f64,
    /// Upper bound of the unique view rotations kept: at most the candidates, and at most the
    /// number of axis directions pairwise `dedupe_tol_deg` apart (`2 / (1 - cos(tol / 2))`,
    /// disjoint caps on the sphere).
    pub rotations: f64,
    /// Distances of the grid.
    pub distances: f64,
    /// Upper bound of the templates: `rotations * distances` (views whose silhouette is empty
    /// are dropped when building).
    pub templates: f64,
    /// Upper bound of the axis comparisons of the deduplication (`candidates * rotations`).
    pub comparisons: f64,
}

/// Estimates the size of the view set of `params` without generating it; see [`ViewEstimate`].
pub fn estimate_views(params: &ViewParams) -> Result<ViewEstimate, Line2dError> {
    check(params)?;
    let n = (63.434_948_822_922_01 / params.step_deg).round().max(1.0);
    let sphere_vertices = 10.0 * n * n + 2.0;
    // Upper hemisphere (z >= 0) with the vertices on the equator: at most half the sphere plus
    // one ring of 10 n, plus the poles.
    let hemisphere = (5.0 * n * n + 10.0 * n + 2.0).min(sphere_vertices);
    let rolls = 2.0 * (params.inplane_range_deg / params.inplane_step_deg + 1e-9).floor() + 1.0;
    let candidates = hemisphere * rolls;
    let half_tol = (params.dedupe_tol_deg / 2.0).to_radians();
    let packing = if half_tol > 0.0 { 2.0 / (1.0 - half_tol.cos()) } else { f64::INFINITY };
    let rotations = candidates.min(packing.ceil());
    let distances = ((params.dist_max - params.dist_min) / params.dist_step + 1e-6).floor() + 1.0;
    Ok(ViewEstimate { subdivision: n, sphere_vertices, candidates, rotations, distances, templates: rotations * distances, comparisons: candidates * rotations })
}

/// `T_world_tube`: tube `+z` along world `x`, tube `x` along world `y`, tube `y` along world `z`.
fn world_tube() -> Pose {
    let r = nalgebra::Matrix3::from_columns(&[Vector3::y(), Vector3::z(), Vector3::x()]);
    Pose::from_parts(Rotation3::from_matrix_unchecked(r), Vector3::zeros())
}

fn check(params: &ViewParams) -> Result<(), Line2dError> {
    let ok = |x: f64| x.is_finite() && x > 0.0;
    if !(ok(params.step_deg) && params.step_deg <= 90.0) {
        return Err(Line2dError::invalid("step-deg", format!("must be in (0, 90], got {}", params.step_deg)));
    }
    if !(ok(params.inplane_step_deg) && params.inplane_range_deg.is_finite() && params.inplane_range_deg >= 0.0) {
        return Err(Line2dError::invalid("inplane", "step must be > 0 and range >= 0 degrees"));
    }
    if !(params.dedupe_tol_deg.is_finite() && params.dedupe_tol_deg >= 0.0) {
        return Err(Line2dError::invalid("dedupe-tol-deg", "must be >= 0"));
    }
    if !(ok(params.dist_min) && ok(params.dist_step) && params.dist_max >= params.dist_min && params.dist_max.is_finite()) {
        return Err(Line2dError::invalid("distances", format!("need 0 < min <= max and step > 0, got {}:{}:{}", params.dist_min, params.dist_max, params.dist_step)));
    }
    Ok(())
}

/// The distance grid `min, min + step, ..., <= max` (metres).
pub fn distances(params: &ViewParams) -> Vec<f64> {
    let n = ((params.dist_max - params.dist_min) / params.dist_step + 1e-6).floor() as usize + 1;
    (0..n).map(|i| params.dist_min + i as f64 * params.dist_step).collect()
}

/// Unique view rotations `R_cam_tube` (at unit distance) after symmetric deduplication.
pub fn unique_rotations(params: &ViewParams) -> Result<Vec<Rotation3<f64>>, Line2dError> {
    check(params)?;
    let n = (63.434_948_822_922_01 / params.step_deg).round().max(1.0) as usize;
    let t_world_tube = world_tube();
    let n_roll = (params.inplane_range_deg / params.inplane_step_deg + 1e-9).floor() as i64;
    let cos_tol = params.dedupe_tol_deg.to_radians().cos();
    let mut kept_axes: Vec<Vector3<f64>> = Vec::new();
    let mut out = Vec::new();
    for v in geodesic_sphere(n).into_iter().filter(|v| v.z >= -1e-9) {
        let up = if v.x.abs() < 1e-9 && v.y.abs() < 1e-9 { Vector3::y() } else { Vector3::z() };
        let t_world_cam = Pose::look_at(&Point3::from(v), &Point3::origin(), &up)?;
        for k in -n_roll..=n_roll {
            let roll = Pose::from_parts(Rotation3::from_axis_angle(&Vector3::z_axis(), (k as f64 * params.inplane_step_deg).to_radians()), Vector3::zeros());
            let t_cam_tube = (t_world_cam * roll).inverse() * t_world_tube;
            let r = t_cam_tube.rotation();
            let a = r.column(2).into_owned();
            if kept_axes.iter().any(|b| a.dot(b) > cos_tol) {
                continue;
            }
            kept_axes.push(a);
            out.push(Rotation3::from_matrix_unchecked(r));
        }
    }
    Ok(out)
}

/// All template views: unique rotations times distances, the tube centre on the optical axis.
pub fn generate_views(params: &ViewParams) -> Result<Vec<ViewSpec>, Line2dError> {
    let rots = unique_rotations(params)?;
    let dists = distances(params);
    let mut out = Vec::with_capacity(rots.len() * dists.len());
    for r in &rots {
        let a = r.matrix().column(2).into_owned();
        for &d in &dists {
            out.push(ViewSpec { t_cam_tube: Pose::from_parts(*r, Vector3::new(0.0, 0.0, d)), alpha_deg: (-a.z).clamp(-1.0, 1.0).acos().to_degrees(), psi_deg: a.y.atan2(a.x).to_degrees(), distance: d });
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn geodesic_spacing_matches_step() {
        for n in [1usize, 2, 6] {
            let v = geodesic_sphere(n);
            assert_eq!(v.len(), 10 * n * n + 2);
            // Nearest-neighbour angle close to 63.4 / n degrees.
            let nn = v[1..].iter().map(|q| v[0].angle(q).to_degrees()).fold(f64::INFINITY, f64::min);
            assert!((nn - 63.43 / n as f64).abs() < 0.25 * 63.43 / n as f64, "n={n} nn={nn}");
        }
    }

    #[test]
    fn estimate_bounds_the_real_counts() {
        let base = ViewParams::default();
        for p in [
            base.clone(),
            ViewParams { step_deg: 5.0, ..base.clone() },
            ViewParams { step_deg: 21.0, inplane_range_deg: 0.0, ..base.clone() },
            ViewParams { dedupe_tol_deg: 0.0, step_deg: 15.0, ..base.clone() },
            ViewParams { dedupe_tol_deg: 20.0, inplane_step_deg: 3.0, inplane_range_deg: 30.0, ..base.clone() },
            ViewParams { dist_min: 0.5, dist_max: 0.5, dist_step: 1.0, ..base.clone() },
        ] {
            let e = estimate_views(&p).unwrap();
            let rots = unique_rotations(&p).unwrap().len() as f64;
            assert!(rots <= e.rotations, "{p:?}: {rots} > {}", e.rotations);
            assert_eq!(e.distances as usize, distances(&p).len());
            assert!(generate_views(&p).unwrap().len() as f64 <= e.templates);
            // Not a wild overestimate for the libraries people build.
            assert!(e.templates <= 5.0 * rots * e.distances, "{p:?}: {} vs {}", e.templates, rots * e.distances);
        }
        for n in 1..=30 {
            let hemi = geodesic_sphere(n).into_iter().filter(|v| v.z >= -1e-9).count() as f64;
            assert!(hemi <= 5.0 * (n * n) as f64 + 10.0 * n as f64 + 2.0, "n={n}: {hemi}");
        }
        // The inputs: estimated instantly, astronomically large.
        let e = estimate_views(&ViewParams { dist_step: 1e-9, ..base.clone() }).unwrap();
        assert!(e.templates > 1e11, "{e:?}");
        let e = estimate_views(&ViewParams { step_deg: 0.01, ..base.clone() }).unwrap();
        assert!(e.candidates > 1e8 && e.comparisons > 1e10, "{e:?}");
    }

    #[test]
    fn geodesic_sphere_grid_lookup_keeps_every_vertex_once() {
        // The quadratic check: every earlier vertex compared (the former algorithm, which kept
        // first occurrences in the same order).
        fn reference(n: usize) -> Vec<Vector3<f64>> {
            let all = geodesic_sphere(n);
            let mut out: Vec<Vector3<f64>> = Vec::new();
            for q in all {
                if !out.iter().any(|o| (o - q).norm() < 1e-9) {
                    out.push(q);
                }
            }
            out
        }
        for n in [1usize, 2, 5, 6, 11] {
            assert_eq!(geodesic_sphere(n), reference(n));
            assert_eq!(geodesic_sphere(n).len(), 10 * n * n + 2);
        }
    }

    #[test]
    fn default_library_size_and_symmetry_dedupe() {
        let p = ViewParams::default();
        let rots = unique_rotations(&p).unwrap();
        let total = rots.len() * distances(&p).len();
        assert!((5500..=8500).contains(&total), "default library has {total} templates");
        // Kept axes are at least the tolerance apart.
        for i in 0..rots.len() {
            for j in 0..i {
                let ang = rots[i].matrix().column(2).angle(&rots[j].matrix().column(2)).to_degrees();
                assert!(ang >= p.dedupe_tol_deg - 1e-9);
            }
        }
        // With no dedupe, more views survive.
        let all = unique_rotations(&ViewParams { dedupe_tol_deg: 0.0, ..p.clone() }).unwrap();
        assert!(all.len() > rots.len());
        assert_eq!(distances(&p).len(), 31);
    }
}
