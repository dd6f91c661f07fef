//! `Scene`: a generated Mars-yard scene (terrain, rocks, tubes with their adverse cases, sun).
//!
//! `Scene::generate(&config, seed)` is a pure function of its inputs: the same configuration
//! and seed give the same scene, bit for bit. World frame: x east, y north, z up, metres; the
//! scene centre (where the cameras look) is the origin.

use crate::heightfield::HeightField;
use crate::mount::{self, TagMount};
use crate::noise::fbm2;
use crate::objects::{Objects, TubeInstance};
use crate::ray::Ray;
use crate::rock::{sample_golombek_diameters, Rock};
use crate::sun::{Sun, JPL_LATITUDE_DEG};
use crate::terrain::{srgb_to_linear, TerrainKind, TerrainParams, SAND_SRGB};
use crate::tube_shape::TubeShape;
use crate::SynthError;
use nalgebra::{Matrix3, Point3, Rotation3, Vector3};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::sync::Arc;
use tubeloc_core::{Plane, Pose, TubeModel};

/// Capture time of day: the paper's "am" (10-12 h) and "pm" (15-17 h) sessions.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TimeOfDay {
    /// 10:00 to 12:00 local solar time.
    Am,
    /// 15:00 to 17:00 local solar time.
    Pm,
}

impl TimeOfDay {
    /// `"am"` or `"pm"`.
    pub fn name(&self) -> &'static str {
        match self {
            TimeOfDay::Am => "am",
            TimeOfDay::Pm => "pm",
        }
    }
}

/// The adverse condition a tube was placed in.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TubeCase {
    /// Clean tube on open ground.
    Unoccluded,
    /// A rock leans on one end of the tube.
    Rock,
    /// A light dust layer: albedo pulled toward regolith.
    Dust,
    /// A sand dune piled along one side.
    Dune,
    /// Part of the tube buried under a sand mound.
    SandMound,
}

/// Loose-sand label of a height-field vertex.
pub mod sand {
    /// Plain ground.
    pub const NONE: u8 = 0;
    /// Sand mound over a tube.
    pub const MOUND: u8 = 1;
    /// Dune along a tube.
    pub const DUNE: u8 = 2;
    /// Sand covering the tag mount.
    pub const MOUNT_COVER: u8 = 3;
}

/// What to generate.
#[derive(Clone, Debug)]
pub struct SceneConfig {
    /// Terrain type.
    pub terrain: TerrainKind,
    /// Capture session.
    pub time: TimeOfDay,
    /// Whether one tube carries the tag mount.
    pub with_tags: bool,
    /// Number of tubes; `None` draws 5 or 6 as in the paper.
    pub tubes: Option<usize>,
    /// Side of the square terrain, metres.
    pub extent_m: f64,
    /// Height-field spacing, metres.
    pub cell_m: f64,
    /// Radius around the centre within which tubes are placed, metres.
    pub tube_field_radius_m: f64,
    /// Tube geometry.
    pub tube_shape: Arc<TubeShape>,
}

impl SceneConfig {
    /// Defaults: 8 m square terrain at 5 mm, tubes within 0.65 m, parametric tube model.
    pub fn new(terrain: TerrainKind, time: TimeOfDay, with_tags: bool) -> Self {
        SceneConfig { terrain, time, with_tags, tubes: None, extent_m: 8.0, cell_m: 0.005, tube_field_radius_m: 0.65, tube_shape: Arc::new(TubeShape::from_model(&TubeModel::default())) }
    }

    /// Checks the numbers (finite, positive, grid not absurdly large).
    pub fn validate(&self) -> Result<(), SynthError> {
        let ok = self.extent_m.is_finite() && self.cell_m.is_finite() && self.extent_m > 0.5 && self.cell_m > 0.0005 && self.cell_m <= 0.05;
        if !ok {
            return Err(SynthError::Invalid(format!("terrain extent {} m / cell {} m out of range (extent > 0.5 m, cell 0.5-50 mm)", self.extent_m, self.cell_m)));
        }
        let n = (self.extent_m / self.cell_m).round();
        if n > 4096.0 {
            return Err(SynthError::Invalid(format!("height field of {n}x{n} vertices is too large (at most 4096 per side)")));
        }
        if !(self.tube_field_radius_m.is_finite() && self.tube_field_radius_m > 0.0 && self.tube_field_radius_m < self.extent_m / 2.0) {
            return Err(SynthError::Invalid(format!("tube field radius {} m must be positive and inside the terrain", self.tube_field_radius_m)));
        }
        if let Some(n) = self.tubes {
            if n > 32 {
                return Err(SynthError::Invalid(format!("{n} tubes per scene is too many (at most 32)")));
            }
        }
        Ok(())
    }
}

