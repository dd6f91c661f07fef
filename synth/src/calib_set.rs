//! Synthetic calibration sets: a planar tag36h11 board seen by a camera rig at many poses.
//!
//! Board frame: origin at the board centre, x right, y down as printed, z into the board (the
//! AprilTag tag frame, so every tag's frame is the board frame shifted to the tag centre).
//! A view is one board pose `T_rig_board`; every rig camera that sees at least
//! [`MIN_TAGS_PER_IMAGE`] whole tags records an observation, so views near the rig centre are
//! simultaneous views of all cameras (for extrinsics) and views near one camera's image edges
//! constrain its distortion. Corners are written exact (projection through the true camera,
//! OpenCV pixel convention: pixel centres at integers) and with added Gaussian noise
//! (`corner_noise_px`, per coordinate). Images are rendered per pixel: each of 2x2 sub-samples
//! casts the distortion-free ray through its undistorted normalized coordinates, hits the board
//! plane, and area-samples the tag texture over its footprint; then Lambertian shading,
//! vignetting and Gaussian grey-level noise.
//!
//! Files written by [`write_calib_set`]: `calib_set.json` ([`CalibSet`]), `rig_true.json`
//! (the rig used, at the set's resolution), and `view{VVV}_{camera}.png` when rendered.

use crate::tags::{TagFamily, TagTexture};
use nalgebra::{Matrix3, Point2, Point3, Rotation3, Unit, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::Path;
use tubeloc_core::{CameraModel, CoreError, Plane, Pose, Rig};

/// An image observation is kept only when this many whole tags are visible.
pub const MIN_TAGS_PER_IMAGE: usize = 4;

/// The default four-camera rig (paper geometry, mild distortion), `data/rig_default.json`.
pub const DEFAULT_RIG_JSON: &str = include_str!("../../data/rig_default.json");

/// Parses [`DEFAULT_RIG_JSON`]: 4 cameras `L40, L20, R20, R40`, 5472x3648 native, 77 degree
/// HFOV, stereo pairs `L20-R20` (0.20 m) and `L40-R40` (0.40 m).
pub fn default_rig() -> Rig {
    serde_json::from_str(DEFAULT_RIG_JSON).expect("data/rig_default.json is valid (checked by tests)")
}

/// A grid of tags on a planar board.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BoardLayout {
    /// Tag family of every tag.
    pub family: TagFamily,
    /// Edge of each tag's black square, metres.
    pub tag_size_m: f64,
    /// Columns of tags.
    pub cols: usize,
    /// Rows of tags.
    pub rows: usize,
    /// Centre-to-centre distance of neighbouring tags, metres.
    pub pitch_m: f64,
    /// Id of the top-left tag; ids increase along rows.
    pub first_id: u32,
    /// Every tag: id and centre `[x, y]` in the board frame (metres), for readers.
    pub tags: Vec<BoardTag>,
}

/// One tag of a board.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BoardTag {
    /// Tag id.
    pub id: u32,
    /// Tag centre in the board frame, metres (z = 0).
    pub centre: [f64; 2],
}

impl BoardLayout {
    /// A `cols x rows` grid of `tag_size_m` tags at centre spacing `pitch_m`, ids from `first_id`.
    pub fn grid(family: TagFamily, cols: usize, rows: usize, tag_size_m: f64, pitch_m: f64, first_id: u32) -> Self {
        let mut tags = Vec::with_capacity(cols * rows);
        for r in 0..rows {
            for c in 0..cols {
                let x = (c as f64 - (cols as f64 - 1.0) / 2.0) * pitch_m;
                let y = (r as f64 - (rows as f64 - 1.0) / 2.0) * pitch_m;
                tags.push(BoardTag { id: first_id + (r * cols + c) as u32, centre: [x, y] });
            }
        }
        BoardLayout { family, tag_size_m, cols, rows, pitch_m, first_id, tags }
    }

    /// The default board: 8 x 6 tag36h11 tags of 6 cm at 8 cm pitch (ids 100..147).
    pub fn default_board() -> Self {
        Self::grid(TagFamily::Tag36h11, 8, 6, 0.06, 0.08, 100)
    }

    /// Corners of tag `k` (index into `tags`) in the board frame, detector order
    /// `(-s/2, s/2), (s/2, s/2), (s/2, -s/2), (-s/2, -s/2)` around the tag centre.
    pub fn corners(&self, k: usize) -> [Point3<f64>; 4] {
        let [cx, cy] = self.tags[k].centre;
        let s = self.tag_size_m / 2.0;
        [(-s, s), (s, s), (s, -s), (-s, -s)].map(|(u, v)| Point3::new(cx + u, cy + v, 0.0))
    }

