//! Per-pixel ray casting of a [`Scene`] through a [`CameraModel`], with hard sun shadows, a
//! sky term and the sensor model; also exact per-pixel ground truth (tube instance, depth,
//! surface kind).
//!
//! Shading of a surface point with unit normal `n`, albedo `ρ`, sun direction `s`:
//! `L = exposure · (ρ · (E_sun · max(0, n·s) · lit + E_sky · V) + k_s · (n·h)^p · lit · E_sun)`,
//! `lit` ∈ {0, 1} from a shadow ray toward the sun against terrain, rocks, tubes and plates,
//! `V` the sky visibility (horizon-scanned for the ground, `0.55 + 0.45 n_z` on objects),
//! `h` the half vector between `s` and the view direction (specular on tubes and plates only).

use crate::noise::value2;
use crate::objects::ObjectHit;
use crate::ray::Ray;
use crate::scene::{sand, Scene};
use crate::sensor::{develop, SensorOptions};
use crate::terrain::srgb_to_linear;
use nalgebra::{Point2, Point3, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use tubeloc_core::{CameraModel, Plane, Pose, TubeMaterial};

/// Kind of surface seen at a pixel (primary ray).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[repr(u8)]
pub enum SurfaceKind {
    /// Nothing: sky.
    Sky = 0,
    /// Terrain (regolith, slabs) or far ground.
    Ground = 1,
    /// A rock.
    Rock = 2,
    /// A tube (see the instance plane for which).
    Tube = 3,
    /// A tag-mount plate.
    Plate = 4,
    /// Sand mound over a tube.
    SandMound = 5,
    /// Dune along a tube.
    Dune = 6,
    /// Sand over the tag mount.
    MountSand = 7,
}

impl SurfaceKind {
    /// From the byte stored in [`RenderOutput::surface`].
    pub fn from_u8(v: u8) -> SurfaceKind {
        match v {
            1 => SurfaceKind::Ground,
            2 => SurfaceKind::Rock,
            3 => SurfaceKind::Tube,
            4 => SurfaceKind::Plate,
            5 => SurfaceKind::SandMound,
            6 => SurfaceKind::Dune,
            7 => SurfaceKind::MountSand,
            _ => SurfaceKind::Sky,
        }
    }
}

/// Rendering options.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct RenderOptions {
    /// Cast shadow rays toward the sun.
    pub shadows: bool,
    /// Sensor model (blur, noise).
    pub sensor: SensorOptions,
    /// Linear gain applied before the sensor.
    pub exposure: f32,
    /// Seed of the sensor noise.
    pub noise_seed: u64,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions { shadows: true, sensor: SensorOptions::default(), exposure: 0.72, noise_seed: 0 }
    }
}

/// A rendered image and its exact ground truth, all `width × height`, row-major.
#[derive(Clone, Debug)]
pub struct RenderOutput {
    /// Width, pixels.
    pub width: usize,
    /// Height, pixels.
    pub height: usize,
    /// sRGB colour, 3 bytes per pixel.
    pub rgb: Vec<u8>,
    /// Depth along the camera's optical axis (camera z), metres; `+inf` for sky.
    pub depth: Plane<f32>,
    /// 0 where no tube is seen first, `i + 1` where tube `i` is the first hit.
    pub instance: Plane<u16>,
    /// [`SurfaceKind`] byte of the first hit.
    pub surface: Plane<u8>,
}

/// Linear light of one pixel and its ground truth.
struct Sample {
    rgb: [f32; 3],
    depth_t: f64,
    instance: u16,
    surface: SurfaceKind,
}

/// First hit of a ray: terrain or object.
enum Hit {
    Ground,
    Far,
    Object(ObjectHit),
}

/// Casts the closest hit of `ray` in the scene for `t ∈ [tmin, tmax]`.
fn cast(scene: &Scene, ray: &Ray, tmin: f64, tmax: f64) -> Option<(f64, Hit)> {
    let tg = scene.hf.intersect(ray, tmin, tmax);
    let limit = tg.unwrap_or(tmax);
    if let Some((t, h)) = scene.objects.intersect(ray, tmin, limit) {
        return Some((t, Hit::Object(h)));
    }
    if let Some(t) = tg {
        return Some((t, Hit::Ground));
    }
    // Beyond the height field: a flat plane at the border level.
    if ray.dir.z < -1e-6 {
        let z = scene.hf.height(scene.hf.x1(), scene.hf.y1()).min(0.0);
        let t = (z - ray.origin.z) / ray.dir.z;
        let p = ray.at(t);
        if t > tmin && t < tmax && !scene.hf.contains(p.x, p.y) {
            return Some((t, Hit::Far));
        }
    }
    None
}

/// True when the point sees the sun.
fn sunlit(scene: &Scene, p: &Point3<f64>, n: &Vector3<f64>, sun: &Vector3<f64>) -> bool {
    let ray = Ray { origin: p + n * 2e-4 + sun * 1e-4, dir: *sun };
    if scene.hf.intersect(&ray, 0.0, 20.0).is_some() {
        return false;
    }
    scene.objects.intersect(&ray, 0.0, 20.0).is_none()
}

