//! Rays and grid traversal shared by the height field, the object grid and the renderer.

use nalgebra::{Point3, Vector3};

/// A ray `p(t) = origin + t · dir` in the world frame (metres); `dir` need not be unit length
/// but renderers pass unit vectors so that `t` is a distance.
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    /// Start point, world frame, metres.
    pub origin: Point3<f64>,
    /// Direction, world frame.
    pub dir: Vector3<f64>,
}

impl Ray {
    /// Point at parameter `t`.
    #[inline]
    pub fn at(&self, t: f64) -> Point3<f64> {
        self.origin + self.dir * t
    }
}

/// Clips the ray against an axis-aligned box (slab method); returns the parameter interval
/// `[t0, t1]` intersected with `[tmin, tmax]`, or `None` when the ray misses.
#[inline]
pub fn clip_aabb(ray: &Ray, lo: [f64; 3], hi: [f64; 3], tmin: f64, tmax: f64) -> Option<(f64, f64)> {
    let (mut t0, mut t1) = (tmin, tmax);
    for k in 0..3 {
        let o = ray.origin[k];
        let d = ray.dir[k];
        if d.abs() < 1e-300 {
            if o < lo[k] || o > hi[k] {
                return None;
            }
        } else {
            let inv = 1.0 / d;
            let (mut a, mut b) = ((lo[k] - o) * inv, (hi[k] - o) * inv);
            if a > b {
                std::mem::swap(&mut a, &mut b);
            }
            t0 = t0.max(a);
            t1 = t1.min(b);
            if t0 > t1 {
                return None;
            }
        }
    }
    Some((t0, t1))
}

/// Walks the cells of a 2D grid (cell size `cell` metres, origin `(x0, y0)`, `nx × ny` cells)
/// crossed by the ray's horizontal projection between `t_start` and `t_end`, in order
/// (Amanatides–Woo DDA). Calls `visit(ix, iy, t_in, t_out)` per cell; stops early and returns
/// the first `Some` that `visit` gives.
#[allow(clippy::too_many_arguments)]
#[inline]
pub fn dda2<R>(ray: &Ray, x0: f64, y0: f64, cell: f64, nx: usize, ny: usize, t_start: f64, t_end: f64, mut visit: impl FnMut(usize, usize, f64, f64) -> Option<R>) -> Option<R> {
    if t_end < t_start {
        return None;
    }
    let p = ray.at(t_start);
    let fx = (p.x - x0) / cell;
    let fy = (p.y - y0) / cell;
    let mut ix = (fx.floor() as i64).clamp(0, nx as i64 - 1);
    let mut iy = (fy.floor() as i64).clamp(0, ny as i64 - 1);
    let (dx, dy) = (ray.dir.x, ray.dir.y);
    let step_x: i64 = if dx > 0.0 { 1 } else { -1 };
    let step_y: i64 = if dy > 0.0 { 1 } else { -1 };
    let big = f64::INFINITY;
    let (mut tmax_x, tdelta_x) = if dx.abs() < 1e-300 {
        (big, big)
    } else {
        let next = if dx > 0.0 { (ix + 1) as f64 } else { ix as f64 };
        (t_start + (x0 + next * cell - p.x) / dx, cell / dx.abs())
    };
    let (mut tmax_y, tdelta_y) = if dy.abs() < 1e-300 {
        (big, big)
    } else {
        let next = if dy > 0.0 { (iy + 1) as f64 } else { iy as f64 };
        (t_start + (y0 + next * cell - p.y) / dy, cell / dy.abs())
    };
    let mut t = t_start;
    loop {
        let t_out = tmax_x.min(tmax_y).min(t_end);
        if let Some(r) = visit(ix as usize, iy as usize, t, t_out) {
            return Some(r);
        }
        if t_out >= t_end {
            return None;
        }
        if tmax_x < tmax_y {
            ix += step_x;
            t = tmax_x;
            tmax_x += tdelta_x;
        } else {
            iy += step_y;
            t = tmax_y;
            tmax_y += tdelta_y;
        }
        if ix < 0 || iy < 0 || ix >= nx as i64 || iy >= ny as i64 {
            return None;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dda_visits_contiguous_cells_in_order() {
        let ray = Ray { origin: Point3::new(0.05, 0.05, 0.0), dir: Vector3::new(1.0, 0.5, 0.0).normalize() };
        let mut cells = Vec::new();
        let mut last_t = 0.0;
        dda2::<()>(&ray, 0.0, 0.0, 0.1, 10, 10, 0.0, 0.9, |ix, iy, t0, t1| {
            assert!((t0 - last_t).abs() < 1e-12 && t1 >= t0);
            last_t = t1;
            cells.push((ix, iy));
            None
        });
        assert_eq!(cells[0], (0, 0));
        for w in cells.windows(2) {
            let d = (w[1].0 as i64 - w[0].0 as i64).abs() + (w[1].1 as i64 - w[0].1 as i64).abs();
            assert_eq!(d, 1, "{cells:?}");
        }
        let end = ray.at(0.9);
        assert_eq!(*cells.last().unwrap(), ((end.x / 0.1) as usize, (end.y / 0.1) as usize));
    }

    #[test]
    fn aabb_clip() {
        let ray = Ray { origin: Point3::new(-1.0, 0.5, 0.5), dir: Vector3::x() };
        let (a, b) = clip_aabb(&ray, [0.0; 3], [1.0; 3], 0.0, 10.0).unwrap();
        assert!((a - 1.0).abs() < 1e-12 && (b - 2.0).abs() < 1e-12);
        assert!(clip_aabb(&ray, [0.0, 0.6, 0.0], [1.0; 3], 0.0, 10.0).is_none());
    }
}
