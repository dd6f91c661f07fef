//! `HeightField`: terrain heights on a regular grid with exact ray intersection.
//!
//! Vertex `(i, j)` sits at world `(x0 + i·cell, y0 + j·cell)` with height `h[j·nx + i]` (metres,
//! z up). Inside a cell the surface is the bilinear patch
//! `h(a, b) = h00 + (h10−h00)·a + (h01−h00)·b + (h00−h10−h01+h11)·a·b`, `a, b ∈ [0, 1]`, so a ray
//! `z(t) − h(a(t), b(t)) = 0` is a quadratic in `t`, solved exactly. Rays are accelerated by a
//! max-height per `TILE × TILE` tile: a DDA over tiles skips every tile whose maximum lies
//! below the ray's segment, then a DDA over the cells of the remaining tiles.

use crate::ray::{clip_aabb, dda2, Ray};
use nalgebra::Vector3;

/// Cells per tile side of the max-height acceleration grid.
pub const TILE: usize = 8;

/// A regular-grid height field with tile max-heights.
#[derive(Clone, Debug)]
pub struct HeightField {
    /// Vertices along x.
    pub nx: usize,
    /// Vertices along y.
    pub ny: usize,
    /// Grid spacing, metres.
    pub cell: f64,
    /// World x of vertex column 0, metres.
    pub x0: f64,
    /// World y of vertex row 0, metres.
    pub y0: f64,
    /// Heights, row-major `h[j * nx + i]`, metres.
    pub h: Vec<f32>,
    tile_max: Vec<f32>,
    ntx: usize,
    nty: usize,
    hmin: f64,
    hmax: f64,
}

impl HeightField {
    /// A flat field of `nx × ny` vertices at height `z`.
    pub fn flat(nx: usize, ny: usize, cell: f64, x0: f64, y0: f64, z: f32) -> Self {
        let mut hf = HeightField { nx, ny, cell, x0, y0, h: vec![z; nx * ny], tile_max: Vec::new(), ntx: 0, nty: 0, hmin: 0.0, hmax: 0.0 };
        hf.rebuild();
        hf
    }

    /// Recomputes the acceleration data; call after editing `h`.
    pub fn rebuild(&mut self) {
        let (ncx, ncy) = (self.nx - 1, self.ny - 1);
        self.ntx = ncx.div_ceil(TILE);
        self.nty = ncy.div_ceil(TILE);
        self.tile_max = vec![f32::MIN; self.ntx * self.nty];
        for j in 0..self.ny {
            let tj_lo = j.saturating_sub(1) / TILE;
            let tj_hi = (j / TILE).min(self.nty - 1);
            for i in 0..self.nx {
                let v = self.h[j * self.nx + i];
                let ti_lo = i.saturating_sub(1) / TILE;
                let ti_hi = (i / TILE).min(self.ntx - 1);
                for tj in tj_lo..=tj_hi {
                    for ti in ti_lo..=ti_hi {
                        let m = &mut self.tile_max[tj * self.ntx + ti];
                        if v > *m {
                            *m = v;
                        }
                    }
                }
            }
        }
        self.hmin = self.h.iter().fold(f32::MAX, |a, &b| a.min(b)) as f64;
        self.hmax = self.h.iter().fold(f32::MIN, |a, &b| a.max(b)) as f64;
    }

    /// World x extent end, metres.
    pub fn x1(&self) -> f64 {
        self.x0 + (self.nx - 1) as f64 * self.cell
    }
    /// World y extent end, metres.
    pub fn y1(&self) -> f64 {
        self.y0 + (self.ny - 1) as f64 * self.cell
    }
    /// Lowest and highest vertex height, metres.
    pub fn range(&self) -> (f64, f64) {
        (self.hmin, self.hmax)
    }

    #[inline]
    fn at(&self, i: usize, j: usize) -> f64 {
        self.h[j * self.nx + i] as f64
    }

    /// True when `(x, y)` lies inside the grid.
    pub fn contains(&self, x: f64, y: f64) -> bool {
        x >= self.x0 && y >= self.y0 && x <= self.x1() && y <= self.y1()
    }