struct Lut([f32; 256]);

impl Lut {
    fn new() -> Lut {
        let mut t = [0.0f32; 256];
        for (i, v) in t.iter_mut().enumerate() {
            *v = srgb_to_linear([i as u8, 0, 0])[0];
        }
        Lut(t)
    }
}

fn ground_albedo(scene: &Scene, lut: &Lut, x: f64, y: f64) -> ([f32; 3], u8) {
    let hf = &scene.hf;
    let u = ((x - hf.x0) / hf.cell).clamp(0.0, (hf.nx - 1) as f64 - 1e-9);
    let v = ((y - hf.y0) / hf.cell).clamp(0.0, (hf.ny - 1) as f64 - 1e-9);
    let (i, j) = (u as usize, v as usize);
    let (a, b) = ((u - i as f64) as f32, (v - j as f64) as f32);
    let n = hf.nx;
    let c = [scene.albedo[j * n + i], scene.albedo[j * n + i + 1], scene.albedo[(j + 1) * n + i], scene.albedo[(j + 1) * n + i + 1]];
    let w = [(1.0 - a) * (1.0 - b), a * (1.0 - b), (1.0 - a) * b, a * b];
    let mut out = [0.0f32; 3];
    for k in 0..4 {
        for ch in 0..3 {
            out[ch] += w[k] * lut.0[c[k][ch] as usize];
        }
    }
    let nearest = c[(if a > 0.5 { 1 } else { 0 }) + (if b > 0.5 { 2 } else { 0 })][3];
    // Pixel-scale grain: value noise at 3 mm, 1 cm and 4 cm.
    let s = scene.terrain.seed;
    let (xf, yf) = (x as f32, y as f32);
    let g = 1.0 + 0.16 * value2(xf / 0.003, yf / 0.003, s ^ 0x101) + 0.10 * value2(xf / 0.01, yf / 0.01, s ^ 0x202) + 0.07 * value2(xf / 0.04, yf / 0.04, s ^ 0x303);
    (out.map(|v| v * g), nearest)
}

const SUN_RGB: [f32; 3] = [1.0, 0.97, 0.92];
const SKY_RGB: [f32; 3] = [0.22, 0.25, 0.30];

fn tube_albedo(material: TubeMaterial) -> ([f32; 3], f32, f32) {
    // (albedo, specular strength, shininess)
    match material {
        TubeMaterial::Alumina => ([0.78, 0.79, 0.75], 0.12, 18.0),
        TubeMaterial::Gold => ([0.45, 0.28, 0.05], 0.55, 40.0),
        TubeMaterial::Titanium => ([0.45, 0.46, 0.48], 0.4, 30.0),
        TubeMaterial::Plastic => ([0.05, 0.05, 0.05], 0.1, 10.0),
    }
}