    /// Half extents of the printed board (tags plus one pitch-gap margin), metres.
    pub fn half_extent(&self) -> (f64, f64) {
        (0.5 * self.cols as f64 * self.pitch_m, 0.5 * self.rows as f64 * self.pitch_m)
    }
}

/// Board texture with per-tag textures, for rendering.
struct BoardTexture<'a> {
    layout: &'a BoardLayout,
    tex: Vec<TagTexture>,
}

impl<'a> BoardTexture<'a> {
    fn new(layout: &'a BoardLayout) -> Result<Self, CoreError> {
        let tex = layout.tags.iter().map(|t| TagTexture::new(layout.family, t.id, layout.tag_size_m).ok_or_else(|| CoreError::invalid("board", format!("tag id {} not in {}", t.id, layout.family.name())))).collect::<Result<Vec<_>, _>>()?;
        Ok(BoardTexture { layout, tex })
    }

    /// Reflectance at board `(x, y)` with footprint half-width `r` (metres); `None` off board.
    fn sample(&self, x: f64, y: f64, r: f64) -> Option<f32> {
        let (hx, hy) = self.layout.half_extent();
        if x.abs() > hx || y.abs() > hy {
            return None;
        }
        let l = self.layout;
        let c = ((x + hx) / l.pitch_m).floor().clamp(0.0, l.cols as f64 - 1.0) as usize;
        let rr = ((y + hy) / l.pitch_m).floor().clamp(0.0, l.rows as f64 - 1.0) as usize;
        let k = rr * l.cols + c;
        let [cx, cy] = l.tags[k].centre;
        Some(self.tex[k].sample_area(x - cx, y - cy, r).unwrap_or(1.0))
    }
}

/// Options of a calibration set.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CalibSetConfig {
    /// Number of board poses (views).
    pub views: usize,
    /// Seed of every random choice.
    pub seed: u64,
    /// Standard deviation of the Gaussian noise added to each corner coordinate, pixels.
    pub corner_noise_px: f64,
    /// Standard deviation of the grey-level noise of rendered images (0..255 scale).
    pub image_noise: f64,
    /// Image scale relative to the rig's native resolution (e.g. 0.25).
    pub scale: f64,
    /// Board distance range from the rig, metres.
    pub distance_m: (f64, f64),
    /// Render images (otherwise corners only).
    pub render: bool,
}

impl Default for CalibSetConfig {
    fn default() -> Self {
        CalibSetConfig { views: 30, seed: 1, corner_noise_px: 0.2, image_noise: 2.0, scale: 0.25, distance_m: (0.8, 2.0), render: true }
    }
}

/// The four corners of one tag in one image, pixels (OpenCV convention).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TagCorners {
    /// Tag id.
    pub id: u32,
    /// Corners in detector order.
    pub corners: [[f64; 2]; 4],
}

/// What one camera saw of one view.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CameraObservation {
    /// Camera name in the rig.
    pub camera: String,
    /// Image file name relative to the set folder, when rendered.
    pub image: Option<String>,
    /// Exact corners of the wholly visible tags.
    pub exact: Vec<TagCorners>,
    /// The same corners with added noise.
    pub noisy: Vec<TagCorners>,
}

/// One board pose and its observations.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CalibView {
    /// View index.
    pub index: usize,
    /// True board pose in the rig frame.
    #[serde(rename = "T_rig_board")]
    pub t_rig_board: Pose,
    /// Observations, one per camera that saw the board.
    pub observations: Vec<CameraObservation>,
}

/// A whole calibration set (`calib_set.json`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CalibSet {
    /// Generator options.
    pub config: CalibSetConfig,
    /// The board.
    pub board: BoardLayout,
    /// The true rig at the set's resolution.
    pub rig: Rig,
    /// The views.
    pub views: Vec<CalibView>,
}

fn scaled_rig(rig: &Rig, scale: f64) -> Rig {
    let mut r = rig.clone();
    for c in &mut r.cameras {
        c.model = c.model.scaled(scale);
    }
    r
}

/// Rotation whose z axis is `dir` and whose x axis is as close as possible to rig x.
fn facing(dir: &Vector3<f64>) -> Rotation3<f64> {
    let z = dir.normalize();
    let y = z.cross(&Vector3::x()).normalize();
    let x = y.cross(&z);
    Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, z]))
}