/// Per-tube facts recorded by the generator.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TubeInfo {
    /// Adverse case the tube was placed in.
    pub case: TubeCase,
    /// Dust level in [0, 1].
    pub dust: f32,
    /// True for the tube carrying the tag mount.
    pub carries_tags: bool,
}

/// A generated scene.
#[derive(Clone, Debug)]
pub struct Scene {
    /// The configuration it was generated from.
    pub config: SceneConfig,
    /// Seed it was generated from.
    pub seed: u64,
    /// Sun position.
    pub sun: Sun,
    /// Local solar time, hours.
    pub solar_hour: f64,
    /// Day of the year used for the sun.
    pub day_of_year: f64,
    /// Terrain heights.
    pub hf: HeightField,
    /// Per-vertex albedo, sRGB-coded, and loose-sand label (see [`sand`]) in the 4th byte.
    pub albedo: Vec<[u8; 4]>,
    /// Rocks, tubes and mount plates.
    pub objects: Objects,
    /// Per-tube facts, same order as `objects.tubes`.
    pub tube_info: Vec<TubeInfo>,
    /// The tag mount of with-tags scenes.
    pub mount: Option<TagMount>,
    /// Sky visibility in [0, 1] on a coarse grid over the terrain (`sky_cell` metres).
    pub sky: Plane<f32>,
    /// Spacing of `sky`, metres.
    pub sky_cell: f64,
    /// Random angular offset of the capture stops, radians.
    pub stop_offset: f64,
    /// Terrain parameters (noise seeds, channel layout).
    pub terrain: TerrainParams,
}

/// Rotation whose z axis is the horizontal direction at `yaw` (radians), rolled by `roll`.
pub fn lying_rotation(yaw: f64, roll: f64) -> Rotation3<f64> {
    let z = Vector3::new(yaw.cos(), yaw.sin(), 0.0);
    let x0 = Vector3::z();
    let y0 = z.cross(&x0);
    let (c, s) = (roll.cos(), roll.sin());
    let x = x0 * c + y0 * s;
    let y = z.cross(&x);
    Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, z]))
}

