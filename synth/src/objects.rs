//! Scene objects above the height field (rocks, tubes, tag-mount plates) and the uniform 2D
//! grid that finds the ones a ray can meet.
//!
//! The grid covers the scene in `cell × cell` columns; each column lists the objects whose
//! bounding box overlaps it (compressed rows: `offsets`, `items`). A ray is clipped to the
//! objects' height range and walked column by column (DDA); the walk stops as soon as the best
//! hit lies before the exit of the current column.

use crate::ray::{clip_aabb, dda2, Ray};
use crate::rock::Rock;
use crate::tags::TagTexture;
use crate::tube_shape::TubeShape;
use nalgebra::{Point3, Vector3};
use std::sync::Arc;
use tubeloc_core::{Pose, TubeMaterial};

/// A tube placed in the world.
#[derive(Clone, Debug)]
pub struct TubeInstance {
    /// Pose of the tube in the world: maps tube-frame points to world points.
    pub t_world_tube: Pose,
    /// Geometry in the tube frame.
    pub shape: Arc<TubeShape>,
    /// Dust cover in [0, 1]: 0 clean, 1 albedo fully regolith.
    pub dust: f32,
    /// Seed of the dust pattern.
    pub seed: u32,
}

/// A thin oriented box (tag plate) with an optional tag printed on its −z face.
#[derive(Clone, Debug)]
pub struct PlateObject {
    /// Pose of the box centre in the world (box axes = frame axes; for tag plates the frame
    /// is the tag frame shifted half a thickness along +z, into the plate).
    pub t_world_box: Pose,
    /// Half extents along the box axes, metres.
    pub half: Vector3<f64>,
    /// Linear albedo of the plate.
    pub albedo: [f32; 3],
    /// Tag printed on the −z face, centred, in tag-plane coordinates `(x, y)` of the box frame.
    pub tag: Option<TagTexture>,
}

impl PlateObject {
    /// Albedo at a point `q` of the box surface (box frame): tag cells on the printed face,
    /// the plate's own albedo elsewhere.
    pub fn albedo_at(&self, q: &Point3<f64>) -> [f32; 3] {
        if q.z < -self.half.z + 1e-7 {
            if let Some(v) = self.tag.as_ref().and_then(|t| t.sample(q.x, q.y)) {
                let a = 0.03 + 0.82 * v;
                return [a, a, a];
            }
        }
        self.albedo
    }
}

/// What a ray met among the objects.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ObjectHit {
    /// Rock index and facet index.
    Rock(usize, usize),
    /// Tube index, surface material, normal in the world frame.
    Tube(usize, TubeMaterial, Vector3<f64>),
    /// Plate index and the hit point in the plate frame.
    Plate(usize, Point3<f64>, Vector3<f64>),
}

/// All objects of a scene plus the column grid.
#[derive(Clone, Debug, Default)]
pub struct Objects {
    /// Rocks.
    pub rocks: Vec<Rock>,
    /// Tubes.
    pub tubes: Vec<TubeInstance>,
    /// Plates and posts of tag mounts.
    pub plates: Vec<PlateObject>,
    x0: f64,
    y0: f64,
    cell: f64,
    nx: usize,
    ny: usize,
    zlo: f64,
    zhi: f64,
    offsets: Vec<u32>,
    items: Vec<u32>,
}

/// Object ids in the grid: rocks first, then tubes, then plates.
#[derive(Clone, Copy)]
enum Id {
    Rock(usize),
    Tube(usize),
    Plate(usize),
}

impl Objects {
    /// Objects without a grid yet; call [`Objects::build_grid`] before casting rays.
    pub fn new(rocks: Vec<Rock>, tubes: Vec<TubeInstance>, plates: Vec<PlateObject>) -> Self {
        Objects { rocks, tubes, plates, ..Default::default() }
    }

    /// World bounds of a tube instance (box around its bounding cylinder).
    pub fn tube_bounds(t: &TubeInstance) -> ([f64; 3], [f64; 3]) {
        let (hl, r) = t.shape.bounds();
        let c = t.t_world_tube.translation();
        let a = t.t_world_tube.transform_vector(&Vector3::z());
        let mut lo = [0.0; 3];
        let mut hi = [0.0; 3];
        for k in 0..3 {
            let e = hl * a[k].abs() + r * (1.0 - a[k] * a[k]).max(0.0).sqrt() + 1e-4;
            lo[k] = c[k] - e;
            hi[k] = c[k] + e;
        }
        (lo, hi)
    }

    fn plate_bounds(p: &PlateObject) -> ([f64; 3], [f64; 3]) {
        let r = p.t_world_box.rotation();
        let c = p.t_world_box.translation();
        let mut lo = [0.0; 3];
        let mut hi = [0.0; 3];
        for k in 0..3 {
            let e = (0..3).map(|j| r[(k, j)].abs() * p.half[j]).sum::<f64>() + 1e-4;
            lo[k] = c[k] - e;
            hi[k] = c[k] + e;
        }
        (lo, hi)
    }

    fn bounds_of(&self, id: Id) -> ([f64; 3], [f64; 3]) {
        match id {
            Id::Rock(i) => (self.rocks[i].lo, self.rocks[i].hi),
            Id::Tube(i) => Self::tube_bounds(&self.tubes[i]),
            Id::Plate(i) => Self::plate_bounds(&self.plates[i]),
        }
    }

