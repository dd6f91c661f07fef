//! Test scene renderer (test code only): a shaded sample tube (coaxial cylinders, gold seal
//! section) lying on a noisy textured ground plane, sun shadows, optional occluding sphere
//! ("rock"), 2x2 supersampling, Gaussian pixel noise. Intensities in [0, 1].
#![allow(dead_code)]

use nalgebra::{Point2, Point3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use tubeloc_core::{CameraModel, Distortion, Plane, TubeModel};
use tubeloc_refine::CylinderModel;

/// Ground truth of one rendered tube.
#[derive(Clone, Copy, Debug)]
pub struct Truth {
    pub centre: Vector3<f64>,
    /// Unit axis toward the seal end.
    pub axis: Vector3<f64>,
}

pub struct Scene {
    pub camera: CameraModel,
    pub image: Plane<f32>,
    pub depth: Plane<f32>,
    pub truth: Truth,
    /// Ground plane: normal (up) and offset, camera frame.
    pub ground_n: Vector3<f64>,
    pub ground_d: f64,
    pub rock: Option<(Vector3<f64>, f64)>,
}

/// The camera: a 1024x768 crop of a 20 MP, 77 degree camera (fx ≈ 3440 px), optionally with
/// lens distortion and an off-centre principal point.
pub fn camera(distorted: bool) -> CameraModel {
    let full = CameraModel::from_hfov(5472, 3648, 77.0);
    let mut c = if distorted { full.cropped(3900, 500, 1024, 768) } else { full.cropped(2224, 1440, 1024, 768) };
    if distorted {
        c.distortion = Distortion { k1: -0.08, k2: 0.02, p1: 0.0005, p2: -0.0003, k3: 0.0 };
    }
    c
}

fn hash(ix: i64, iy: i64, seed: u64) -> f64 {
    let mut h = (ix as u64).wrapping_mul(0x9E3779B97F4A7C15) ^ (iy as u64).wrapping_mul(0xC2B2AE3D27D4EB4F) ^ seed;
    h ^= h >> 31;
    h = h.wrapping_mul(0xBF58476D1CE4E5B9);
    h ^= h >> 29;
    (h >> 11) as f64 / (1u64 << 53) as f64
}

fn value_noise(x: f64, y: f64, seed: u64) -> f64 {
    let (ix, iy) = (x.floor() as i64, y.floor() as i64);
    let (fx, fy) = (x - x.floor(), y - y.floor());
    let s = |t: f64| t * t * (3.0 - 2.0 * t);
    let (sx, sy) = (s(fx), s(fy));
    let a = hash(ix, iy, seed) * (1.0 - sx) + hash(ix + 1, iy, seed) * sx;
    let b = hash(ix, iy + 1, seed) * (1.0 - sx) + hash(ix + 1, iy + 1, seed) * sx;
    a * (1.0 - sy) + b * sy
}

/// Ground texture at a ground point (metres): multi-octave value noise, 0.25..0.6.
fn ground_albedo(p: &Vector3<f64>, seed: u64) -> f64 {
    let (u, v) = (p.x * 40.0, p.z * 40.0 + p.y * 40.0);
    let mut a = 0.0;
    let mut w = 0.5;
    let mut f = 1.0;
    for o in 0..4 {
        a += w * value_noise(u * f, v * f, seed + o);
        w *= 0.5;
        f *= 2.1;
    }
    0.25 + 0.35 * a / 0.94
}

/// Ray from the origin along `d` (unit) vs the tube; returns (t, normal, albedo).
fn hit_tube(model: &CylinderModel, t: &Truth, d: &Vector3<f64>) -> Option<(f64, Vector3<f64>, f64)> {
    let a = t.axis;
    let w = -t.centre;
    let (da, wa) = (d.dot(&a), w.dot(&a));
    let dp = d - a * da;
    let wp = w - a * wa;
    let mut best: Option<(f64, Vector3<f64>, f64)> = None;
    let nsec = model.sections.len();
    for (i, s) in model.sections.iter().enumerate() {
        let albedo = if i == nsec - 1 { 0.45 } else { 0.85 };
        let qa = dp.dot(&dp);
        let qb = 2.0 * wp.dot(&dp);
        let qc = wp.dot(&wp) - s.r * s.r;
        let disc = qb * qb - 4.0 * qa * qc;
        if disc >= 0.0 && qa > 1e-15 {
            let tt = (-qb - disc.sqrt()) / (2.0 * qa);
            let z = wa + tt * da;
            if tt > 0.0 && z >= s.z0 && z <= s.z1 && best.is_none_or(|b| tt < b.0) {
                let n = (wp + dp * tt).normalize();
                best = Some((tt, n, albedo));
            }
        }
        if da.abs() > 1e-12 {
            for (z, sgn) in [(s.z0, -1.0), (s.z1, 1.0)] {
                let tt = (z - wa) / da;
                if tt > 0.0 && (wp + dp * tt).norm() <= s.r && best.is_none_or(|b| tt < b.0) {
                    best = Some((tt, a * sgn, albedo));
                }
            }
        }
    }
    best
}

fn hit_sphere(c: &Vector3<f64>, r: f64, o: &Vector3<f64>, d: &Vector3<f64>) -> Option<f64> {
    let w = o - c;
    let b = w.dot(d);
    let cc = w.dot(&w) - r * r;
    let disc = b * b - cc;
    if disc < 0.0 {
        return None;
    }
    let t = -b - disc.sqrt();
    (t > 1e-9).then_some(t)
}

/// Random tube pose on the ground in front of a camera looking down at ~45 degrees.
/// Returns the scene parameters (no image yet).
pub fn random_truth(rng: &mut ChaCha8Rng, model: &CylinderModel, camera: &CameraModel, dist: (f64, f64)) -> (Truth, Vector3<f64>, f64) {
    // Camera tilted down by 45 deg: world up in the camera frame.
    let tilt = rng.random_range(35f64..55.0).to_radians();
    let up = Vector3::new(0.0, -tilt.cos(), -tilt.sin());
    // Pick a pixel near the middle of the crop and a range; the tube centre lies there.
    let px = Point2::new(rng.random_range(0.35..0.65) * camera.width as f64, rng.random_range(0.35..0.65) * camera.height as f64);
    let ray = camera.unproject(&px);
    let range = rng.random_range(dist.0..dist.1);
    let centre = ray * range;
    // Ground below the tube by the mean of the two end radii (roughly resting on both ends).
    let h = model.max_radius();
    let ground_d = up.dot(&centre) - h;
    // Axis in the ground plane at a random heading.
    let e1 = up.cross(&Vector3::x()).normalize();
    let e2 = up.cross(&e1);
    let th = rng.random_range(0.0..std::f64::consts::TAU);
    let axis = e1 * th.cos() + e2 * th.sin();
    (Truth { centre, axis }, up, ground_d)
}

/// Renders the scene. `rock`: optional occluding sphere (centre, radius), camera frame.
#[allow(clippy::too_many_arguments)]
pub fn render(model: &CylinderModel, camera: &CameraModel, truth: Truth, up: Vector3<f64>, ground_d: f64, rock: Option<(Vector3<f64>, f64)>, seed: u64, noise: f64) -> Scene {
    render_at(model, camera, truth, up, ground_d, rock, seed, noise, Vector3::zeros())
}

/// The right view of a rectified pair: the same scene (given in the left camera frame) seen by
/// a camera at `(baseline, 0, 0)` with the left camera's orientation and intrinsics; the ground
/// texture stays attached to the ground. The returned scene is in the right camera's frame.
#[allow(clippy::too_many_arguments)]
pub fn render_right(model: &CylinderModel, camera: &CameraModel, truth: Truth, up: Vector3<f64>, ground_d: f64, seed: u64, noise: f64, baseline: f64) -> Scene {
    let t = Vector3::new(baseline, 0.0, 0.0);
    let tr = Truth { centre: truth.centre - t, axis: truth.axis };
    render_at(model, camera, tr, up, ground_d - up.dot(&t), None, seed, noise, t)
}

/// [`render_right`] with an occluding sphere `rock` (centre, radius; left camera frame).
#[allow(clippy::too_many_arguments, dead_code)]
pub fn render_right_rock(model: &CylinderModel, camera: &CameraModel, truth: Truth, up: Vector3<f64>, ground_d: f64, rock: (Vector3<f64>, f64), seed: u64, noise: f64, baseline: f64) -> Scene {
    let t = Vector3::new(baseline, 0.0, 0.0);
    let tr = Truth { centre: truth.centre - t, axis: truth.axis };
    render_at(model, camera, tr, up, ground_d - up.dot(&t), Some((rock.0 - t, rock.1)), seed, noise, t)
}

#[allow(clippy::too_many_arguments)]
fn render_at(model: &CylinderModel, camera: &CameraModel, truth: Truth, up: Vector3<f64>, ground_d: f64, rock: Option<(Vector3<f64>, f64)>, seed: u64, noise: f64, texture_offset: Vector3<f64>) -> Scene {
    let (w, h) = (camera.width as usize, camera.height as usize);
    let sun = (up * 0.8 + Vector3::new(0.5, 0.1, -0.3)).normalize();
    let mut img = vec![0f32; w * h];
    let mut depth = vec![f32::INFINITY; w * h];
    let shade = |d: &Vector3<f64>| -> (f64, f64) {
        let mut best_t = f64::INFINITY;
        let mut val = 0.0;
        if let Some((t, n, alb)) = hit_tube(model, &truth, d) {
            best_t = t;
            val = alb * (0.35 + 0.65 * n.dot(&sun).max(0.0));
        }
        if let Some((rc, rr)) = rock {
            if let Some(t) = hit_sphere(&rc, rr, &Vector3::zeros(), d) {
                if t < best_t {
                    best_t = t;
                    let n = (d * t - rc).normalize();
                    val = 0.4 * (0.35 + 0.65 * n.dot(&sun).max(0.0));
                }
            }
        }
        let den = up.dot(d);
        if den.abs() > 1e-9 {
            let t = ground_d / den;
            if t > 0.0 && t < best_t {
                best_t = t;
                let p = d * t;
                let mut lit = 0.35 + 0.65 * up.dot(&sun).max(0.0);
                // Shadow of the tube: march toward the sun against the tube (shifted ray).
                let shifted = Truth { centre: truth.centre - p, axis: truth.axis };
                if hit_tube(model, &shifted, &sun).is_some() {
                    lit = 0.35;
                }
                val = ground_albedo(&(p + texture_offset), seed) * lit;
            }
        }
        (val, best_t)
    };
    let rows: Vec<(Vec<f32>, Vec<f32>)> = (0..h)
        .map(|y| {
            let mut r = vec![0f32; w];
            let mut dr = vec![f32::INFINITY; w];
            for x in 0..w {
                let mut acc = 0.0;
                for (sx, sy) in [(-0.25, -0.25), (0.25, -0.25), (-0.25, 0.25), (0.25, 0.25)] {
                    let d = camera.unproject(&Point2::new(x as f64 + sx, y as f64 + sy));
                    acc += shade(&d).0;
                }
                r[x] = (acc / 4.0) as f32;
                let d = camera.unproject(&Point2::new(x as f64, y as f64));
                let t = shade(&d).1;
                dr[x] = (t * d.z) as f32;
            }
            (r, dr)
        })
        .collect();
    for (y, (r, dr)) in rows.into_iter().enumerate() {
        img[y * w..(y + 1) * w].copy_from_slice(&r);
        depth[y * w..(y + 1) * w].copy_from_slice(&dr);
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5eed ^ texture_offset.x.to_bits());
    let nd = Normal::new(0.0, noise.max(1e-12)).unwrap();
    for v in &mut img {
        *v = (*v + nd.sample(&mut rng) as f32).clamp(0.0, 1.0);
    }
    Scene { camera: camera.clone(), image: Plane::from_vec(w, h, img), depth: Plane::from_vec(w, h, depth), truth, ground_n: up, ground_d, rock }
}

/// Simulated triangulated stereo points on the visible tube surface: pixels of the tube's
/// image (every `step` px), depth noise `σ_Z = Z² σ_d / (f B)` along the ray.
pub fn stereo_points(model: &CylinderModel, scene: &Scene, step: usize, sigma_disp_px: f64, baseline: f64, seed: u64) -> Vec<Point3<f64>> {
    let cam = &scene.camera;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = Normal::new(0.0, 1.0).unwrap();
    let mut out = Vec::new();
    for y in (0..cam.height as usize).step_by(step) {
        for x in (0..cam.width as usize).step_by(step) {
            let d = cam.unproject(&Point2::new(x as f64, y as f64));
            let Some((t, _, _)) = hit_tube(model, &scene.truth, &d) else { continue };
            let z_true = scene.depth.get(x, y) as f64;
            if (t * d.z - z_true).abs() > 1e-6 {
                continue; // hidden by a rock
            }
            let z = t * d.z;
            let sz = z * z * sigma_disp_px / (cam.fx * baseline);
            let zn = z + sz * n.sample(&mut rng);
            out.push(Point3::from(d * (zn / d.z)));
        }
    }
    out
}

pub fn default_model() -> CylinderModel {
    CylinderModel::new(&TubeModel::default()).unwrap()
}

/// Median and 90th percentile.
pub fn med_p90(v: &mut [f64]) -> (f64, f64) {
    v.sort_by(|a, b| a.total_cmp(b));
    let q = |p: f64| v[((v.len() - 1) as f64 * p).round() as usize];
    (q(0.5), q(0.9))
}

/// The tube's visible mask (pixel centres whose ray hits the tube first), like a perfect
/// segmenter's output.
pub fn tube_mask(model: &CylinderModel, scene: &Scene) -> tubeloc_core::BinaryMask {
    let cam = &scene.camera;
    tubeloc_core::BinaryMask::from_fn(cam.width as usize, cam.height as usize, |x, y| {
        let d = cam.unproject(&Point2::new(x as f64, y as f64));
        match hit_tube(model, &scene.truth, &d) {
            Some((t, _, _)) => (t * d.z - scene.depth.get(x, y) as f64).abs() < 1e-6,
            None => false,
        }
    })
}

/// A learned-segmenter-like detection of `mask`: the mask, its box, and the axis seed of its
/// pixels (principal axis), score 0.9.
pub fn mask_detection(mask: &tubeloc_core::BinaryMask) -> tubeloc_core::TubeDetection {
    use tubeloc_core::{AxisSeed, DetectionSource, Rle, TubeDetection};
    let mut det = TubeDetection::new(0, 0.9, mask.bbox(), DetectionSource::Learned);
    det.axis_seed = AxisSeed::from_pixels((0..mask.height).flat_map(|y| (0..mask.width).map(move |x| (x, y))).filter(|&(x, y)| mask.get(x, y)).map(|(x, y)| (x as f64, y as f64)));
    det.mask = Some(Rle::from_mask(mask));
    det
}

/// The mono speed scene of `benches/refine.rs` and `examples/refine_speed.rs`: the renderer's
/// scene with a tube at 1.1-1.3 m (random seed 21), the default refiner, and a seed 3 mm /
/// 2 degrees off the truth.
pub struct SpeedScene {
    pub scene: Scene,
    pub refiner: tubeloc_refine::Refiner,
    pub seed: tubeloc_refine::Seed,
}

/// Builds the [`SpeedScene`].
pub fn speed_scene() -> SpeedScene {
    use nalgebra::{Rotation3, Unit};
    use tubeloc_refine::{AxisState, RefineConfig, Refiner, Seed};
    let model = default_model();
    let cam = camera(false);
    let mut rng = ChaCha8Rng::seed_from_u64(21);
    let (truth, up, gd) = random_truth(&mut rng, &model, &cam, (1.1, 1.3));
    let scene = render(&model, &cam, truth, up, gd, None, 4242, 0.01);
    let refiner = Refiner::new(&TubeModel::default(), RefineConfig::default()).unwrap();
    let r = Rotation3::from_axis_angle(&Unit::new_normalize(Vector3::new(0.3, -0.5, 0.8)), 2f64.to_radians());
    let seed = Seed { state: AxisState { c: truth.centre + Vector3::new(0.003, -0.002, 0.003), a: r * truth.axis }, end_known: false };
    SpeedScene { scene, refiner, seed }
}

impl SpeedScene {
    /// The refiner's input: the image alone (mono, no ground, no scene data).
    pub fn input(&self) -> tubeloc_refine::RefineInput<'_> {
        tubeloc_refine::RefineInput { image: &self.scene.image, camera: &self.scene.camera, ground: None, scene: tubeloc_refine::Scene::default() }
    }
}