impl Scene {
    /// Generates a scene; deterministic in `(config, seed)`.
    pub fn generate(config: &SceneConfig, seed: u64) -> Result<Scene, SynthError> {
        config.validate()?;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let half = config.extent_m / 2.0;
        let n = (config.extent_m / config.cell_m).round() as usize + 1;
        let cell = config.extent_m / (n - 1) as f64;
        let params = TerrainParams {
            kind: config.terrain,
            seed: rng.random(),
            ditch: (rng.random_range(0.0..std::f64::consts::PI), rng.random_range(-0.35..0.35)),
            channels: (0..2).map(|k| (rng.random_range(0.0..std::f64::consts::PI), (k as f64 - 0.5) * 1.4 + rng.random_range(-0.3..0.3), rng.random_range(0.05..0.08))).collect(),
        };
        let (x0, y0) = (-half, -half);
        let mut hf = HeightField::flat(n, n, cell, x0, y0, 0.0);
        let mut lin: Vec<[f32; 3]> = vec![[0.0; 3]; n * n];
        hf.h.par_chunks_mut(n).zip(lin.par_chunks_mut(n)).enumerate().for_each(|(j, (hrow, arow))| {
            let y = y0 + j as f64 * cell;
            for i in 0..n {
                let (h, a) = params.sample(x0 + i as f64 * cell, y);
                hrow[i] = h;
                arow[i] = a;
            }
        });
        let mut labels = vec![sand::NONE; n * n];
        hf.rebuild();

        // Tubes and their cases.
        let shape = config.tube_shape.clone();
        let (hl, r) = shape.bounds();
        let n_tubes = config.tubes.unwrap_or_else(|| rng.random_range(5..=6));
        let mut cases = [TubeCase::Unoccluded, TubeCase::Rock, TubeCase::Dust, TubeCase::Dune, TubeCase::SandMound, TubeCase::Unoccluded];
        cases.shuffle(&mut rng);
        let mut tubes: Vec<TubeInstance> = Vec::new();
        let mut info: Vec<TubeInfo> = Vec::new();
        let mut case_rocks: Vec<Rock> = Vec::new();
        let sand_lin = srgb_to_linear(SAND_SRGB);
        for k in 0..n_tubes {
            let case = cases[k % cases.len()];
            let mut pos = (0.0, 0.0);
            for _attempt in 0..200 {
                let rad = config.tube_field_radius_m * rng.random::<f64>().sqrt();
                let a = rng.random_range(0.0..std::f64::consts::TAU);
                pos = (rad * a.cos(), rad * a.sin());
                let far = tubes.iter().all(|t| {
                    let c = t.t_world_tube.translation();
                    ((c.x - pos.0).powi(2) + (c.y - pos.1).powi(2)).sqrt() > 2.0 * hl + 0.06
                });
                if far {
                    break;
                }
            }
            let mut yaw = rng.random_range(0.0..std::f64::consts::TAU);
            // On slopes (ditch walls, channel banks) a lying tube settles along the contour.
            let slope = hf.normal(pos.0, pos.1);
            if slope.z < 0.995 {
                yaw = slope.y.atan2(slope.x) + std::f64::consts::FRAC_PI_2 + (yaw - std::f64::consts::PI) * 0.1;
            }
            let roll = rng.random_range(0.0..std::f64::consts::TAU);
            let axis = Vector3::new(yaw.cos(), yaw.sin(), 0.0);
            let perp = Vector3::new(-yaw.sin(), yaw.cos(), 0.0);
            // Rest height: upper quantile of the ground under the footprint plus the radius.
            let mut samples: Vec<f64> = Vec::new();
            for si in -4..=4 {
                for qi in -1..=1 {
                    let p = Vector3::new(pos.0, pos.1, 0.0) + axis * (si as f64 / 4.0 * hl) + perp * (qi as f64 * r * 0.6);
                    samples.push(hf.height(p.x, p.y));
                }
            }
            samples.sort_by(|a, b| a.total_cmp(b));
            let ground = samples[(samples.len() * 3) / 4];
            let zc = ground + r * 0.92;
            let centre = Point3::new(pos.0, pos.1, zc);
            let pose = Pose::from_parts(lying_rotation(yaw, roll), centre.coords);
            let dust = match case {
                TubeCase::Dust => rng.random_range(0.35..0.65),
                _ => rng.random_range(0.0..0.08),
            };
            // Edit the height field around the tube: carve the bed, then sand.
            let side = if rng.random::<bool>() { 1.0 } else { -1.0 };
            let dune_top = zc + r * rng.random_range(-0.1..0.35);
            let mound_s = if rng.random::<bool>() { 1.0 } else { -1.0 } * rng.random_range(0.18..0.33) * 2.0 * hl;
            let mound_q = rng.random_range(-0.01..0.01);
            let mound_rho = rng.random_range(0.035..0.05);
            let mound_h = 2.0 * r + rng.random_range(0.004..0.012);
            let reach = hl + 0.15;
            let (i0, i1) = (((pos.0 - reach - x0) / cell).floor().max(0.0) as usize, (((pos.0 + reach - x0) / cell).ceil() as usize).min(n - 1));
            let (j0, j1) = (((pos.1 - reach - y0) / cell).floor().max(0.0) as usize, (((pos.1 + reach - y0) / cell).ceil() as usize).min(n - 1));
            for j in j0..=j1 {
                for i in i0..=i1 {
                    let (x, y) = (x0 + i as f64 * cell, y0 + j as f64 * cell);
                    let d = Vector3::new(x - pos.0, y - pos.1, 0.0);
                    let (s, q) = (d.dot(&axis), d.dot(&perp));
                    let idx = j * n + i;
                    let mut h = hf.h[idx] as f64;
                    if s.abs() <= hl + 0.003 && q.abs() < r {
                        h = h.min(zc - (r * r - q * q).sqrt() - 0.0005);
                    }
                    let old = h;
                    let base = zc - r;
                    let mut label = labels[idx];
                    match case {
                        TubeCase::Dune => {
                            let qs = q * side;
                            let f = if qs < -0.3 * r {
                                0.0
                            } else if qs <= 0.9 * r {
                                1.0
                            } else {
                                (-((qs - 0.9 * r) / 0.05).powi(2)).exp()
                            };
                            let g = if s.abs() <= hl * 0.8 { 1.0 } else { (-((s.abs() - hl * 0.8) / 0.05).powi(2)).exp() };
                            let ripple = 1.0 + 0.15 * fbm2((x / 0.03) as f32, (y / 0.03) as f32, 2, 0.5, params.seed ^ 0x3d) as f64;
                            let target = old + (dune_top - old) * f * g * ripple;
                            if target > h {
                                h = target;
                            }
                            if h > old + 0.002 {
                                label = sand::DUNE;
                            }
                        }
                        TubeCase::SandMound => {
                            let (ds, dq) = (s - mound_s, q - mound_q);
                            let rr = (ds / (1.6 * mound_rho)).powi(2) + (dq / mound_rho).powi(2);
                            if rr < 1.0 {
                                let w = (1.0 - rr).powi(2);
                                let top = base + mound_h * (1.0 + 0.05 * fbm2((x / 0.02) as f32, (y / 0.02) as f32, 2, 0.5, params.seed ^ 0x4e) as f64);
                                let target = old + (top - old) * w;
                                if target > h {
                                    h = target;
                                }
                                if h > old + 0.002 {
                                    label = sand::MOUND;
                                }
                            }
                        }
                        _ => {}
                    }
                    hf.h[idx] = h as f32;
                    if label != sand::NONE && labels[idx] == sand::NONE {
                        labels[idx] = label;
                        let a = lin[idx];
                        lin[idx] = [0.25 * a[0] + 0.75 * sand_lin[0], 0.25 * a[1] + 0.75 * sand_lin[1], 0.25 * a[2] + 0.75 * sand_lin[2]];
                    }
                }
            }
            if case == TubeCase::Rock {
                let dd = rng.random_range(0.08..0.16);
                let axes = [dd / 2.0 * rng.random_range(0.9..1.2), dd / 2.0 * rng.random_range(0.7..1.0), dd / 2.0 * rng.random_range(0.55..0.8)];
                let end = if rng.random::<bool>() { 1.0 } else { -1.0 } * hl * rng.random_range(0.55..0.9);
                let c = Vector3::new(pos.0, pos.1, 0.0) + axis * end + perp * (side * (r + axes[1] * 0.45));
                let gz = hf.height(c.x, c.y);
                let alb = srgb_to_linear([96, 80, 68]);
                let yaw_r = rng.random_range(0.0..6.3);
                case_rocks.push(Rock::new(&mut rng, Point3::new(c.x, c.y, gz + axes[2] * 0.45), axes, yaw_r, 0.25, 26, alb));
            }
            tubes.push(TubeInstance { t_world_tube: pose, shape: shape.clone(), dust, seed: rng.random() });
            info.push(TubeInfo { case, dust, carries_tags: false });
        }

        // Tag mount on one clean tube.
        let mut plates = Vec::new();
        let mut mount_out = None;
        if config.with_tags && !tubes.is_empty() {
            let k = info.iter().position(|t| t.case == TubeCase::Unoccluded).unwrap_or(0);
            info[k].carries_tags = true;
            let c = tubes[k].t_world_tube.translation();
            let axis = tubes[k].t_world_tube.transform_vector(&Vector3::z());
            tubes[k].t_world_tube = Pose::from_parts(mount::carrier_rotation(&axis), c);
            let m = mount::build_mount(&tubes[k].t_world_tube, k)?;
            mount::cover_with_sand(&m, &mut hf, &mut labels, &mut lin, &tubes[k].t_world_tube, r);
            plates = m.plates.clone();
            mount_out = Some(m);
        }
        hf.rebuild();

        // Rock field.
        let area_r = (half - 0.3).min(3.6);
        let area = std::f64::consts::PI * area_r * area_r;
        let (k_cfa, dmin, dmax, facets) = match config.terrain {
            TerrainKind::Cfa6 => (0.06, 0.03, 0.7, 22),
            TerrainKind::Cfa2 => (0.02, 0.015, 0.3, 20),
            TerrainKind::Flagstone => (0.008, 0.02, 0.15, 18),
            TerrainKind::Ditch => (0.03, 0.02, 0.35, 20),
            TerrainKind::Riverbed => (0.02, 0.015, 0.25, 20),
        };
        let mut diameters = sample_golombek_diameters(&mut rng, k_cfa, area, dmin, dmax);
        if config.terrain == TerrainKind::Riverbed {
            diameters.extend((0..900).map(|_| rng.random_range(0.01..0.05)));
        }
        let palette: [[u8; 3]; 5] = [[82, 72, 64], [118, 92, 72], [104, 100, 96], [128, 86, 62], [70, 62, 58]];
        let mut rocks = Vec::with_capacity(diameters.len() + case_rocks.len());
        for (idx, &d) in diameters.iter().enumerate() {
            let riverbed_pebble = config.terrain == TerrainKind::Riverbed && idx >= diameters.len() - 900;
            let (x, y) = loop {
                let rad = area_r * rng.random::<f64>().sqrt();
                let a = rng.random_range(0.0..std::f64::consts::TAU);
                let (x, y) = (rad * a.cos(), rad * a.sin());
                if !riverbed_pebble || params.channel_weight(x, y) > rng.random_range(0.2..1.0) {
                    break (x, y);
                }
            };
            let axes = [d / 2.0 * rng.random_range(0.8..1.2), d / 2.0 * rng.random_range(0.6..1.0), d / 2.0 * rng.random_range(0.35..0.7)];
            let clear = tubes.iter().all(|t| {
                let c = t.t_world_tube.translation();
                let ax = t.t_world_tube.transform_vector(&Vector3::z());
                let v = Vector3::new(x - c.x, y - c.y, 0.0);
                let s = v.dot(&ax).clamp(-hl, hl);
                let closest = v - ax * s;
                closest.norm() > axes[0].max(axes[1]) * 1.1 + r + 0.02
            }) && mount_out.as_ref().is_none_or(|m| m.clear_of(x, y, axes[0].max(axes[1]) + 0.02));
            let colour = palette[rng.random_range(0..palette.len())];
            let shade = rng.random_range(0.85..1.15);
            let alb = srgb_to_linear(colour).map(|c| c * shade);
            let gz = hf.height(x, y);
            let burial = rng.random_range(0.2..0.5);
            let yaw_r = rng.random_range(0.0..6.3);
            let rock = Rock::new(&mut rng, Point3::new(x, y, gz + axes[2] * (1.0 - 2.0 * burial)), axes, yaw_r, 0.3, facets, alb);
            if clear {
                rocks.push(rock);
            }
        }
        rocks.extend(case_rocks);

        let albedo: Vec<[u8; 4]> = lin.par_iter().zip(labels.par_iter()).map(|(a, &l)| [crate::terrain::linear_to_srgb8(a[0]), crate::terrain::linear_to_srgb8(a[1]), crate::terrain::linear_to_srgb8(a[2]), l]).collect();
        let mut objects = Objects::new(rocks, tubes, plates);
        let gcell = 0.1;
        let gn = (config.extent_m / gcell).ceil() as usize;
        objects.build_grid(x0, y0, gcell, gn, gn);

        let day_of_year = rng.random_range(60.0..300.0);
        let solar_hour = match config.time {
            TimeOfDay::Am => rng.random_range(10.0..12.0),
            TimeOfDay::Pm => rng.random_range(15.0..17.0),
        };
        let sun = Sun::at(JPL_LATITUDE_DEG, day_of_year, solar_hour);
        let stop_offset = rng.random_range(0.0..std::f64::consts::TAU);
        let mut scene = Scene { config: config.clone(), seed, sun, solar_hour, day_of_year, hf, albedo, objects, tube_info: info, mount: mount_out, sky: Plane::new(1, 1), sky_cell: 0.02, stop_offset, terrain: params };
        scene.sky = scene.compute_sky();
        Ok(scene)
    }