/// Samples a board pose in the rig frame. Every third view is centred in front of the rig
/// (seen by all cameras); the others aim at one camera's outer image regions.
fn sample_pose(rng: &mut ChaCha8Rng, rig: &Rig, k: usize, cfg: &CalibSetConfig) -> Pose {
    let d = rng.random_range(cfg.distance_m.0..cfg.distance_m.1);
    let cam = &rig.cameras[rng.random_range(0..rig.cameras.len())];
    let m = &cam.model;
    let tx = (m.width as f64 / 2.0) / m.fx;
    let ty = (m.height as f64 / 2.0) / m.fy;
    let (centre, frac) = if k % 3 == 0 { (Vector3::zeros(), 0.15) } else { (cam.t_rig_cam.translation(), 0.6) };
    let x = centre.x + rng.random_range(-frac..frac) * tx * d;
    let y = centre.y + rng.random_range(-frac..frac) * ty * d;
    let p = Vector3::new(x, y, d);
    let base = facing(&p);
    let ax = rng.random_range(-0.6..0.6);
    let ay = rng.random_range(-0.6..0.6);
    let az = rng.random_range(-0.35..0.35);
    let tilt = Rotation3::from_axis_angle(&Vector3::x_axis(), ax) * Rotation3::from_axis_angle(&Vector3::y_axis(), ay) * Rotation3::from_axis_angle(&Unit::new_normalize(Vector3::z()), az);
    Pose::from_parts(base * tilt, p)
}

/// Exact corners of the tags wholly visible (2 px margin, facing the camera) in `model`.
fn visible_corners(model: &CameraModel, t_cam_board: &Pose, board: &BoardLayout) -> Vec<TagCorners> {
    let normal = t_cam_board.transform_vector(&Vector3::z());
    let mut out = Vec::new();
    for k in 0..board.tags.len() {
        let mut px = [[0.0; 2]; 4];
        let mut ok = true;
        for (j, c) in board.corners(k).iter().enumerate() {
            let p = t_cam_board.transform_point(c);
            // Facing: the camera looks along +z of the board (onto its printed side).
            if p.z < 0.05 || normal.dot(&p.coords) / p.coords.norm() < 0.2 {
                ok = false;
                break;
            }
            // Points far outside the field of view can wrap through the distortion polynomial.
            let (x, y) = (p.x / p.z, p.y / p.z);
            if x.abs() > 1.3 * model.width as f64 / 2.0 / model.fx || y.abs() > 1.3 * model.height as f64 / 2.0 / model.fy {
                ok = false;
                break;
            }
            match model.project(&p) {
                Some(q) if q.x >= 2.0 && q.y >= 2.0 && q.x <= model.width as f64 - 3.0 && q.y <= model.height as f64 - 3.0 => px[j] = [q.x, q.y],
                _ => {
                    ok = false;
                    break;
                }
            }
        }
        if ok {
            out.push(TagCorners { id: board.tags[k].id, corners: px });
        }
    }
    out
}

/// Generates the views of a calibration set (no files written; images are not rendered here).
pub fn generate(rig: &Rig, board: &BoardLayout, cfg: &CalibSetConfig) -> Result<CalibSet, CoreError> {
    rig.validate()?;
    if !(cfg.scale > 0.0 && cfg.scale <= 1.0) {
        return Err(CoreError::invalid("scale", format!("must be in (0, 1], got {}", cfg.scale)));
    }
    let distances_ok = cfg.distance_m.0 > 0.0 && cfg.distance_m.1 > cfg.distance_m.0;
    if cfg.corner_noise_px.is_nan() || cfg.corner_noise_px < 0.0 || !distances_ok {
        return Err(CoreError::invalid("calibration set", "noise must be >= 0 and the distance range increasing"));
    }
    BoardTexture::new(board)?;
    let rig_s = scaled_rig(rig, cfg.scale);
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
    let noise = Normal::new(0.0, cfg.corner_noise_px.max(1e-300)).map_err(|e| CoreError::invalid("noise", e.to_string()))?;
    let mut views = Vec::with_capacity(cfg.views);
    let mut attempts = 0;
    while views.len() < cfg.views {
        attempts += 1;
        if attempts > cfg.views * 50 + 100 {
            return Err(CoreError::invalid("calibration set", "could not place the board in view; is it too large for the distance range?"));
        }
        let k = views.len();
        let t_rig_board = sample_pose(&mut rng, &rig_s, k, cfg);
        let mut observations = Vec::new();
        for cam in &rig_s.cameras {
            let t_cam_board = cam.t_rig_cam.inverse() * t_rig_board;
            let exact = visible_corners(&cam.model, &t_cam_board, board);
            if exact.len() < MIN_TAGS_PER_IMAGE {
                continue;
            }
            let noisy = exact.iter().map(|t| TagCorners { id: t.id, corners: t.corners.map(|[x, y]| if cfg.corner_noise_px > 0.0 { [x + noise.sample(&mut rng), y + noise.sample(&mut rng)] } else { [x, y] }) }).collect();
            let image = cfg.render.then(|| format!("view{k:03}_{}.png", cam.name));
            observations.push(CameraObservation { camera: cam.name.clone(), image, exact, noisy });
        }
        if observations.is_empty() {
            continue;
        }
        views.push(CalibView { index: k, t_rig_board, observations });
    }
    Ok(CalibSet { config: cfg.clone(), board: board.clone(), rig: rig_s, views })
}