/// The mask-seed speed scene of `benches/refine.rs` and `examples/refine_speed.rs`: a rendered
/// tube at a distance drawn from `range` (metres, random seed 21) and the mask detection of its
/// exact silhouette (the learned segmenter's kind of seed: mask, axis seed, no template pose).
pub fn mask_seed_scene(range: (f64, f64)) -> (Scene, tubeloc_core::TubeDetection) {
    let model = default_model();
    let cam = camera(false);
    let mut rng = ChaCha8Rng::seed_from_u64(21);
    let (truth, up, gd) = random_truth(&mut rng, &model, &cam, range);
    let scene = render(&model, &cam, truth, up, gd, None, 4242, 0.01);
    let det = mask_detection(&tube_mask(&model, &scene));
    (scene, det)
}

impl Scene {
    /// The ground plane the tube rests on (camera frame).
    pub fn ground(&self) -> tubeloc_refine::GroundPlane {
        tubeloc_refine::GroundPlane { normal: self.ground_n, offset: self.ground_d }
    }

    /// The refiner's input for a mask seed: the image with the scene's ground plane (the path of
    /// `tubeloc refine --detections --ground auto`).
    pub fn ground_input(&self) -> tubeloc_refine::RefineInput<'_> {
        tubeloc_refine::RefineInput { image: &self.image, camera: &self.camera, ground: Some(self.ground()), scene: tubeloc_refine::Scene::default() }
    }
}
