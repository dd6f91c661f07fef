//! Composite mode: synthetic tubes, with shadows, rendered onto a real photograph whose camera
//! and ground plane are known.
//!
//! The ground plane is given in the camera frame as `n · X + d = 0` (`n` unit, pointing toward
//! the camera side). A ground frame is built on it: origin at the point of the plane hit by
//! the optical axis (or the camera's foot point when the axis misses the plane), z = `n`,
//! x = the camera x axis projected on the plane. The sun is given in that ground frame by
//! azimuth (degrees from the camera's forward direction on the ground, positive toward the
//! camera's right) and elevation (degrees above the plane).
//!
//! Tube pixels are shaded like the benchmark renderer with an exposure matched to the photo
//! (the median linear intensity of the lower image half is taken as regolith in sunlight; the
//! photo's values are read as light, and the tubes written back, by its [`PhotoEncoding`]);
//! ground pixels in a tube's shadow are darkened by `E_sky / (E_sun cos θ + E_sky)`.
//! Colours use 2 × 2 samples per pixel at tube borders; the ground-truth masks use the pixel
//! centre ray, exactly as in the benchmark.
//!
//! The materials reflect in the [`SpectralBand`] of the camera that took the photo: sRGB
//! albedos for colour cameras, one albedo per material in 600-800 nm for the rovers'
//! monochrome engineering cameras, where the gold (TiN) seal is nearly as bright as the white
//! body (0.62 against 0.78) and both are about twice the regolith (0.34).

use crate::objects::{ObjectHit, Objects, TubeInstance};
use crate::ray::Ray;
use crate::render::{pixel_ray, RenderOutput, SurfaceKind};
use crate::scene::lying_rotation;
use crate::terrain::{linear_to_srgb8, srgb_to_linear, REGOLITH_SRGB};
use crate::truth::{projected_rect, tube_truth, TubeTruth};
use crate::tube_shape::TubeShape;
use crate::SynthError;
use nalgebra::{Matrix3, Rotation3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use std::sync::Arc;
use tubeloc_core::{CameraModel, Plane, Pose, TubeMaterial};

/// What to composite.
#[derive(Clone, Debug)]
pub struct CompositeConfig {
    /// Ground plane in the camera frame: unit normal `n` (toward the camera) and `d` (metres),
    /// `n · X + d = 0`.
    pub ground: (Vector3<f64>, f64),
    /// Sun azimuth and elevation in the ground frame, degrees.
    pub sun_az_el_deg: (f64, f64),
    /// Number of tubes to place.
    pub tubes: usize,
    /// Dust level of the tubes, [0, 1].
    pub dust: f32,
    /// Seed of the placement.
    pub seed: u64,
    /// Tube geometry.
    pub tube_shape: Arc<TubeShape>,
    /// Distance band from the camera centre, metres, within which tube centres are placed
    /// (`None`: anywhere on the ground in the lower two thirds of the image).
    pub range_m: Option<(f64, f64)>,
    /// Sun direction as a unit vector in the camera frame (toward the sun); overrides
    /// `sun_az_el_deg` when set (PDS labels give it this way).
    pub sun_cam: Option<Vector3<f64>>,
    /// Gain on the tubes' shaded radiance (1 = matched to the photo's exposure); appearance
    /// randomization for training sets.
    pub tube_gain: f32,
    /// Spectral band of the photo's camera: which albedos the tubes and the exposure use.
    pub band: SpectralBand,
    /// How the photo's pixel values relate to the light the camera received.
    pub encoding: PhotoEncoding,
}

/// How a photo's 8-bit pixel values `p` relate to the light `L` the camera received (linear,
/// 1 at the value 255): what the composite reads the photo's exposure in and writes its
/// tubes and shadows back in.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum PhotoEncoding {
    /// The sRGB transfer curve (about `p ∝ L^(1/2.2)`): JPEGs and browse products, whose
    /// square-root companding it approximates.
    #[default]
    Srgb,
    /// Linear with an offset, `p = black + L (255 - black)`: a linear stretch of a product's
    /// raw or radiance values, `black` (pixel units, negative where the stretch's low end is
    /// above zero) the value of no light.
    Linear {
        /// The pixel value of no light.
        black: f32,
    },
}

