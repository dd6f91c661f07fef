//! Synthetic stereo pairs with exact disparity: benchmark scenes seen by both cameras of a rig
//! pair through the same crop window.
//!
//! The paper rig's cameras share orientation and intrinsics and sit on a bar along their x
//! axis, so a pair cropped with the same window (equal principal points) is already rectified:
//! a point at depth `Z` (left camera z, metres) appears at `x_r = x_l - d`, `y_r = y_l`, with
//!
//! ```text
//! d = f_x · B / Z      (pixels; B = baseline, metres)
//! ```
//!
//! Output folder (the contract other crates rely on):
//! - `annotations.json`: COCO like the benchmark (left images, tube masks, `T_cam_tube`, ...);
//!   every image also carries `right_file_name` (relative to `right/`), `pair: [L, R]`,
//!   `baseline_m`, `right_camera` (camera JSON), `T_left_right` (pose JSON) and
//!   `disparity_file_name` (relative to `disparity/`);
//! - `images/*.png` (left), `right/*.png`, `disparity/*.pfm`: exact left disparity in pixels
//!   from the rendered depth, `+inf` where the ray hits no surface (sky);
//! - `rig.json` (native-resolution rig).
//!
//! Everything is written under `<out>.tmp-<pid>` and renamed at the end.

use crate::dataset::{encode_png, pose_json, tube_category, DatasetSpec, DatasetSummary};
use crate::render::render;
use crate::rig::{paper_rig, stop_pose, STOP_RADIUS_M};
use crate::scene::{Scene, SceneConfig};
use crate::truth::tube_truth;
use crate::SynthError;
use nalgebra::Point3;
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde_json::{json, Map, Value};
use std::path::Path;
use tubeloc_core::{files, CameraModel, CocoAnnotation, CocoDataset, CocoImage, Plane, Pose, Rig};

/// A stereo set to render: the scenes, scale and crop of a benchmark preset, one rig pair.
#[derive(Clone, Debug)]
pub struct StereoSetSpec {
    /// Scenes, scale, crop side, stops, heights, rendering options (images per scene are
    /// replaced by `pairs_per_scene`).
    pub base: DatasetSpec,
    /// Left and right camera names of the paper rig (`("L20", "R20")` or `("L40", "R40")`).
    pub pair: (String, String),
    /// Stereo pairs drawn from each scene's views.
    pub pairs_per_scene: usize,
}

/// The rectified geometry of a rig pair: `T_left_right` and the baseline (metres).
/// Errors unless both cameras exist, share intrinsics and orientation, and the right camera
/// sits on the left camera's +x axis.
pub fn pair_geometry(rig: &Rig, left: &str, right: &str) -> Result<(Pose, f64), SynthError> {
    let names: Vec<&str> = rig.cameras.iter().map(|c| c.name.as_str()).collect();
    let find = |n: &str| rig.camera(n).ok_or_else(|| SynthError::Invalid(format!("rig has no camera {n:?} (cameras: {})", names.join(", "))));
    let (l, r) = (find(left)?, find(right)?);
    if l.model != r.model {
        return Err(SynthError::Invalid(format!("pair {left},{right}: intrinsics differ, the crops would not be rectified")));
    }
    let t = l.t_rig_cam.inverse() * r.t_rig_cam;
    let tr = t.translation();
    let rot_err = (t.rotation() - nalgebra::Matrix3::identity()).norm();
    if rot_err > 1e-9 || tr.y.abs() > 1e-9 || tr.z.abs() > 1e-9 || tr.x <= 0.0 {
        return Err(SynthError::Invalid(format!("pair {left},{right}: the right camera must share the left camera's orientation and sit on its +x axis (translation {:.4},{:.4},{:.4} m)", tr.x, tr.y, tr.z)));
    }
    Ok((t, tr.x))
}

/// Exact left disparity `f_x B / Z` from a camera-z depth map (`+inf` where depth is infinite).
pub fn disparity_from_depth(depth: &Plane<f32>, fx: f64, baseline_m: f64) -> Plane<f32> {
    let data = depth.data.iter().map(|&z| if z.is_finite() && z > 0.0 { (fx * baseline_m / z as f64) as f32 } else { f32::INFINITY }).collect();
    Plane::from_vec(depth.width, depth.height, data)
}

