//! Tube geometry for ray casting, in the tube frame (origin at the centre, +z toward the seal).
//!
//! Parametric model: each section is a cylinder `x² + y² = r²`, `z ∈ [z0, z1]`, closed by disc
//! caps; a ray `o + t d` meets the side where `(d_x² + d_y²) t² + 2(o_x d_x + o_y d_y) t +
//! (o_x² + o_y² − r²) = 0`. The closest hit over all sides and caps is the boundary of the
//! union (inner faces lie inside the solid and are never the first hit). Mesh model: triangles
//! (Möller–Trumbore) under a bounding-volume hierarchy with median splits.

use nalgebra::{Point3, Vector3};
use tubeloc_core::{TubeMaterial, TubeMesh, TubeModel};

/// A hit on the tube surface in the tube frame.
#[derive(Clone, Copy, Debug)]
pub struct TubeHit {
    /// Ray parameter.
    pub t: f64,
    /// Outward unit normal, tube frame.
    pub normal: Vector3<f64>,
    /// Material of the surface hit.
    pub material: TubeMaterial,
}

/// Ray-castable tube geometry.
#[derive(Clone, Debug)]
pub enum TubeShape {
    /// Coaxial cylinders `(z0, z1, radius, material)` in the tube frame.
    Parametric(Vec<(f64, f64, f64, TubeMaterial)>),
    /// Triangle mesh with a BVH.
    Mesh(MeshBvh),
}

impl TubeShape {
    /// The parametric shape of a [`TubeModel`].
    pub fn from_model(m: &TubeModel) -> Self {
        TubeShape::Parametric(
            m.sections
                .iter()
                .map(|s| {
                    let (z0, z1) = m.section_z_in_tube_frame(s);
                    (z0, z1, s.radius, s.material)
                })
                .collect(),
        )
    }

    /// The mesh shape of a [`TubeMesh`].
    pub fn from_mesh(m: &TubeMesh) -> Self {
        TubeShape::Mesh(MeshBvh::build(m))
    }

    /// Half length along z and the largest radius (metres): the bounding cylinder.
    pub fn bounds(&self) -> (f64, f64) {
        match self {
            TubeShape::Parametric(s) => {
                let hl = s.iter().map(|x| x.0.abs().max(x.1.abs())).fold(0.0, f64::max);
                (hl, s.iter().map(|x| x.2).fold(0.0, f64::max))
            }
            TubeShape::Mesh(b) => (b.half_length, b.max_radius),
        }
    }

    /// Closest hit of the tube-frame ray `o + t d` with `t ∈ [tmin, tmax]`.
    pub fn intersect(&self, o: &Point3<f64>, d: &Vector3<f64>, tmin: f64, tmax: f64) -> Option<TubeHit> {
        match self {
            TubeShape::Parametric(sections) => intersect_sections(sections, o, d, tmin, tmax),
            TubeShape::Mesh(b) => b.intersect(o, d, tmin, tmax),
        }
    }
}

fn intersect_sections(sections: &[(f64, f64, f64, TubeMaterial)], o: &Point3<f64>, d: &Vector3<f64>, tmin: f64, tmax: f64) -> Option<TubeHit> {
    let mut best: Option<TubeHit> = None;
    let mut tbest = tmax;
    let a = d.x * d.x + d.y * d.y;
    let b = o.x * d.x + o.y * d.y;
    let c0 = o.x * o.x + o.y * o.y;
    for &(z0, z1, r, mat) in sections {
        if a > 1e-18 {
            let disc = b * b - a * (c0 - r * r);
            if disc >= 0.0 {
                let t = (-b - disc.sqrt()) / a;
                if t >= tmin && t < tbest {
                    let z = o.z + t * d.z;
                    if z >= z0 && z <= z1 {
                        let (x, y) = (o.x + t * d.x, o.y + t * d.y);
                        tbest = t;
                        best = Some(TubeHit { t, normal: Vector3::new(x / r, y / r, 0.0), material: mat });
                    }
                }
            }
        }
        if d.z.abs() > 1e-18 {
            for (zc, nz) in [(z0, -1.0), (z1, 1.0)] {
                let t = (zc - o.z) / d.z;
                if t >= tmin && t < tbest && d.z * nz < 0.0 {
                    let (x, y) = (o.x + t * d.x, o.y + t * d.y);
                    if x * x + y * y <= r * r {
                        tbest = t;
                        best = Some(TubeHit { t, normal: Vector3::new(0.0, 0.0, nz), material: mat });
                    }
                }
            }
        }
    }
    best
}

