//! Rocks: faceted convex polytopes cut from an ellipsoid, and Golombek rock-size sampling.
//!
//! A rock is the intersection of `K` half-spaces `n_k · x ≤ d_k` tangent to an ellipsoid with
//! semi-axes `(a, b, c)` (support distance `d = sqrt(a²n_x² + b²n_y² + c²n_z²)`), each pushed
//! inward by a random amount, which gives the angular facets of real rocks. Ray intersection is
//! the exact slab clip `t_near = max(entering), t_far = min(leaving)`.
//!
//! Rock sizes follow Golombek & Rapp's model of the cumulative fractional area covered by rocks
//! of diameter ≥ D: `F_k(D) = k · exp(−q(k) · D)` with `q(k) = 1.79 + 0.152 / k` (D in metres).

use crate::ray::Ray;
use nalgebra::{Point3, Rotation3, Vector3};
use rand::Rng;

/// `q(k) = 1.79 + 0.152 / k` of the Golombek model (1/m).
pub fn golombek_q(k: f64) -> f64 {
    1.79 + 0.152 / k
}

/// Cumulative fractional area covered by rocks of diameter ≥ `d` metres: `k e^{−q(k) d}`.
pub fn golombek_cfa(k: f64, d: f64) -> f64 {
    k * (-golombek_q(k) * d).exp()
}