    /// Top surface height (terrain, rocks, tubes) at `(x, y)`, metres.
    pub fn top_height(&self, x: f64, y: f64) -> f64 {
        let g = self.hf.height(x, y);
        let ray = Ray { origin: Point3::new(x, y, g + 2.0), dir: -Vector3::z() };
        match self.objects.intersect(&ray, 0.0, 2.0) {
            Some((t, _)) => (g + 2.0 - t).max(g),
            None => g,
        }
    }

    /// Sky visibility by horizon scanning: for 8 directions, the largest elevation angle `θ`
    /// of the top surface within 0.5 m; visibility `1 − mean(sin θ)`.
    pub(crate) fn compute_sky(&self) -> Plane<f32> {
        let c = self.sky_cell;
        let n = ((self.hf.x1() - self.hf.x0) / c).floor() as usize + 1;
        let x0 = self.hf.x0;
        let y0 = self.hf.y0;
        let mut top = vec![0.0f32; n * n];
        top.par_chunks_mut(n).enumerate().for_each(|(j, row)| {
            for (i, v) in row.iter_mut().enumerate() {
                *v = self.top_height(x0 + i as f64 * c, y0 + j as f64 * c) as f32;
            }
        });
        let dists = [1usize, 2, 3, 5, 7, 10, 15, 22];
        let dirs: Vec<(f64, f64)> = (0..8).map(|k| (k as f64 * std::f64::consts::FRAC_PI_4).sin_cos()).collect();
        let mut vis = vec![1.0f32; n * n];
        vis.par_chunks_mut(n).enumerate().for_each(|(j, row)| {
            for (i, v) in row.iter_mut().enumerate() {
                let h0 = top[j * n + i];
                let mut occ = 0.0f32;
                for &(s, co) in &dirs {
                    let mut best = 0.0f32;
                    for &d in &dists {
                        let ii = i as f64 + co * d as f64;
                        let jj = j as f64 + s * d as f64;
                        if ii < 0.0 || jj < 0.0 || ii >= n as f64 || jj >= n as f64 {
                            break;
                        }
                        let dh = top[jj as usize * n + ii as usize] - h0;
                        let tan = dh / (d as f32 * c as f32);
                        best = best.max(tan);
                    }
                    occ += best / (1.0 + best * best).sqrt();
                }
                *v = 1.0 - occ / dirs.len() as f32;
            }
        });
        Plane::from_vec(n, n, vis)
    }