/// Shades the primary ray of one pixel.
fn shade(scene: &Scene, lut: &Lut, ray: &Ray, opts: &RenderOptions) -> Sample {
    let sun = scene.sun.direction();
    let Some((t, hit)) = cast(scene, ray, 0.0, 500.0) else {
        // Sky: pale at the horizon, deeper toward the zenith.
        let e = ray.dir.z.max(0.0) as f32;
        let sky = [0.62 - 0.35 * e, 0.70 - 0.30 * e, 0.80 - 0.15 * e];
        return Sample { rgb: sky, depth_t: f64::INFINITY, instance: 0, surface: SurfaceKind::Sky };
    };
    let p = ray.at(t);
    let view = -ray.dir;
    let (albedo, n, surface, instance, spec, ao) = match hit {
        Hit::Far => {
            let (xf, yf) = (p.x as f32, p.y as f32);
            let g = 1.0 + 0.1 * value2(xf / 0.5, yf / 0.5, 17);
            let alb = srgb_to_linear(crate::terrain::REGOLITH_SRGB).map(|c| c * g);
            (alb, Vector3::z(), SurfaceKind::Ground, 0u16, None, 1.0f32)
        }
        Hit::Ground => {
            let (alb, label) = ground_albedo(scene, lut, p.x, p.y);
            let kind = match label {
                sand::MOUND => SurfaceKind::SandMound,
                sand::DUNE => SurfaceKind::Dune,
                sand::MOUNT_COVER => SurfaceKind::MountSand,
                _ => SurfaceKind::Ground,
            };
            (alb, scene.hf.normal(p.x, p.y), kind, 0, None, scene.sky_at(p.x, p.y))
        }
        Hit::Object(ObjectHit::Rock(i, f)) => {
            let rock = &scene.objects.rocks[i];
            let n = rock.planes[f].0;
            let (xf, yf, zf) = (p.x as f32, p.y as f32, p.z as f32);
            let g = 1.0 + 0.18 * value2((xf + 0.7 * zf) / 0.004, (yf - 0.5 * zf) / 0.004, rock.seed) + 0.12 * value2((xf - 0.3 * zf) / 0.015, (yf + 0.6 * zf) / 0.015, rock.seed ^ 1);
            let dusty = (0.35 * n.z.max(0.0) as f32) * (0.5 + 0.5 * value2(xf / 0.02, yf / 0.02, rock.seed ^ 2));
            let reg = srgb_to_linear(crate::terrain::REGOLITH_SRGB);
            let alb = [0, 1, 2].map(|k| (rock.albedo[k] * g) * (1.0 - dusty) + reg[k] * dusty);
            (alb, n, SurfaceKind::Rock, 0, None, 0.55 + 0.45 * n.z.max(-1.0) as f32)
        }
        Hit::Object(ObjectHit::Tube(i, material, n)) => {
            let tube = &scene.objects.tubes[i];
            let (mut alb, ks, shin) = tube_albedo(material);
            let (xf, yf, zf) = (p.x as f32, p.y as f32, p.z as f32);
            let patch = 0.7 + 0.6 * (0.5 + 0.5 * value2((xf + zf) / 0.006, (yf - zf) / 0.006, tube.seed));
            let d = (tube.dust * (0.55 + 0.45 * n.z.max(0.0) as f32) * patch).clamp(0.0, 1.0);
            let reg = srgb_to_linear(crate::terrain::REGOLITH_SRGB);
            alb = [0, 1, 2].map(|k| alb[k] * (1.0 - d) + reg[k] * 1.1 * d);
            (alb, n, SurfaceKind::Tube, (i + 1) as u16, Some((ks * (1.0 - d), shin)), 0.55 + 0.45 * n.z as f32)
        }
        Hit::Object(ObjectHit::Plate(i, q, n)) => {
            let plate = &scene.objects.plates[i];
            let alb = plate.albedo_at(&q);
            (alb, n, SurfaceKind::Plate, 0, Some((0.05, 8.0)), 0.55 + 0.45 * n.z as f32)
        }
    };
    let ndl = n.dot(&sun).max(0.0) as f32;
    let lit = if ndl > 0.0 && opts.shadows && !matches!(hit, Hit::Far) {
        if sunlit(scene, &p, &n, &sun) {
            1.0
        } else {
            0.0
        }
    } else if ndl > 0.0 {
        1.0
    } else {
        0.0
    };
    let mut rgb = [0.0f32; 3];
    for k in 0..3 {
        rgb[k] = albedo[k] * (SUN_RGB[k] * ndl * lit + SKY_RGB[k] * ao);
    }
    if let Some((ks, shin)) = spec {
        if lit > 0.0 {
            let h = (sun + view).normalize();
            let s = ks * (n.dot(&h).max(0.0) as f32).powf(shin);
            for k in 0..3 {
                rgb[k] += s * SUN_RGB[k];
            }
        }
    }
    if matches!(hit, Hit::Far) {
        let fog = 1.0 - (-(t as f32) / 40.0).exp();
        rgb = [0, 1, 2].map(|k| rgb[k] * (1.0 - fog) + [0.62, 0.70, 0.80][k] * fog);
    }
    Sample { rgb, depth_t: t, instance, surface }
}

/// World-frame ray through pixel `(u, v)` of `cam` at pose `t_world_cam`, and the factor that
/// turns the ray parameter into camera-z depth.
#[inline]
pub fn pixel_ray(cam: &CameraModel, t_world_cam: &Pose, u: f64, v: f64) -> (Ray, f64) {
    let (x, y) = cam.normalize(&Point2::new(u, v));
    let d_cam = Vector3::new(x, y, 1.0);
    let norm = d_cam.norm();
    let dir = t_world_cam.transform_vector(&(d_cam / norm));
    (Ray { origin: Point3::from(t_world_cam.translation()), dir }, 1.0 / norm)
}

/// Renders `scene` through `cam` (intrinsics of the image or crop to produce) at pose
/// `t_world_cam`: colour after the sensor model, and exact per-pixel ground truth.
pub fn render(scene: &Scene, cam: &CameraModel, t_world_cam: &Pose, opts: &RenderOptions) -> RenderOutput {
    let (w, h) = (cam.width as usize, cam.height as usize);
    let lut = Lut::new();
    let mut linear = vec![0.0f32; w * h * 3];
    let mut depth = Plane::filled(w, h, f32::INFINITY);
    let mut instance = Plane::<u16>::new(w, h);
    let mut surface = Plane::<u8>::new(w, h);
    linear.par_chunks_mut(w * 3).zip(depth.data.par_chunks_mut(w)).zip(instance.data.par_chunks_mut(w)).zip(surface.data.par_chunks_mut(w)).enumerate().for_each(|(y, (((lrow, drow), irow), srow))| {
        for x in 0..w {
            let (ray, zf) = pixel_ray(cam, t_world_cam, x as f64, y as f64);
            let s = shade(scene, &lut, &ray, opts);
            for k in 0..3 {
                lrow[x * 3 + k] = s.rgb[k] * opts.exposure;
            }
            drow[x] = (s.depth_t * zf) as f32;
            irow[x] = s.instance;
            srow[x] = s.surface as u8;
        }
    });
    let rgb = develop(&mut linear, w, h, &opts.sensor, opts.noise_seed);
    RenderOutput { width: w, height: h, rgb, depth, instance, surface }
}