/// Node of the mesh BVH: bounds and either children or a triangle range.
#[derive(Clone, Debug)]
struct Node {
    lo: [f64; 3],
    hi: [f64; 3],
    /// Leaf: `(start, count)` into `order`; inner: `count == 0` and `start` = left child
    /// (right child is `start + 1`).
    start: u32,
    count: u32,
}

/// Bounding-volume hierarchy over a tube mesh (tube frame).
#[derive(Clone, Debug)]
pub struct MeshBvh {
    tris: Vec<[Point3<f64>; 3]>,
    mats: Vec<TubeMaterial>,
    nodes: Vec<Node>,
    half_length: f64,
    max_radius: f64,
}

impl MeshBvh {
    /// Builds the hierarchy (median split on the longest axis, leaves of ≤ 4 triangles).
    pub fn build(mesh: &TubeMesh) -> Self {
        let mut tris: Vec<[Point3<f64>; 3]> = mesh.triangles.iter().map(|t| t.map(|i| mesh.vertices[i as usize])).collect();
        let mut mats = mesh.materials.clone();
        let mut idx: Vec<usize> = (0..tris.len()).collect();
        let mut nodes = vec![Node { lo: [0.0; 3], hi: [0.0; 3], start: 0, count: 0 }];
        build_node(&tris, &mut idx, 0, tris.len(), 0, &mut nodes);
        tris = idx.iter().map(|&i| tris[i]).collect();
        mats = idx.iter().map(|&i| mats[i]).collect();
        let half_length = mesh.vertices.iter().map(|p| p.z.abs()).fold(0.0, f64::max);
        let max_radius = mesh.vertices.iter().map(|p| (p.x * p.x + p.y * p.y).sqrt()).fold(0.0, f64::max);
        MeshBvh { tris, mats, nodes, half_length, max_radius }
    }

    fn intersect(&self, o: &Point3<f64>, d: &Vector3<f64>, tmin: f64, tmax: f64) -> Option<TubeHit> {
        let inv = Vector3::new(1.0 / d.x, 1.0 / d.y, 1.0 / d.z);
        let mut best: Option<(f64, usize)> = None;
        let mut tbest = tmax;
        let mut stack = [0u32; 64];
        let mut sp = 1;
        while sp > 0 {
            sp -= 1;
            let node = &self.nodes[stack[sp] as usize];
            if !slab(o, &inv, &node.lo, &node.hi, tmin, tbest) {
                continue;
            }
            if node.count > 0 {
                for k in node.start as usize..(node.start + node.count) as usize {
                    if let Some(t) = tri_hit(&self.tris[k], o, d) {
                        if t >= tmin && t < tbest {
                            tbest = t;
                            best = Some((t, k));
                        }
                    }
                }
            } else if sp + 2 <= stack.len() {
                stack[sp] = node.start;
                stack[sp + 1] = node.start + 1;
                sp += 2;
            }
        }
        best.map(|(t, k)| {
            let [a, b, c] = self.tris[k];
            let mut n = (b - a).cross(&(c - a)).normalize();
            if n.dot(d) > 0.0 {
                n = -n;
            }
            TubeHit { t, normal: n, material: self.mats[k] }
        })
    }
}

fn build_node(tris: &[[Point3<f64>; 3]], idx: &mut [usize], start: usize, end: usize, node: usize, nodes: &mut Vec<Node>) {
    let (mut lo, mut hi) = ([f64::MAX; 3], [f64::MIN; 3]);
    for &i in &idx[start..end] {
        for p in &tris[i] {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
    }
    nodes[node].lo = lo;
    nodes[node].hi = hi;
    if end - start <= 4 {
        nodes[node].start = start as u32;
        nodes[node].count = (end - start) as u32;
        return;
    }
    let axis = (0..3).max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b]))).unwrap_or(0);
    let centroid = |i: usize| (tris[i][0][axis] + tris[i][1][axis] + tris[i][2][axis]) / 3.0;
    let mid = (start + end) / 2;
    idx[start..end].select_nth_unstable_by(mid - start, |&a, &b| centroid(a).total_cmp(&centroid(b)));
    let left = nodes.len();
    nodes.push(Node { lo: [0.0; 3], hi: [0.0; 3], start: 0, count: 0 });
    nodes.push(Node { lo: [0.0; 3], hi: [0.0; 3], start: 0, count: 0 });
    nodes[node].start = left as u32;
    nodes[node].count = 0;
    build_node(tris, idx, start, mid, left, nodes);
    build_node(tris, idx, mid, end, left + 1, nodes);
}