/// Renders the board seen by `model` at `t_cam_board` as 8-bit grey, with `noise` grey levels
/// of Gaussian noise drawn from `seed`. Background (off the board) is a dim grey.
pub fn render_board(model: &CameraModel, t_cam_board: &Pose, board: &BoardLayout, noise: f64, seed: u64) -> Result<Plane<u8>, CoreError> {
    render_planes(model, &[(*t_cam_board, board)], noise, seed)
}

/// Renders several planar boards (each `(T_cam_board, layout)`; a single tag is a 1x1 board)
/// as 8-bit grey; the nearest board hit along each ray wins. 2x2 sub-samples per pixel, each
/// area-sampling the texture over its footprint; Lambertian shading from a fixed light,
/// vignetting, and Gaussian grey-level noise of `noise` (seeded by `seed`).
pub fn render_planes(model: &CameraModel, planes: &[(Pose, &BoardLayout)], noise: f64, seed: u64) -> Result<Plane<u8>, CoreError> {
    let texs = planes.iter().map(|(_, b)| BoardTexture::new(b)).collect::<Result<Vec<_>, _>>()?;
    let (w, h) = (model.width as usize, model.height as usize);
    let light = Vector3::new(0.3, -0.5, -1.0).normalize();
    // Per plane: rotation R_cam_plane, origin in the camera frame (m), unit normal, shade.
    type PlaneGeo = (Matrix3<f64>, Vector3<f64>, Vector3<f64>, f64);
    let geo: Vec<PlaneGeo> = planes
        .iter()
        .map(|(p, _)| {
            let r = p.rotation();
            let n = r.column(2).into_owned();
            (r, p.translation(), n, 0.35 + 0.65 * n.dot(&-light).abs())
        })
        .collect();
    let mut img = Plane::<u8>::new(w, h);
    img.data.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ (y as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
        let gauss = Normal::new(0.0, noise.max(1e-9)).expect("positive sigma");
        for (x, out) in row.iter_mut().enumerate() {
            let mut acc = 0.0f64;
            for (sx, sy) in [(-0.25, -0.25), (0.25, -0.25), (-0.25, 0.25), (0.25, 0.25)] {
                let (nx, ny) = model.normalize(&Point2::new(x as f64 + sx, y as f64 + sy));
                let d = Vector3::new(nx, ny, 1.0);
                let mut best: Option<(f64, f64)> = None;
                for ((r, t, n, shade), tex) in geo.iter().zip(&texs) {
                    let denom = n.dot(&d);
                    if denom.abs() < 1e-9 {
                        continue;
                    }
                    let lambda = n.dot(t) / denom;
                    if lambda <= 0.0 || best.map(|b| lambda >= b.0).unwrap_or(false) {
                        continue;
                    }
                    let p = r.transpose() * (d * lambda - t);
                    // Footprint of a quarter pixel on the board, metres.
                    let foot = 0.25 * lambda * d.norm() / model.fx / (denom.abs() / d.norm()).sqrt();
                    if let Some(v) = tex.sample(p.x, p.y, foot) {
                        best = Some((lambda, (0.06 + 0.8 * v as f64) * shade * 255.0));
                    }
                }
                acc += best.map(|b| b.1).unwrap_or(70.0);
            }
            let u = (x as f64 / w as f64 - 0.5, y as f64 / h as f64 - 0.5);
            let vignette = 1.0 - 0.25 * (u.0 * u.0 + u.1 * u.1);
            let v = acc / 4.0 * vignette + if noise > 0.0 { gauss.sample(&mut rng) } else { 0.0 };
            *out = v.round().clamp(0.0, 255.0) as u8;
        }
    });
    Ok(img)
}