impl PhotoEncoding {
    /// The encoding of a linear stretch of data values `lo..hi` onto 0..255: no light (data
    /// value 0) is `black = -255 lo / (hi - lo)`. `None` unless `0 <= lo < hi`, finite.
    pub fn linear_stretch(lo: f64, hi: f64) -> Option<PhotoEncoding> {
        (lo.is_finite() && hi.is_finite() && lo >= 0.0 && hi > lo).then(|| PhotoEncoding::Linear { black: (-255.0 * lo / (hi - lo)) as f32 })
    }

    /// Light `L` of pixel value `p` (0-255).
    pub fn to_linear(self, p: u8) -> f32 {
        match self {
            PhotoEncoding::Srgb => srgb_to_linear([p, 0, 0])[0],
            PhotoEncoding::Linear { black } => (p as f32 - black) / (255.0 - black),
        }
    }

    /// The pixel value of light `l`, rounded and clipped to 0-255.
    pub fn to_pixel(self, l: f32) -> u8 {
        match self {
            PhotoEncoding::Srgb => linear_to_srgb8(l),
            PhotoEncoding::Linear { black } => ((black + l * (255.0 - black)).clamp(0.0, 255.0) + 0.5) as u8,
        }
    }
}

/// The spectral band a composite imitates: the band of the camera that took its photo.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum SpectralBand {
    /// Colour (sRGB primaries): each material's RGB albedo, regolith `REGOLITH_SRGB`.
    #[default]
    Visible,
    /// 600-800 nm, the band of the monochrome engineering cameras (MSL and MER Navcam and
    /// Hazcam; MER Pancam's 753 nm filter is inside it): one albedo per material in every
    /// channel ([`band_albedo`]), the regolith's that of its red channel (0.34).
    RedNir,
}

impl SpectralBand {
    /// The band of a photo: [`SpectralBand::RedNir`] for a grey one (the rovers' monochrome
    /// cameras image 600-800 nm), [`SpectralBand::Visible`] for a colour one.
    pub fn of_photo(grey: bool) -> Self {
        if grey {
            SpectralBand::RedNir
        } else {
            SpectralBand::Visible
        }
    }

    /// Linear albedo of the regolith in this band, per channel.
    fn regolith(self) -> [f32; 3] {
        let reg = srgb_to_linear(REGOLITH_SRGB);
        match self {
            SpectralBand::Visible => reg,
            SpectralBand::RedNir => [reg[0]; 3],
        }
    }
}

/// Linear albedo of a tube material in 600-800 nm ([`SpectralBand::RedNir`]): the white
/// alumina coating 0.78 (flat across the visible and near infrared, as its sRGB albedo);
/// the TiN seal 0.62, its normal reflectance `((n - 1)² + k²) / ((n + 1)² + k²)` = 0.59 from
/// `n` = 1.35, `k` = 2.76 at 633 nm (Pflüger et al. 1984), rising into the near infrared
/// past its plasma edge near 480 nm (in blue light it reflects about 0.2, hence its gold
/// colour); titanium 0.5; the black plastic cap 0.05.
pub fn band_albedo(mat: TubeMaterial) -> f32 {
    match mat {
        TubeMaterial::Alumina => 0.78,
        TubeMaterial::Gold => 0.62,
        TubeMaterial::Titanium => 0.5,
        TubeMaterial::Plastic => 0.05,
    }
}

/// The result: composited sRGB image, ground truth, and the frames used.
#[derive(Clone, Debug)]
pub struct Composite {
    /// Composited image and per-pixel truth (instance, depth, surface).
    pub output: RenderOutput,
    /// Per-tube truth.
    pub truth: Vec<TubeTruth>,
    /// Pose of the camera in the ground frame.
    pub t_ground_cam: Pose,
    /// Placed tubes (poses in the ground frame).
    pub tubes: Vec<TubeInstance>,
}