    /// Bilinear height at world `(x, y)`, clamped to the border.
    pub fn height(&self, x: f64, y: f64) -> f64 {
        let u = ((x - self.x0) / self.cell).clamp(0.0, (self.nx - 1) as f64 - 1e-9);
        let v = ((y - self.y0) / self.cell).clamp(0.0, (self.ny - 1) as f64 - 1e-9);
        let (i, j) = (u.floor() as usize, v.floor() as usize);
        let (a, b) = (u - i as f64, v - j as f64);
        let (h00, h10, h01, h11) = (self.at(i, j), self.at(i + 1, j), self.at(i, j + 1), self.at(i + 1, j + 1));
        h00 + (h10 - h00) * a + (h01 - h00) * b + (h00 - h10 - h01 + h11) * a * b
    }

    /// Smooth unit normal at `(x, y)`: bilinear blend of central-difference vertex gradients.
    pub fn normal(&self, x: f64, y: f64) -> Vector3<f64> {
        let u = ((x - self.x0) / self.cell).clamp(0.0, (self.nx - 1) as f64 - 1e-9);
        let v = ((y - self.y0) / self.cell).clamp(0.0, (self.ny - 1) as f64 - 1e-9);
        let (i, j) = (u.floor() as usize, v.floor() as usize);
        let (a, b) = (u - i as f64, v - j as f64);
        let g = |i: usize, j: usize| -> (f64, f64) {
            let (il, ir) = (i.saturating_sub(1), (i + 1).min(self.nx - 1));
            let (jl, jr) = (j.saturating_sub(1), (j + 1).min(self.ny - 1));
            let gx = (self.at(ir, j) - self.at(il, j)) / ((ir - il).max(1) as f64 * self.cell);
            let gy = (self.at(i, jr) - self.at(i, jl)) / ((jr - jl).max(1) as f64 * self.cell);
            (gx, gy)
        };
        let (g00, g10, g01, g11) = (g(i, j), g(i + 1, j), g(i, j + 1), g(i + 1, j + 1));
        let w = [(1.0 - a) * (1.0 - b), a * (1.0 - b), (1.0 - a) * b, a * b];
        let gx = w[0] * g00.0 + w[1] * g10.0 + w[2] * g01.0 + w[3] * g11.0;
        let gy = w[0] * g00.1 + w[1] * g10.1 + w[2] * g01.1 + w[3] * g11.1;
        Vector3::new(-gx, -gy, 1.0).normalize()
    }

    /// First intersection of the ray with the surface for `t ∈ [tmin, tmax]`, or `None`.
    pub fn intersect(&self, ray: &Ray, tmin: f64, tmax: f64) -> Option<f64> {
        let lo = [self.x0, self.y0, self.hmin - 1e-6];
        let hi = [self.x1(), self.y1(), self.hmax + 1e-6];
        let (ta, tb) = clip_aabb(ray, lo, hi, tmin, tmax)?;
        let tile = TILE as f64 * self.cell;
        let (ncx, ncy) = (self.nx - 1, self.ny - 1);
        dda2(ray, self.x0, self.y0, tile, self.ntx, self.nty, ta, tb, |tx, ty, t0, t1| {
            let zmin = ray.at(t0).z.min(ray.at(t1).z);
            if zmin > self.tile_max[ty * self.ntx + tx] as f64 {
                return None;
            }
            // Cell DDA inside this tile, over the tile's segment.
            let (cx0, cy0) = (tx * TILE, ty * TILE);
            let (cnx, cny) = ((ncx - cx0).min(TILE), (ncy - cy0).min(TILE));
            let ox = self.x0 + cx0 as f64 * self.cell;
            let oy = self.y0 + cy0 as f64 * self.cell;
            dda2(ray, ox, oy, self.cell, cnx, cny, t0, t1, |ci, cj, c0, c1| self.hit_cell(ray, cx0 + ci, cy0 + cj, c0, c1))
        })
    }

