//! Silhouette + depth rendering of a triangle mesh of the tube (e.g. the CAD model's OBJ), so
//! that templates can come from the real shape instead of the parametric cylinders.
//!
//! Triangles are rasterized at pixel centres (integer coordinates, as in
//! [`crate::line2d::render`]): a pixel is covered when its centre lies inside the projected
//! triangle (edge functions, both windings); the depth is `Z = 1 / (Σ b_i / Z_i)` with the
//! screen-space barycentrics `b_i` (perspective-correct), the smallest over triangles.

use crate::line2d::render::{Pinhole, Silhouette};
use nalgebra::{Point3, Vector3};
use tubeloc_core::{Pose, TubeMaterial, TubeMesh};

/// A mesh ready for rendering: vertices in the tube frame (metres), triangles.
#[derive(Clone, Debug, PartialEq)]
pub struct MeshShape {
    /// Vertex positions, tube frame, metres.
    pub vertices: Vec<Point3<f64>>,
    /// Triangles as vertex indices.
    pub triangles: Vec<[u32; 3]>,
}

impl MeshShape {
    /// Keeps the triangles whose material is not in `exclude` (e.g. the CAD model's
    /// non-flight plastic cap) and re-centres along `z` so that the tube frame's origin is the
    /// midpoint between the lowest and highest kept vertex, as for the parametric model.
    /// Returns `None` when no triangle is left.
    pub fn from_mesh(mesh: &TubeMesh, exclude: &[TubeMaterial]) -> Option<MeshShape> {
        let triangles: Vec<[u32; 3]> = mesh.triangles.iter().zip(&mesh.materials).filter(|(_, m)| !exclude.contains(m)).map(|(t, _)| *t).collect();
        if triangles.is_empty() {
            return None;
        }
        let (mut zmin, mut zmax) = (f64::INFINITY, f64::NEG_INFINITY);
        for t in &triangles {
            for &i in t {
                let z = mesh.vertices[i as usize].z;
                zmin = zmin.min(z);
                zmax = zmax.max(z);
            }
        }
        let mid = 0.5 * (zmin + zmax);
        let vertices = mesh.vertices.iter().map(|p| Point3::new(p.x, p.y, p.z - mid)).collect();
        Some(MeshShape { vertices, triangles })
    }

    /// Length along `z` of the kept triangles, metres.
    pub fn length(&self) -> f64 {
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for t in &self.triangles {
            for &i in t {
                lo = lo.min(self.vertices[i as usize].z);
                hi = hi.max(self.vertices[i as usize].z);
            }
        }
        hi - lo
    }
}

/// Renders the mesh at `t_cam_tube` with pinhole intrinsics `k`; the box is the projection of
/// the used vertices grown by one pixel (two on the far side), clipped to `clip` when given.
/// Returns an empty silhouette when a vertex is behind the camera or the box is empty.
pub fn render_mesh_silhouette(shape: &MeshShape, k: &Pinhole, t_cam_tube: &Pose, clip: Option<(usize, usize)>) -> Silhouette {
    let empty = Silhouette { x0: 0, y0: 0, width: 0, height: 0, mask: vec![], depth: vec![] };
    // Camera-frame vertices and their projections.
    let cam: Vec<Vector3<f64>> = shape.vertices.iter().map(|p| t_cam_tube.transform_point(p).coords).collect();
    let (mut umin, mut umax, mut vmin, mut vmax) = (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
    let mut proj = vec![(0.0f64, 0.0f64); cam.len()];
    for t in &shape.triangles {
        for &i in t {
            let c = cam[i as usize];
            if c.z <= 1e-6 {
                return empty;
            }
            let (u, v) = (k.fx * c.x / c.z + k.cx, k.fy * c.y / c.z + k.cy);
            proj[i as usize] = (u, v);
            umin = umin.min(u);
            umax = umax.max(u);
            vmin = vmin.min(v);
            vmax = vmax.max(v);
        }
    }
    let (mut x0, mut y0) = (umin.floor() as i64 - 1, vmin.floor() as i64 - 1);
    let (mut x1, mut y1) = (umax.ceil() as i64 + 2, vmax.ceil() as i64 + 2);
    if let Some((w, h)) = clip {
        x0 = x0.max(0);
        y0 = y0.max(0);
        x1 = x1.min(w as i64);
        y1 = y1.min(h as i64);
    }
    if x1 <= x0 || y1 <= y0 || (x1 - x0) > 100_000 || (y1 - y0) > 100_000 {
        return empty;
    }
    let (w, h) = ((x1 - x0) as usize, (y1 - y0) as usize);
    let mut mask = vec![0u8; w * h];
    let mut depth = vec![f32::INFINITY; w * h];
    for t in &shape.triangles {
        let [a, b, c] = t.map(|i| proj[i as usize]);
        let [za, zb, zc] = t.map(|i| cam[i as usize].z);
        let area = (b.0 - a.0) * (c.1 - a.1) - (b.1 - a.1) * (c.0 - a.0);
        if area.abs() < 1e-12 {
            continue;
        }
        let px0 = (a.0.min(b.0).min(c.0).ceil() as i64).max(x0);
        let px1 = (a.0.max(b.0).max(c.0).floor() as i64).min(x1 - 1);
        let py0 = (a.1.min(b.1).min(c.1).ceil() as i64).max(y0);
        let py1 = (a.1.max(b.1).max(c.1).floor() as i64).min(y1 - 1);
        for py in py0..=py1 {
            let y = py as f64;
            for px in px0..=px1 {
                let x = px as f64;
                // Barycentrics by edge functions, normalized by the signed area (any winding).
                let wa = ((b.0 - x) * (c.1 - y) - (b.1 - y) * (c.0 - x)) / area;
                let wb = ((c.0 - x) * (a.1 - y) - (c.1 - y) * (a.0 - x)) / area;
                let wc = 1.0 - wa - wb;
                if wa < 0.0 || wb < 0.0 || wc < 0.0 {
                    continue;
                }
                let z = 1.0 / (wa / za + wb / zb + wc / zc);
                let i = (py - y0) as usize * w + (px - x0) as usize;
                mask[i] = 1;
                if (z as f32) < depth[i] {
                    depth[i] = z as f32;
                }
            }
        }
    }
    Silhouette { x0: x0 as i32, y0: y0 as i32, width: w, height: h, mask, depth }
}