/// The ground frame of a plane given in the camera frame: returns `T_ground_cam`.
pub fn ground_frame(n: &Vector3<f64>, d: f64) -> Result<Pose, SynthError> {
    let nn = n.norm();
    if !(nn.is_finite() && nn > 1e-9 && d.is_finite()) {
        return Err(SynthError::Invalid(format!("ground plane ({}, {}, {}; {d}) needs a non-zero finite normal and finite d", n.x, n.y, n.z)));
    }
    let (mut n, mut d) = (n / nn, d / nn);
    if d < 0.0 {
        // Orient the normal toward the camera (camera origin on the positive side).
        n = -n;
        d = -d;
    }
    if d < 1e-6 {
        return Err(SynthError::Invalid("the camera lies on the ground plane".into()));
    }
    let z_axis = Vector3::z();
    let denom = n.dot(&z_axis);
    let origin = if denom < -1e-6 { z_axis * (-d / denom) } else { -n * d };
    let mut x = Vector3::x() - n * n.x;
    if x.norm() < 1e-9 {
        x = Vector3::y() - n * n.y;
    }
    let x = x.normalize();
    let y = n.cross(&x);
    let r_cam_ground = Matrix3::from_columns(&[x, y, n]);
    let t_cam_ground = Pose::from_parts(Rotation3::from_matrix_unchecked(r_cam_ground), origin);
    Ok(t_cam_ground.inverse())
}