    /// Exact ray / bilinear-patch intersection inside cell `(i, j)` over `t ∈ [c0, c1]`.
    #[inline]
    fn hit_cell(&self, ray: &Ray, i: usize, j: usize, c0: f64, c1: f64) -> Option<f64> {
        let (h00, h10, h01, h11) = (self.at(i, j), self.at(i + 1, j), self.at(i, j + 1), self.at(i + 1, j + 1));
        let p0 = ray.at(c0);
        let z1 = p0.z + ray.dir.z * (c1 - c0);
        if p0.z.min(z1) > h00.max(h10).max(h01).max(h11) {
            return None;
        }
        let a0 = (p0.x - self.x0) / self.cell - i as f64;
        let b0 = (p0.y - self.y0) / self.cell - j as f64;
        let (da, db) = (ray.dir.x / self.cell, ray.dir.y / self.cell);
        let (bb, cc, dd) = (h10 - h00, h01 - h00, h00 - h10 - h01 + h11);
        let c = p0.z - (h00 + bb * a0 + cc * b0 + dd * a0 * b0);
        if c <= 0.0 {
            return Some(c0);
        }
        let l = ray.dir.z - bb * da - cc * db - dd * (a0 * db + b0 * da);
        let q = -dd * da * db;
        let len = c1 - c0;
        let root = smallest_root_in(q, l, c, len)?;
        Some(c0 + root)
    }
}

/// Smallest root of `q t² + l t + c = 0` in `[0, len]` (with `c > 0`), or `None`.
#[inline]
fn smallest_root_in(q: f64, l: f64, c: f64, len: f64) -> Option<f64> {
    if q.abs() < 1e-12 {
        if l >= 0.0 {
            return None;
        }
        let t = -c / l;
        return (t <= len).then_some(t);
    }
    let disc = l * l - 4.0 * q * c;
    if disc < 0.0 {
        return None;
    }
    let s = disc.sqrt();
    let k = -0.5 * (l + l.signum() * s);
    let (mut r0, mut r1) = (k / q, if k != 0.0 { c / k } else { f64::INFINITY });
    if r0 > r1 {
        std::mem::swap(&mut r0, &mut r1);
    }
    if r0 >= 0.0 && r0 <= len {
        Some(r0)
    } else if r1 >= 0.0 && r1 <= len {
        Some(r1)
    } else {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;

    fn wavy() -> HeightField {
        let mut hf = HeightField::flat(201, 161, 0.01, -1.0, -0.8, 0.0);
        for j in 0..hf.ny {
            for i in 0..hf.nx {
                let (x, y) = (hf.x0 + i as f64 * hf.cell, hf.y0 + j as f64 * hf.cell);
                hf.h[j * hf.nx + i] = (0.05 * (3.0 * x).sin() * (2.0 * y).cos()) as f32;
            }
        }
        hf.rebuild();
        hf
    }

    #[test]
    fn ray_hits_lie_on_the_surface_and_agree_with_brute_force() {
        let hf = wavy();
        for k in 0..200 {
            let a = k as f64 * 0.7;
            let origin = Point3::new(1.5 * a.cos(), 1.2 * a.sin(), 1.0 + 0.3 * (k % 3) as f64);
            let target = Point3::new(0.3 * (a * 1.3).sin(), 0.2 * (a * 0.9).cos(), 0.0);
            let ray = Ray { origin, dir: (target - origin).normalize() };
            let t = hf.intersect(&ray, 0.0, 10.0).expect("ray toward the centre must hit");
            let p = ray.at(t);
            assert!((p.z - hf.height(p.x, p.y)).abs() < 1e-9, "off surface at {p:?}");
            // No earlier crossing: march finely before t.
            let mut s = 0.0;
            while s < t - 1e-3 {
                let q = ray.at(s);
                if hf.contains(q.x, q.y) {
                    assert!(q.z > hf.height(q.x, q.y) - 1e-9, "missed earlier hit at s={s}, t={t}");
                }
                s += 1e-3;
            }
        }
        let up = Ray { origin: Point3::new(0.0, 0.0, 0.5), dir: Vector3::z() };
        assert!(hf.intersect(&up, 0.0, 10.0).is_none());
        let n = hf.normal(0.0, 0.0);
        assert!((n.norm() - 1.0).abs() < 1e-12 && n.z > 0.9);
    }
}