#[inline]
fn slab(o: &Point3<f64>, inv: &Vector3<f64>, lo: &[f64; 3], hi: &[f64; 3], tmin: f64, tmax: f64) -> bool {
    let (mut t0, mut t1) = (tmin, tmax);
    for k in 0..3 {
        let (mut a, mut b) = ((lo[k] - o[k]) * inv[k], (hi[k] - o[k]) * inv[k]);
        if a > b {
            std::mem::swap(&mut a, &mut b);
        }
        if a.is_nan() || b.is_nan() {
            continue;
        }
        t0 = t0.max(a);
        t1 = t1.min(b);
    }
    t0 <= t1
}

/// Möller–Trumbore ray/triangle intersection (two-sided).
#[inline]
fn tri_hit(tri: &[Point3<f64>; 3], o: &Point3<f64>, d: &Vector3<f64>) -> Option<f64> {
    let e1 = tri[1] - tri[0];
    let e2 = tri[2] - tri[0];
    let p = d.cross(&e2);
    let det = e1.dot(&p);
    if det.abs() < 1e-18 {
        return None;
    }
    let inv = 1.0 / det;
    let s = o - tri[0];
    let u = s.dot(&p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(&e1);
    let v = d.dot(&q) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    Some(e2.dot(&q) * inv)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parametric_side_and_cap_hits() {
        let shape = TubeShape::from_model(&TubeModel::default());
        // Straight down onto the body at the centre: hit at the body radius.
        let o = Point3::new(0.0, 1.0, 0.0);
        let h = shape.intersect(&o, &-Vector3::y(), 0.0, 10.0).unwrap();
        assert!((h.t - (1.0 - 0.00855)).abs() < 1e-12);
        assert_eq!(h.material, TubeMaterial::Alumina);
        // Along the axis from the seal end: hits the seal cap at z = +0.075.
        let h = shape.intersect(&Point3::new(0.0, 0.0, 1.0), &-Vector3::z(), 0.0, 10.0).unwrap();
        assert!((h.t - 0.925).abs() < 1e-12 && h.normal.z > 0.99 && h.material == TubeMaterial::Gold);
        // The step between body and seal: a ray parallel to the axis at r = 0.010 hits the
        // seal's lower cap (z = 0.015) coming from the foot side.
        let h = shape.intersect(&Point3::new(0.010, 0.0, -0.05), &Vector3::z(), 0.0, 10.0).unwrap();
        assert!((h.t - 0.065).abs() < 1e-12 && h.normal.z < -0.99);
        let (hl, r) = shape.bounds();
        assert!((hl - 0.075).abs() < 1e-12 && (r - 0.0115).abs() < 1e-12);
    }

    #[test]
    fn mesh_bvh_matches_brute_force() {
        // A closed box mesh as a stand-in tube.
        let obj = "v -0.01 -0.01 0\nv 0.01 -0.01 0\nv 0.01 0.01 0\nv -0.01 0.01 0\nv -0.01 -0.01 0.1\nv 0.01 -0.01 0.1\nv 0.01 0.01 0.1\nv -0.01 0.01 0.1\n\
f 1 2 3 4\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n";
        let mesh = TubeMesh::parse_obj(obj, std::path::Path::new("box.obj")).unwrap();
        let shape = TubeShape::from_mesh(&mesh);
        let h = shape.intersect(&Point3::new(0.0, 0.0, 1.0), &-Vector3::z(), 0.0, 10.0).unwrap();
        assert!((h.t - 0.95).abs() < 1e-12 && h.normal.z > 0.99);
        let h = shape.intersect(&Point3::new(1.0, 0.005, 0.01), &-Vector3::x(), 0.0, 10.0).unwrap();
        assert!((h.t - 0.99).abs() < 1e-12 && h.normal.x > 0.99);
        assert!(shape.intersect(&Point3::new(1.0, 0.05, 0.01), &-Vector3::x(), 0.0, 10.0).is_none());
    }
}