    /// Sky visibility at `(x, y)` (bilinear on the coarse grid).
    #[inline]
    pub fn sky_at(&self, x: f64, y: f64) -> f32 {
        let u = ((x - self.hf.x0) / self.sky_cell) as f32;
        let v = ((y - self.hf.y0) / self.sky_cell) as f32;
        self.sky.sample_bilinear(u, v)
    }

    /// The scene's nominal ground height (world z, metres): the median terrain height over
    /// the disc of `radius_m` around the origin (the datasets use the ring of capture stops,
    /// [`crate::rig::STOP_RADIUS_M`]). It is the level of a plane fitted robustly to the
    /// terrain the cameras see, which is what a rover's own estimate of its workspace's ground
    /// gives; world z = 0 is only the height field's datum (on flagstone the bottom of the
    /// cracks, 1-3 cm under the slabs). Rocks and tubes are not terrain and do not count.
    pub fn nominal_ground_height(&self, radius_m: f64) -> f64 {
        let hf = &self.hf;
        let mut heights: Vec<f32> = Vec::new();
        for j in 0..hf.ny {
            let y = hf.y0 + j as f64 * hf.cell;
            for i in 0..hf.nx {
                let x = hf.x0 + i as f64 * hf.cell;
                if x * x + y * y <= radius_m * radius_m {
                    heights.push(hf.h[j * hf.nx + i]);
                }
            }
        }
        if heights.is_empty() {
            return hf.height(0.0, 0.0);
        }
        let mid = heights.len() / 2;
        let (_, m, _) = heights.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
        *m as f64
    }

    /// `T_world_tube` of every tube.
    pub fn tube_poses(&self) -> Vec<Pose> {
        self.objects.tubes.iter().map(|t| t.t_world_tube).collect()
    }
}