/// Portable float map (PFM, greyscale, little-endian, rows bottom to top).
pub fn encode_pfm(p: &Plane<f32>) -> Vec<u8> {
    let mut out = format!("Pf\n{} {}\n-1.0\n", p.width, p.height).into_bytes();
    out.reserve(p.data.len() * 4);
    for y in (0..p.height).rev() {
        for v in p.row(y) {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    out
}

/// One planned pair: stop, height and the crop origin shared by both cameras.
#[derive(Clone, Debug)]
struct PairView {
    stop: usize,
    height: f64,
    crop_x0: u32,
    crop_y0: u32,
}

/// Plans `n` pair views of a scene: random (stop, height) without repetition (cycling when
/// there are fewer), each cropped so that one whole tube is inside the left image.
fn plan_pairs(scene: &Scene, spec: &DatasetSpec, left: &tubeloc_core::RigCamera, n: usize, seed: u64) -> Result<Vec<PairView>, SynthError> {
    let mut all: Vec<(usize, f64)> = (0..spec.stops).flat_map(|s| spec.heights.iter().map(move |&h| (s, h))).collect();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    all.shuffle(&mut rng);
    let cam = left.model.scaled(spec.scale);
    let crop = spec.crop as i64;
    let mut views = Vec::new();
    for (stop, height) in all.iter().cycle().take(n.max(1) * 4 + 16).copied() {
        if views.len() == n {
            break;
        }
        let t_world_cam = stop_pose(&Point3::origin(), STOP_RADIUS_M, height, stop, spec.stops, scene.stop_offset)? * left.t_rig_cam;
        let Some((x0, y0)) = crate::dataset::crop_around_a_tube(scene, &cam, &t_world_cam, crop, &mut rng) else {
            continue;
        };
        views.push(PairView { stop, height, crop_x0: x0 as u32, crop_y0: y0 as u32 });
    }
    if views.len() < n {
        return Err(SynthError::Invalid(format!("could not find {n} pair views with a whole tube inside a {crop} px crop (scene seed {})", scene.seed)));
    }
    Ok(views)
}

/// Renders the stereo set into `out` (see the module doc). `overwrite` replaces an existing
/// folder. `progress(done, total)` is called after every pair.
pub fn write_stereo_set(spec: &StereoSetSpec, out: &Path, overwrite: bool, progress: &(dyn Fn(usize, usize) + Sync)) -> Result<DatasetSummary, SynthError> {
    spec.base.validate()?;
    if spec.pairs_per_scene == 0 {
        return Err(SynthError::Invalid("pairs per scene must be at least 1".into()));
    }
    pair_geometry(&paper_rig(), &spec.pair.0, &spec.pair.1)?;
    crate::dataset::write_folder_atomically(out, overwrite, |tmp| write_into(spec, tmp, progress))
}

fn write_into(spec: &StereoSetSpec, dir: &Path, progress: &(dyn Fn(usize, usize) + Sync)) -> Result<(usize, usize), SynthError> {
    for sub in ["images", "right", "disparity"] {
        std::fs::create_dir_all(dir.join(sub)).map_err(|e| tubeloc_core::CoreError::io(dir, e))?;
    }
    let rig = paper_rig();
    rig.save_json(&dir.join("rig.json"))?;
    let base = &spec.base;
    let total = base.scenes.len() * spec.pairs_per_scene;
    let done = std::sync::atomic::AtomicUsize::new(0);
    let (mut images, mut annotations) = (Vec::new(), Vec::new());
    for (si, ss) in base.scenes.iter().enumerate() {
        let mut cfg = SceneConfig::new(ss.terrain, ss.time, ss.split == "with-tags");
        cfg.extent_m = base.terrain_extent_m;
        cfg.cell_m = base.terrain_cell_m;
        cfg.tube_shape = base.tube_shape.clone();
        let scene = Scene::generate(&cfg, ss.seed)?;
        let ground_height = scene.nominal_ground_height(STOP_RADIUS_M);
        let left = rig.camera(&spec.pair.0).ok_or_else(|| SynthError::Invalid(format!("no camera {}", spec.pair.0)))?;
        let views = plan_pairs(&scene, base, left, spec.pairs_per_scene, ss.seed ^ 0x57e7e0)?;
        let rendered: Vec<Result<(CocoImage, Vec<CocoAnnotation>), SynthError>> = views
            .par_iter()
            .enumerate()
            .map(|(k, v)| {
                let r = render_pair(spec, &scene, ground_height, si, k, v, dir, &rig);
                progress(done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1, total);
                r
            })
            .collect();
        for r in rendered {
            let (img, anns) = r?;
            images.push(img);
            annotations.extend(anns);
        }
    }
    let (n_images, n_anns) = (images.len(), annotations.len());
    let ds = CocoDataset {
        info: Some(json!({
            "description": format!("tubeloc synthetic stereo pairs ({},{}), preset {}", spec.pair.0, spec.pair.1, base.preset),
            "generator": "tubeloc-synth stereo", "version": env!("CARGO_PKG_VERSION"), "seed": base.seed,
            "scale": base.scale, "crop": base.crop, "tube": base.tube_source,
            "disparity": "left disparity d = x_left - x_right = fx * baseline_m / Z (px), +inf where no surface; PFM",
            "frames": "world x east, y north, z up (m); cameras OpenCV; T_a_b maps b into a",
        })),
        licenses: None,
        images,
        annotations,
        categories: vec![tube_category()],
        extra: Map::new(),
    };
    ds.save(&dir.join("annotations.json"))?;
    Ok((n_images, n_anns))
}

#[allow(clippy::too_many_arguments)]
fn render_pair(spec: &StereoSetSpec, scene: &Scene, ground_height: f64, si: usize, k: usize, v: &PairView, dir: &Path, rig: &Rig) -> Result<(CocoImage, Vec<CocoAnnotation>), SynthError> {
    let base = &spec.base;
    let ss = &base.scenes[si];
    let (ln, rn) = (&spec.pair.0, &spec.pair.1);
    let (t_left_right, baseline) = pair_geometry(rig, ln, rn)?;
    let image_id = (si as u64 + 1) * 1000 + k as u64 + 1;
    let lc = rig.camera(ln).ok_or_else(|| SynthError::Invalid(format!("no camera {ln}")))?;
    let cam: CameraModel = lc.model.scaled(base.scale).cropped(v.crop_x0, v.crop_y0, base.crop, base.crop);
    let t_world_left = stop_pose(&Point3::origin(), STOP_RADIUS_M, v.height, v.stop, base.stops, scene.stop_offset)? * lc.t_rig_cam;
    let t_world_right = t_world_left * t_left_right;
    let mut opts = base.render;
    opts.noise_seed = ss.seed ^ image_id.wrapping_mul(0x2545_f491_4f6c_dd1d);
    let out_l = render(scene, &cam, &t_world_left, &opts);
    opts.noise_seed = ss.seed ^ image_id.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ 0x5151;
    let out_r = render(scene, &cam, &t_world_right, &opts);
    let truth = tube_truth(&scene.objects, &cam, &t_world_left, &out_l);
    let stem = format!("{image_id:06}_{}_{}_{}_s{}_h{}_{ln}{rn}", ss.split, ss.terrain.name(), ss.time.name(), v.stop, v.height);
    let (file_name, pfm_name) = (format!("{stem}.png"), format!("{stem}.pfm"));
    for (sub, o) in [("images", &out_l), ("right", &out_r)] {
        let path = dir.join(sub).join(&file_name);
        let png = encode_png(&o.rgb, cam.width, cam.height).map_err(|m| SynthError::Image { path: path.clone(), message: m })?;
        files::write_atomic(&path, &png)?;
    }
    let disp = disparity_from_depth(&out_l.depth, cam.fx, baseline);
    files::write_atomic(&dir.join("disparity").join(&pfm_name), &encode_pfm(&disp))?;
    let mut extra = Map::new();
    extra.insert("camera".into(), serde_json::to_value(&cam).unwrap_or(Value::Null));
    extra.insert("T_world_cam".into(), pose_json(&t_world_left));
    extra.insert("right_file_name".into(), json!(file_name));
    extra.insert("pair".into(), json!([ln, rn]));
    extra.insert("baseline_m".into(), json!(baseline));
    extra.insert("right_camera".into(), serde_json::to_value(&cam).unwrap_or(Value::Null));
    extra.insert("T_left_right".into(), pose_json(&t_left_right));
    extra.insert("disparity_file_name".into(), json!(pfm_name));
    extra.insert("terrain".into(), json!(ss.terrain.name()));
    extra.insert("time".into(), json!(ss.time.name()));
    extra.insert("height_m".into(), json!(v.height));
    extra.insert("ground_height_m".into(), json!(ground_height));
    extra.insert("stop".into(), json!(v.stop));
    extra.insert("camera_name".into(), json!(ln));
    extra.insert("split".into(), json!(ss.split));
    extra.insert("scene_index".into(), json!(si));
    extra.insert("scene_seed".into(), json!(ss.seed));
    extra.insert("scale".into(), json!(base.scale));
    extra.insert("crop_origin".into(), json!([v.crop_x0, v.crop_y0]));
    let image = CocoImage { id: image_id, width: cam.width, height: cam.height, file_name, extra };
    let anns = crate::dataset::scene_annotations(scene, &truth, image_id, &cam);
    Ok((image, anns))
}

#[cfg(test)]
mod tests {
    use super::*;
    use tubeloc_core::TubeModel;

    fn decode_pfm(bytes: &[u8]) -> Plane<f32> {
        let mut parts = Vec::new();
        let mut start = 0;
        for (i, &b) in bytes.iter().enumerate() {
            if b == b'\n' {
                parts.push(std::str::from_utf8(&bytes[start..i]).unwrap().to_string());
                start = i + 1;
                if parts.len() == 3 {
                    break;
                }
            }
        }
        assert_eq!(parts[0], "Pf");
        let dims: Vec<usize> = parts[1].split_whitespace().map(|v| v.parse().unwrap()).collect();
        let (w, h) = (dims[0], dims[1]);
        let vals: Vec<f32> = bytes[start..].chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect();
        let mut p = Plane::<f32>::new(w, h);
        for y in 0..h {
            p.data[y * w..(y + 1) * w].copy_from_slice(&vals[(h - 1 - y) * w..(h - y) * w]);
        }
        p
    }

    fn luma(path: &Path) -> Plane<u8> {
        let img = image::open(path).unwrap().to_luma8();
        Plane::from_vec(img.width() as usize, img.height() as usize, img.into_raw())
    }

    fn tiny_spec(seed: u64) -> StereoSetSpec {
        let mut base = DatasetSpec::preset("tiny", seed).unwrap().with_scenes(1).unwrap();
        base.crop = 160;
        StereoSetSpec { base, pair: ("L20".into(), "R20".into()), pairs_per_scene: 1 }
    }

    #[test]
    fn pairs_are_refused_unless_rectified() {
        let rig = paper_rig();
        let (t, b) = pair_geometry(&rig, "L40", "R40").unwrap();
        assert!((b - 0.4).abs() < 1e-12 && (t.translation().x - 0.4).abs() < 1e-12);
        let e = pair_geometry(&rig, "R20", "L20").unwrap_err().to_string();
        assert!(e.contains("+x axis"), "{e}");
        let e = pair_geometry(&rig, "L20", "X9").unwrap_err().to_string();
        assert!(e.contains("no camera \"X9\""), "{e}");
        let mut rig2 = rig.clone();
        rig2.cameras[2].model.fx *= 1.01;
        assert!(pair_geometry(&rig2, "L20", "R20").unwrap_err().to_string().contains("intrinsics differ"));
    }

    #[test]
    fn disparity_files_match_tube_geometry_and_images_and_are_deterministic() {
        let tmp = tempfile::tempdir().unwrap();
        let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
        let spec = tiny_spec(11);
        write_stereo_set(&spec, &a, false, &|_, _| {}).unwrap();
        write_stereo_set(&spec, &b, false, &|_, _| {}).unwrap();
        let ds = CocoDataset::load(&a.join("annotations.json")).unwrap();
        assert_eq!(ds.images.len(), 1);
        let img = &ds.images[0];
        let e = &img.extra;
        let cam: CameraModel = serde_json::from_value(e["camera"].clone()).unwrap();
        let b_m = e["baseline_m"].as_f64().unwrap();
        assert!((b_m - 0.2).abs() < 1e-12);
        assert_eq!(e["pair"], json!(["L20", "R20"]));
        let t_lr: Pose = serde_json::from_value(e["T_left_right"].clone()).unwrap();
        let disp_bytes = std::fs::read(a.join("disparity").join(e["disparity_file_name"].as_str().unwrap())).unwrap();
        let disp = decode_pfm(&disp_bytes);
        let left = luma(&a.join("images").join(&img.file_name));
        let right = luma(&a.join("right").join(e["right_file_name"].as_str().unwrap()));
        // Same seed, same bytes.
        for f in ["annotations.json", &format!("images/{}", img.file_name), &format!("right/{}", img.file_name)] {
            assert_eq!(std::fs::read(a.join(f)).unwrap(), std::fs::read(b.join(f)).unwrap(), "{f}");
        }
        assert_eq!(disp_bytes, std::fs::read(b.join("disparity").join(e["disparity_file_name"].as_str().unwrap())).unwrap());

        // Tube pixels: the point at depth Z = fx B / d lies on the tube surface, and it
        // projects into the right camera at x - d on the same row.
        let model = TubeModel::default();
        let ann = ds.annotations.iter().max_by(|p, q| p.area.total_cmp(&q.area)).unwrap();
        let t_cam_tube: Pose = serde_json::from_value(ann.extra["T_cam_tube"].clone()).unwrap();
        let mask = match &ann.segmentation {
            Some(tubeloc_core::Segmentation::CompressedRle { counts, size }) => tubeloc_core::Rle::from_compressed_string(counts, *size).unwrap().to_mask().unwrap(),
            _ => panic!("expected RLE"),
        };
        let (mut n, mut on_surface, mut photo_err, mut shifted_err) = (0usize, 0usize, 0.0f64, 0.0f64);
        for y in 2..cam.height as usize - 2 {
            for x in 2..cam.width as usize - 2 {
                if !mask.get(x, y) {
                    continue;
                }
                let d = disp.get(x, y) as f64;
                assert!(d.is_finite() && d > 0.0, "tube pixel ({x},{y}) has disparity {d}");
                let z = cam.fx * b_m / d;
                let p_left = cam.unproject_depth(&nalgebra::Point2::new(x as f64, y as f64), z);
                let p_tube = t_cam_tube.inverse().transform_point(&p_left);
                let r = (p_tube.x * p_tube.x + p_tube.y * p_tube.y).sqrt();
                if (r - model.radius_at(p_tube.z)).abs() < 0.5e-3 || p_tube.z.abs() > model.length / 2.0 - 1e-3 {
                    on_surface += 1;
                }
                let pr = cam.project(&t_lr.inverse().transform_point(&p_left)).unwrap();
                assert!((pr.x - (x as f64 - d)).abs() < 1e-6 && (pr.y - y as f64).abs() < 1e-6, "({x},{y}) -> {pr:?}, d {d}");
                let xr = (x as f64 - d).round() as i64;
                if xr >= 0 && (xr as usize) < right.width {
                    n += 1;
                    photo_err += (left.get(x, y) as f64 - right.get(xr as usize, y) as f64).abs();
                    let xs = (xr + 7).clamp(0, right.width as i64 - 1) as usize;
                    shifted_err += (left.get(x, y) as f64 - right.get(xs, y) as f64).abs();
                }
            }
        }
        eprintln!("tube pixels {n}, on surface {on_surface}, photometric error {:.2} (shifted by 7 px: {:.2})", photo_err / n as f64, shifted_err / n as f64);
        assert!(n > 50, "only {n} tube pixels");
        assert!(on_surface as f64 > 0.95 * n as f64, "{on_surface} of {n} points on the tube surface");
        let (pe, se) = (photo_err / n as f64, shifted_err / n as f64);
        assert!(pe < 0.5 * se, "right image does not match the disparity: {pe:.2} vs shifted {se:.2}");
    }
}