/// Writes `calib_set.json`, `rig_true.json` and (when `set.config.render`) the images into
/// `dir`, calling `progress` after each rendered image. All files are written atomically.
pub fn write_calib_set(dir: &Path, set: &CalibSet, mut progress: impl FnMut()) -> Result<(), CoreError> {
    for view in &set.views {
        for obs in &view.observations {
            let Some(name) = &obs.image else { continue };
            let cam = set.rig.camera(&obs.camera).ok_or_else(|| CoreError::invalid("calibration set", format!("unknown camera {}", obs.camera)))?;
            let t_cam_board = cam.t_rig_cam.inverse() * view.t_rig_board;
            let seed = set.config.seed.wrapping_mul(1_000_003).wrapping_add((view.index * 16 + set.rig.cameras.iter().position(|c| c.name == cam.name).unwrap_or(0)) as u64);
            let img = render_board(&cam.model, &t_cam_board, &set.board, set.config.image_noise, seed)?;
            let path = dir.join(name);
            let mut png = Vec::new();
            image::GrayImage::from_raw(img.width as u32, img.height as u32, img.data)
                .ok_or_else(|| CoreError::invalid("image", "buffer size"))?
                .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
                .map_err(|e| CoreError::parse(&path, e.to_string()))?;
            tubeloc_core::files::write_atomic(&path, &png)?;
            progress();
        }
    }
    tubeloc_core::files::write_json(&dir.join("rig_true.json"), &set.rig)?;
    tubeloc_core::files::write_json(&dir.join("calib_set.json"), set)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_rig_has_paper_geometry() {
        let rig = default_rig();
        rig.validate().unwrap();
        assert_eq!(rig.cameras.len(), 4);
        assert!((rig.baseline("L20", "R20").unwrap() - 0.20).abs() < 2e-3);
        assert!((rig.baseline("L40", "R40").unwrap() - 0.40).abs() < 2e-3);
        for c in &rig.cameras {
            assert_eq!((c.model.width, c.model.height), (5472, 3648));
            assert!((c.model.hfov_deg() - 77.0).abs() < 0.5, "{}", c.model.hfov_deg());
            assert!(!c.model.distortion.is_zero());
        }
    }

    #[test]
    fn same_seed_same_set_and_simultaneous_views_exist() {
        let cfg = CalibSetConfig { views: 12, render: false, ..Default::default() };
        let a = generate(&default_rig(), &BoardLayout::default_board(), &cfg).unwrap();
        let b = generate(&default_rig(), &BoardLayout::default_board(), &cfg).unwrap();
        assert_eq!(serde_json::to_string(&a).unwrap(), serde_json::to_string(&b).unwrap());
        assert!(a.views.iter().any(|v| v.observations.len() == 4), "no view seen by all 4 cameras");
        // Exact corners reproject from the true pose.
        let v = &a.views[0];
        let obs = &v.observations[0];
        let cam = a.rig.camera(&obs.camera).unwrap();
        let k = a.board.tags.iter().position(|t| t.id == obs.exact[0].id).unwrap();
        let p = (cam.t_rig_cam.inverse() * v.t_rig_board).transform_point(&a.board.corners(k)[0]);
        let q = cam.model.project(&p).unwrap();
        assert!((q.x - obs.exact[0].corners[0][0]).abs() < 1e-9);
    }

    #[test]
    fn rendered_board_is_dark_on_tag_border_and_bright_on_ring() {
        let board = BoardLayout::grid(TagFamily::Tag36h11, 2, 1, 0.08, 0.12, 0);
        let model = CameraModel::from_hfov(320, 240, 60.0);
        let pose = Pose::from_parts(Rotation3::identity(), Vector3::new(0.0, 0.0, 0.5));
        let img = render_board(&model, &pose, &board, 0.0, 1).unwrap();
        // Tag 0 centred at x = -0.06: its black border top-left corner region vs white ring.
        let px = |x: f64, y: f64| model.project(&Point3::new(x, y, 0.5)).unwrap();
        let black = px(-0.06 - 0.035, -0.035);
        let white = px(-0.06 - 0.045, -0.045);
        assert!(img.get(black.x.round() as usize, black.y.round() as usize) < 60);
        assert!(img.get(white.x.round() as usize, white.y.round() as usize) > 150);
    }
}