    fn decode(&self, item: u32) -> Id {
        let i = item as usize;
        let (nr, nt) = (self.rocks.len(), self.tubes.len());
        if i < nr {
            Id::Rock(i)
        } else if i < nr + nt {
            Id::Tube(i - nr)
        } else {
            Id::Plate(i - nr - nt)
        }
    }

    /// Builds the column grid over `[x0, x0 + nx·cell] × [y0, y0 + ny·cell]`.
    pub fn build_grid(&mut self, x0: f64, y0: f64, cell: f64, nx: usize, ny: usize) {
        self.x0 = x0;
        self.y0 = y0;
        self.cell = cell;
        self.nx = nx;
        self.ny = ny;
        let total = self.rocks.len() + self.tubes.len() + self.plates.len();
        let mut lists: Vec<Vec<u32>> = vec![Vec::new(); nx * ny];
        let (mut zlo, mut zhi) = (f64::MAX, f64::MIN);
        for item in 0..total {
            let (lo, hi) = self.bounds_of(self.decode(item as u32));
            zlo = zlo.min(lo[2]);
            zhi = zhi.max(hi[2]);
            let ix0 = (((lo[0] - x0) / cell).floor().max(0.0) as usize).min(nx - 1);
            let ix1 = (((hi[0] - x0) / cell).floor().max(0.0) as usize).min(nx - 1);
            let iy0 = (((lo[1] - y0) / cell).floor().max(0.0) as usize).min(ny - 1);
            let iy1 = (((hi[1] - y0) / cell).floor().max(0.0) as usize).min(ny - 1);
            for iy in iy0..=iy1 {
                for ix in ix0..=ix1 {
                    lists[iy * nx + ix].push(item as u32);
                }
            }
        }
        self.zlo = if total > 0 { zlo } else { 0.0 };
        self.zhi = if total > 0 { zhi } else { 0.0 };
        self.offsets = Vec::with_capacity(nx * ny + 1);
        self.items.clear();
        self.offsets.push(0);
        for l in &lists {
            self.items.extend_from_slice(l);
            self.offsets.push(self.items.len() as u32);
        }
    }

    /// Closest object hit with `t ∈ [tmin, tmax]`.
    pub fn intersect(&self, ray: &Ray, tmin: f64, tmax: f64) -> Option<(f64, ObjectHit)> {
        if self.items.is_empty() {
            return None;
        }
        let lo = [self.x0, self.y0, self.zlo];
        let hi = [self.x0 + self.nx as f64 * self.cell, self.y0 + self.ny as f64 * self.cell, self.zhi];
        let (ta, tb) = clip_aabb(ray, lo, hi, tmin, tmax)?;
        let mut best: Option<(f64, ObjectHit)> = None;
        let mut tbest = tb;
        dda2(ray, self.x0, self.y0, self.cell, self.nx, self.ny, ta, tb, |ix, iy, _t0, t1| {
            let c = iy * self.nx + ix;
            for &item in &self.items[self.offsets[c] as usize..self.offsets[c + 1] as usize] {
                if let Some((t, h)) = self.hit_one(self.decode(item), ray, tmin, tbest) {
                    if t < tbest {
                        tbest = t;
                        best = Some((t, h));
                    }
                }
            }
            (tbest <= t1).then_some(())
        });
        best
    }

    /// Closest hit of one tube only (ignores everything else), `t ∈ [tmin, tmax]`.
    pub fn intersect_tube(&self, i: usize, ray: &Ray, tmin: f64, tmax: f64) -> Option<f64> {
        self.hit_one(Id::Tube(i), ray, tmin, tmax).map(|(t, _)| t)
    }

    fn hit_one(&self, id: Id, ray: &Ray, tmin: f64, tmax: f64) -> Option<(f64, ObjectHit)> {
        let (lo, hi) = self.bounds_of(id);
        clip_aabb(ray, lo, hi, tmin, tmax)?;
        match id {
            Id::Rock(i) => self.rocks[i].intersect(ray, tmin, tmax).map(|(t, f)| (t, ObjectHit::Rock(i, f))),
            Id::Tube(i) => {
                let tube = &self.tubes[i];
                let inv = tube.t_world_tube.inverse();
                let o = inv.transform_point(&ray.origin);
                let d = inv.transform_vector(&ray.dir);
                tube.shape.intersect(&o, &d, tmin, tmax).map(|h| (h.t, ObjectHit::Tube(i, h.material, tube.t_world_tube.transform_vector(&h.normal))))
            }
            Id::Plate(i) => {
                let p = &self.plates[i];
                let inv = p.t_world_box.inverse();
                let o = inv.transform_point(&ray.origin);
                let d = inv.transform_vector(&ray.dir);
                let local = Ray { origin: o, dir: d };
                let h = p.half;
                let (t0, _) = clip_aabb(&local, [-h.x, -h.y, -h.z], [h.x, h.y, h.z], tmin, tmax)?;
                let q = local.at(t0);
                // Normal: the face whose slab was entered last.
                let rel = [q.x / h.x, q.y / h.y, q.z / h.z];
                let k = (0..3).max_by(|&a, &b| rel[a].abs().total_cmp(&rel[b].abs())).unwrap_or(2);
                let mut n = Vector3::zeros();
                n[k] = rel[k].signum();
                Some((t0, ObjectHit::Plate(i, q, p.t_world_box.transform_vector(&n))))
            }
        }
    }
}