/// Composites tubes onto `background` (sRGB, `cam.width × cam.height × 3`).
pub fn composite(background: &[u8], cam: &CameraModel, cfg: &CompositeConfig) -> Result<Composite, SynthError> {
    cam.validate()?;
    let (w, h) = (cam.width as usize, cam.height as usize);
    if background.len() != w * h * 3 {
        return Err(SynthError::Invalid(format!("background has {} bytes, camera expects {w}x{h} RGB", background.len())));
    }
    let (az, el) = cfg.sun_az_el_deg;
    if cfg.sun_cam.is_none() && !(az.is_finite() && el.is_finite() && el > 0.0 && el <= 90.0) {
        return Err(SynthError::Invalid(format!("sun elevation {el} must be in (0, 90] degrees and azimuth finite")));
    }
    if !(cfg.tube_gain.is_finite() && cfg.tube_gain > 0.0) {
        return Err(SynthError::Invalid(format!("tube gain {} must be finite and > 0", cfg.tube_gain)));
    }
    if let Some((r0, r1)) = cfg.range_m {
        if !(r0.is_finite() && r1.is_finite() && r0 >= 0.0 && r1 > r0) {
            return Err(SynthError::Invalid(format!("range band {r0}..{r1} m must be finite with 0 <= near < far")));
        }
    }
    if !(0.0..=1.0).contains(&cfg.dust) {
        return Err(SynthError::Invalid(format!("dust {} must be in [0, 1]", cfg.dust)));
    }
    let t_ground_cam = ground_frame(&cfg.ground.0, cfg.ground.1)?;
    // Sun in the ground frame: azimuth from the camera's forward direction on the ground.
    let fwd = t_ground_cam.transform_vector(&Vector3::z());
    let fwd = Vector3::new(fwd.x, fwd.y, 0.0);
    let fwd = if fwd.norm() > 1e-9 { fwd.normalize() } else { Vector3::y() };
    let right = Vector3::new(fwd.y, -fwd.x, 0.0);
    let sun = match cfg.sun_cam {
        Some(s) => {
            let s = t_ground_cam.transform_vector(&s);
            if !(s.norm().is_finite() && s.z / s.norm() > 1e-3) {
                return Err(SynthError::Invalid(format!("sun direction {s:?} (ground frame) must point above the ground")));
            }
            s.normalize()
        }
        None => {
            let (a, e) = (az.to_radians(), el.to_radians());
            (fwd * a.cos() + right * a.sin()) * e.cos() + Vector3::z() * e.sin()
        }
    };
    let cam_centre = t_ground_cam.translation();

    // Place tubes at random pixels of the lower two thirds whose whole tube projects inside.
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
    let (hl, r) = cfg.tube_shape.bounds();
    let mut objects = Objects::new(Vec::new(), Vec::new(), Vec::new());
    let mut tries = 0;
    while objects.tubes.len() < cfg.tubes && tries < 20000 {
        tries += 1;
        let (u, v) = (rng.random_range(0.0..w as f64), rng.random_range(h as f64 / 3.0..h as f64));
        let (ray, _) = pixel_ray(cam, &t_ground_cam, u, v);
        if ray.dir.z > -1e-3 {
            continue;
        }
        let t = -ray.origin.z / ray.dir.z;
        let p = ray.at(t);
        if let Some((r0, r1)) = cfg.range_m {
            let r = (p.coords - cam_centre).norm();
            if r < r0 || r > r1 {
                continue;
            }
        }
        if objects.tubes.iter().any(|o| (o.t_world_tube.translation().xy() - p.coords.xy()).norm() < 2.0 * hl + 0.03) {
            continue;
        }
        let pose = Pose::from_parts(lying_rotation(rng.random_range(0.0..std::f64::consts::TAU), rng.random_range(0.0..std::f64::consts::TAU)), Vector3::new(p.x, p.y, r));
        let inst = TubeInstance { t_world_tube: pose, shape: cfg.tube_shape.clone(), dust: cfg.dust, seed: rng.random() };
        let probe = Objects::new(Vec::new(), vec![inst.clone()], Vec::new());
        let inside = projected_rect(&probe, 0, cam, &t_ground_cam).is_some_and(|(u0, v0, u1, v1)| u0 >= 0 && v0 >= 0 && u1 < w as i64 && v1 < h as i64);
        if inside {
            objects.tubes.push(inst);
        }
    }
    if objects.tubes.len() < cfg.tubes {
        return Err(SynthError::Invalid(format!("could place only {} of {} tubes fully inside the image on that ground plane", objects.tubes.len(), cfg.tubes)));
    }
    let ext = objects.tubes.iter().map(|t| t.t_world_tube.translation().xy().norm()).fold(0.0, f64::max) + 1.0;
    let n = (2.0 * ext / 0.05).ceil() as usize;
    objects.build_grid(-ext, -ext, 0.05, n, n);

    // Exposure from the photo: median linear intensity of the lower half = sunlit regolith.
    let lut: Vec<f32> = (0..256).map(|i| cfg.encoding.to_linear(i as u8)).collect();
    let mut lows: Vec<f32> = background[w * 3 * (h / 2)..].chunks(3).map(|p| (lut[p[0] as usize] + lut[p[1] as usize] + lut[p[2] as usize]) / 3.0).collect();
    lows.sort_by(|a, b| a.total_cmp(b));
    let median = lows.get(lows.len() / 2).copied().unwrap_or(0.2).max(0.01);
    let reg = cfg.band.regolith();
    let (e_sun, e_sky) = (1.0f32, 0.25f32);
    let cos_sun = sun.z as f32;
    let exposure = cfg.tube_gain * median / (((reg[0] + reg[1] + reg[2]) / 3.0) * (e_sun * cos_sun + e_sky));
    let shadow_factor = e_sky / (e_sun * cos_sun + e_sky);

    let mut rgb = vec![0u8; w * h * 3];
    let mut depth = Plane::filled(w, h, f32::INFINITY);
    let mut instance = Plane::<u16>::new(w, h);
    let mut surface = Plane::<u8>::new(w, h);
    let to_pixel = |v: f32| cfg.encoding.to_pixel(v);
    let objects_ref = &objects;
    rgb.par_chunks_mut(w * 3).zip(depth.data.par_chunks_mut(w)).zip(instance.data.par_chunks_mut(w)).zip(surface.data.par_chunks_mut(w)).enumerate().for_each(|(y, (((row, drow), irow), srow))| {
        let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed ^ (y as u64 + 1).wrapping_mul(0x9e37_79b9_7f4a_7c15));
        for x in 0..w {
            let bg = [lut[background[(y * w + x) * 3] as usize], lut[background[(y * w + x) * 3 + 1] as usize], lut[background[(y * w + x) * 3 + 2] as usize]];
            let (centre, zf) = pixel_ray(cam, &t_ground_cam, x as f64, y as f64);
            let hit = objects_ref.intersect(&centre, 0.0, 1e3);
            srow[x] = SurfaceKind::Ground as u8;
            if let Some((t, ObjectHit::Tube(i, _, _))) = hit {
                irow[x] = (i + 1) as u16;
                drow[x] = (t * zf) as f32;
                srow[x] = SurfaceKind::Tube as u8;
            } else if centre.dir.z < 0.0 {
                drow[x] = (-centre.origin.z / centre.dir.z * zf) as f32;
            }
            let mut acc = [0.0f32; 3];
            let near = (0..4).map(|k| {
                let (du, dv) = (((k & 1) as f64 - 0.5) * 0.5, ((k >> 1) as f64 - 0.5) * 0.5);
                pixel_ray(cam, &t_ground_cam, x as f64 + du, y as f64 + dv).0
            });
            for ray in near {
                let c = match objects_ref.intersect(&ray, 0.0, 1e3) {
                    Some((t, ObjectHit::Tube(i, mat, n))) => shade_tube(objects_ref, i, mat, cfg.band, reg, &n, &ray, t, &sun, e_sun, e_sky, exposure, &mut rng),
                    _ => {
                        if ray.dir.z < 0.0 {
                            let t = -ray.origin.z / ray.dir.z;
                            let p = ray.at(t);
                            let sh = Ray { origin: p + Vector3::z() * 1e-4, dir: sun };
                            if objects_ref.intersect(&sh, 0.0, 50.0).is_some() {
                                bg.map(|v| v * shadow_factor)
                            } else {
                                bg
                            }
                        } else {
                            bg
                        }
                    }
                };
                for k in 0..3 {
                    acc[k] += c[k] * 0.25;
                }
            }
            for k in 0..3 {
                row[x * 3 + k] = to_pixel(acc[k]);
            }
        }
    });
    let output = RenderOutput { width: w, height: h, rgb, depth, instance, surface };
    let truth = tube_truth(&objects, cam, &t_ground_cam, &output);
    Ok(Composite { output, truth, t_ground_cam, tubes: objects.tubes })
}