/// Draws rock diameters (metres) for a scene of `area` m² with rock abundance `k` (0.06 for
/// CFA6), restricted to `[d_min, d_max]`. The expected number of rocks with diameter in
/// `[D, D + dD]` is `area · (−dF/dD) / (π D² / 4) · dD`; diameters are drawn by inverting the
/// cumulative count `N(≥ D)` (tabulated on a fine grid) with uniform variates, and the total
/// count is Poisson-free (rounded expectation) so that the covered area matches `F_k`.
pub fn sample_golombek_diameters<R: Rng>(rng: &mut R, k: f64, area: f64, d_min: f64, d_max: f64) -> Vec<f64> {
    let q = golombek_q(k);
    let n = 2000;
    let step = (d_max - d_min) / n as f64;
    // Cumulative count from d_max downward: N(≥ D).
    let mut cum = vec![0.0f64; n + 1];
    for i in (0..n).rev() {
        let d = d_min + (i as f64 + 0.5) * step;
        let density = area * k * q * (-q * d).exp() / (std::f64::consts::PI * d * d / 4.0);
        cum[i] = cum[i + 1] + density * step;
    }
    let total = cum[0];
    let count = total.round() as usize;
    let mut out = Vec::with_capacity(count);
    for _ in 0..count {
        let u: f64 = rng.random::<f64>() * total;
        // Find i with cum[i] >= u > cum[i+1] (cum decreasing).
        let (mut lo, mut hi) = (0usize, n);
        while hi - lo > 1 {
            let mid = (lo + hi) / 2;
            if cum[mid] >= u {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let frac = if cum[lo] > cum[lo + 1] { (cum[lo] - u) / (cum[lo] - cum[lo + 1]) } else { 0.5 };
        out.push(d_min + (lo as f64 + frac) * step);
    }
    out
}

/// A convex faceted rock in the world frame.
#[derive(Clone, Debug)]
pub struct Rock {
    /// Half-space normals (unit, world frame) and offsets: inside when `n · x ≤ d`.
    pub planes: Vec<(Vector3<f64>, f64)>,
    /// Axis-aligned bounds (world, metres).
    pub lo: [f64; 3],
    /// Axis-aligned bounds (world, metres).
    pub hi: [f64; 3],
    /// Linear RGB albedo of the rock.
    pub albedo: [f32; 3],
    /// Seed of the rock's surface texture.
    pub seed: u32,
}

impl Rock {
    /// Builds a rock of semi-axes `axes` (metres) centred at `centre`, yawed by `yaw` and
    /// tilted by `tilt` (radians), with `facets` random facets.
    pub fn new<R: Rng>(rng: &mut R, centre: Point3<f64>, axes: [f64; 3], yaw: f64, tilt: f64, facets: usize, albedo: [f32; 3]) -> Rock {
        let rot = Rotation3::from_euler_angles(tilt * rng.random_range(-1.0..1.0), tilt * rng.random_range(-1.0..1.0), yaw);
        let [a, b, c] = axes;
        let mut planes = Vec::with_capacity(facets + 6);
        let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        for i in 0..facets {
            let z = 1.0 - 2.0 * (i as f64 + rng.random_range(0.2..0.8)) / facets as f64;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let phi = golden * i as f64 + rng.random_range(-0.4..0.4);
            let n = Vector3::new(r * phi.cos(), r * phi.sin(), z).normalize();
            let support = (a * a * n.x * n.x + b * b * n.y * n.y + c * c * n.z * n.z).sqrt();
            let d = support * (1.0 - rng.random_range(0.0..0.18));
            planes.push((n, d));
        }
        // Bounding planes keep the polytope bounded whatever the random facets.
        for (n, d) in [(Vector3::x(), a), (-Vector3::x(), a), (Vector3::y(), b), (-Vector3::y(), b), (Vector3::z(), c), (-Vector3::z(), c)] {
            planes.push((n, d * 1.05));
        }
        let planes: Vec<(Vector3<f64>, f64)> = planes
            .into_iter()
            .map(|(n, d)| {
                let nw = rot * n;
                (nw, d + nw.dot(&centre.coords))
            })
            .collect();
        let ext = 1.05 * a.max(b).max(c) * 3f64.sqrt();
        let rad = [ext.min(1.05 * (a * a + b * b + c * c).sqrt()); 3];
        let lo = [centre.x - rad[0], centre.y - rad[1], centre.z - rad[2]];
        let hi = [centre.x + rad[0], centre.y + rad[1], centre.z + rad[2]];
        Rock { planes, lo, hi, albedo, seed: rng.random() }
    }

    /// Exact ray/polytope intersection over `[tmin, tmax]`: the entry parameter and the index
    /// of the entry facet. Rays starting inside the rock report no hit.
    #[inline]
    pub fn intersect(&self, ray: &Ray, tmin: f64, tmax: f64) -> Option<(f64, usize)> {
        let (mut t0, mut t1, mut face) = (f64::NEG_INFINITY, tmax, usize::MAX);
        for (k, (n, d)) in self.planes.iter().enumerate() {
            let denom = n.dot(&ray.dir);
            let dist = d - n.dot(&ray.origin.coords);
            if denom.abs() < 1e-15 {
                if dist < 0.0 {
                    return None;
                }
                continue;
            }
            let t = dist / denom;
            if denom < 0.0 {
                if t > t0 {
                    t0 = t;
                    face = k;
                }
            } else if t < t1 {
                t1 = t;
            }
            if t0 > t1 {
                return None;
            }
        }
        (t0 >= tmin && face != usize::MAX).then_some((t0, face))
    }

    /// True when the world point lies inside the rock.
    pub fn contains(&self, p: &Point3<f64>) -> bool {
        self.planes.iter().all(|(n, d)| n.dot(&p.coords) <= *d)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn golombek_sampling_reproduces_covered_area() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let (k, area, dmin, dmax) = (0.06, 400.0, 0.03, 1.0);
        let ds = sample_golombek_diameters(&mut rng, k, area, dmin, dmax);
        let covered: f64 = ds.iter().map(|d| std::f64::consts::PI * d * d / 4.0).sum::<f64>() / area;
        let expect = golombek_cfa(k, dmin) - golombek_cfa(k, dmax);
        assert!((covered - expect).abs() / expect < 0.15, "covered {covered}, expected {expect}");
        assert!(ds.iter().all(|&d| (dmin..=dmax).contains(&d)));
        assert!((golombek_q(0.06) - (1.79 + 0.152 / 0.06)).abs() < 1e-12);
    }

    #[test]
    fn rock_ray_hits_are_on_the_boundary() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let rock = Rock::new(&mut rng, Point3::new(0.0, 0.0, 0.0), [0.1, 0.07, 0.05], 0.3, 0.2, 24, [0.2; 3]);
        assert!(rock.contains(&Point3::origin()));
        let mut hits = 0;
        for i in 0..100 {
            let a = i as f64 * 0.37;
            let o = Point3::new(a.cos(), a.sin(), 0.3);
            let ray = Ray { origin: o, dir: (Point3::new(0.02 * a.sin(), 0.0, 0.0) - o).normalize() };
            if let Some((t, f)) = rock.intersect(&ray, 0.0, 10.0) {
                hits += 1;
                let p = ray.at(t);
                let (n, d) = rock.planes[f];
                assert!((n.dot(&p.coords) - d).abs() < 1e-9);
                assert!(!rock.contains(&ray.at(t - 1e-6)) && rock.contains(&ray.at(t + 1e-6)));
                assert!((0..3).all(|k| p[k] >= rock.lo[k] && p[k] <= rock.hi[k]));
            }
        }
        assert_eq!(hits, 100);
    }
}