/// Linear radiance of a tube sample of material `mat` in `band` (dust mixes in the regolith's
/// albedo `reg` of that band, computed once per composite).
#[allow(clippy::too_many_arguments)]
fn shade_tube(objects: &Objects, i: usize, mat: TubeMaterial, band: SpectralBand, reg: [f32; 3], n: &Vector3<f64>, ray: &Ray, t: f64, sun: &Vector3<f64>, e_sun: f32, e_sky: f32, exposure: f32, rng: &mut ChaCha8Rng) -> [f32; 3] {
    let (alb, ks, shin) = match mat {
        TubeMaterial::Alumina => ([0.78f32, 0.79, 0.75], 0.12f32, 18.0f32),
        TubeMaterial::Gold => ([0.45, 0.28, 0.05], 0.55, 40.0),
        TubeMaterial::Titanium => ([0.45, 0.46, 0.48], 0.4, 30.0),
        TubeMaterial::Plastic => ([0.05, 0.05, 0.05], 0.1, 10.0),
    };
    let alb = match band {
        SpectralBand::Visible => alb,
        SpectralBand::RedNir => [band_albedo(mat); 3],
    };
    let dust = objects.tubes[i].dust * (0.55 + 0.45 * n.z.max(0.0) as f32);
    let alb = [0, 1, 2].map(|k| alb[k] * (1.0 - dust) + reg[k] * dust);
    let p = ray.at(t);
    let ndl = n.dot(sun).max(0.0) as f32;
    let lit = if ndl > 0.0 && objects.intersect(&Ray { origin: p + n * 2e-4, dir: *sun }, 0.0, 50.0).is_none() { 1.0 } else { 0.0 };
    let ao = 0.55 + 0.45 * n.z as f32;
    let hv = (sun - ray.dir).normalize();
    let spec = ks * (1.0 - dust) * (n.dot(&hv).max(0.0) as f32).powf(shin) * lit;
    let noise: f32 = rng.random_range(-0.01..0.01);
    [0, 1, 2].map(|k| exposure * (alb[k] * (e_sun * ndl * lit + e_sky * ao) + spec * e_sun) + noise)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;

    /// Mean 8-bit luminance of the composite's pixels whose centre ray hits `want`.
    /// Both encodings give back every pixel value they read; a linear stretch of `lo..hi` puts
    /// no light at `-255 lo / (hi - lo)`, and a stretch that starts below zero or is empty is
    /// none.
    #[test]
    fn photo_encodings_read_and_write_every_pixel_value_unchanged() {
        let stretch = PhotoEncoding::linear_stretch(562.0, 1959.0).unwrap();
        let PhotoEncoding::Linear { black } = stretch else { panic!("{stretch:?}") };
        assert!((black as f64 + 255.0 * 562.0 / 1397.0).abs() < 1e-4, "{black}");
        for enc in [PhotoEncoding::Srgb, stretch, PhotoEncoding::Linear { black: 0.0 }] {
            for p in 0..=255u8 {
                assert_eq!(enc.to_pixel(enc.to_linear(p)), p, "{enc:?} {p}");
            }
        }
        // Twice the light of pixel 120: 240 - black above black, clipped at 255.
        assert_eq!(PhotoEncoding::Linear { black: 0.0 }.to_pixel(2.0 * PhotoEncoding::Linear { black: 0.0 }.to_linear(100)), 200);
        assert_eq!(stretch.to_pixel(2.0 * stretch.to_linear(120)), 255);
        assert_eq!(PhotoEncoding::linear_stretch(-1.0, 10.0), None);
        assert_eq!(PhotoEncoding::linear_stretch(10.0, 10.0), None);
    }

    /// On a photo that is a linear stretch, the white body's light above the stretch's black
    /// is its albedo over the regolith's (0.78 / 0.34) times the ground's, less the cylinder's
    /// shading: far brighter than the same light written through the sRGB curve.
    #[test]
    fn a_linear_photo_takes_its_tubes_light_linearly() {
        let black = -40.0f32;
        let (cam, background, cfg) = overhead(SpectralBand::RedNir, PhotoEncoding::Linear { black });
        let linear = composite(&background, &cam, &cfg).unwrap();
        let srgb = composite(&background, &cam, &CompositeConfig { encoding: PhotoEncoding::Srgb, ..cfg }).unwrap();
        let (bl, bs) = (mean_of_material(&linear, &cam, TubeMaterial::Alumina), mean_of_material(&srgb, &cam, TubeMaterial::Alumina));
        let gain = (bl - black as f64) / (60.0 - black as f64);
        assert!(gain > 1.5 && gain < 0.78 / 0.34 + 0.05, "body {bl:.1} on ground 60, black {black}: {gain:.2}x the light");
        assert!(bl > bs + 20.0, "linear {bl:.1} against sRGB {bs:.1}");
        assert_eq!(&linear.output.rgb[..3], &[60, 60, 60]);
    }

    /// One tube 1 m below a camera looking straight down (160 px, f 400 px), sun 89 degrees
    /// up, on grey ground of pixel value 60: the camera, the photo and the configuration.
    fn overhead(band: SpectralBand, encoding: PhotoEncoding) -> (CameraModel, Vec<u8>, CompositeConfig) {
        let cam = CameraModel { width: 160, height: 160, fx: 400.0, fy: 400.0, cx: 79.5, cy: 79.5, distortion: Default::default() };
        let shape = Arc::new(TubeShape::from_model(&tubeloc_core::TubeModel::default()));
        let cfg = CompositeConfig { ground: (Vector3::new(0.0, 0.0, -1.0), 1.0), sun_az_el_deg: (0.0, 89.0), tubes: 1, dust: 0.0, seed: 3, tube_shape: shape, range_m: None, sun_cam: None, tube_gain: 1.0, band, encoding };
        (cam, vec![60u8; 160 * 160 * 3], cfg)
    }

    fn mean_of_material(c: &Composite, cam: &CameraModel, want: TubeMaterial) -> f64 {
        let mut objects = Objects::new(Vec::new(), c.tubes.clone(), Vec::new());
        objects.build_grid(-3.0, -3.0, 0.05, 120, 120);
        let (mut sum, mut n) = (0.0, 0usize);
        for y in 0..cam.height as usize {
            for x in 0..cam.width as usize {
                let (ray, _) = pixel_ray(cam, &c.t_ground_cam, x as f64, y as f64);
                if let Some((_, ObjectHit::Tube(_, mat, _))) = objects.intersect(&ray, 0.0, 1e3) {
                    if mat == want {
                        let p = &c.output.rgb[(y * cam.width as usize + x) * 3..][..3];
                        sum += 0.299 * p[0] as f64 + 0.587 * p[1] as f64 + 0.114 * p[2] as f64;
                        n += 1;
                    }
                }
            }
        }
        assert!(n > 20, "{want:?}: {n} pixels");
        sum / n as f64
    }

    #[test]
    fn red_nir_band_makes_the_seal_about_as_bright_as_the_body() {
        let (cam, background, cfg) = overhead(SpectralBand::RedNir, PhotoEncoding::Srgb);
        let vis = composite(&background, &cam, &CompositeConfig { band: SpectralBand::Visible, ..cfg.clone() }).unwrap();
        let nir = composite(&background, &cam, &cfg).unwrap();
        let ratio = |c: &Composite| mean_of_material(c, &cam, TubeMaterial::Gold) / mean_of_material(c, &cam, TubeMaterial::Alumina);
        let (rv, rn) = (ratio(&vis), ratio(&nir));
        // Visible luminance: gold (0.45, 0.28, 0.05) is far darker than the white body; in
        // 600-800 nm TiN reflects 0.62 against the body's 0.78 (the glossier seal's highlight
        // aside).
        assert!(rv < 0.75, "visible seal / body {rv:.2}");
        assert!(rn > 0.8 && rn > rv + 0.1, "red-nir seal / body {rn:.2} (visible {rv:.2})");
        // The body is brighter than the ground it lies on: 0.78 / 0.34 of its linear intensity
        // lit from above, less the cylinder's shading, through the sRGB curve.
        let body = mean_of_material(&nir, &cam, TubeMaterial::Alumina);
        assert!(body > 1.25 * 60.0 && body < 2.3 * 60.0, "red-nir body {body:.1} on ground 60");
        // The ground away from the tube is the photo's own.
        assert_eq!(&nir.output.rgb[..3], &[60, 60, 60]);
    }

    #[test]
    fn ground_frame_puts_the_plane_at_z0_and_camera_above() {
        // Camera 1.5 m above a ground seen at 45 degrees: plane normal (0, -a, -a) in camera frame.
        let a = std::f64::consts::FRAC_1_SQRT_2;
        let t_ground_cam = ground_frame(&Vector3::new(0.0, -a, -a), 1.5).unwrap();
        let cam_origin = t_ground_cam.transform_point(&Point3::origin());
        assert!((cam_origin.z - 1.5).abs() < 1e-9, "{cam_origin:?}");
        let t_cam_ground = t_ground_cam.inverse();
        for p in [Point3::new(0.3, 0.2, 0.0), Point3::new(-1.0, 2.0, 0.0)] {
            let pc = t_cam_ground.transform_point(&p);
            assert!((pc.coords.dot(&Vector3::new(0.0, -a, -a)) + 1.5).abs() < 1e-9);
        }
        assert!(ground_frame(&Vector3::zeros(), 1.0).is_err());
    }
}
