//! Benchmark datasets: presets, view planning, rendering and the COCO writer.
//!
//! The paper preset mirrors the paper's dataset: a with-tags split (flagstone, CFA6, CFA2) and
//! a no-tags split (flagstone, CFA6, ditch, riverbed), each terrain in an am and a pm scene,
//! every scene seen from 8 stops × 2 heights × 4 cameras, and 256 + 568 = 824 images drawn
//! from those views. Images are rendered at half resolution and cropped to 1024 × 1024 at a
//! random place that keeps at least one whole tube inside.
//!
//! Output folder: `images/*.png`, `annotations.json` (COCO, with camera, pose and condition
//! attributes), `rig.json` (the native-resolution rig). Everything is written under
//! `<out>.tmp-<pid>` and renamed to `<out>` at the end, so a failed run leaves nothing partial.

use crate::render::{render, RenderOptions, SurfaceKind};
use crate::rig::{paper_rig, stop_pose, HEIGHTS_M, STOP_RADIUS_M};
use crate::scene::{Scene, SceneConfig, TimeOfDay};
use crate::terrain::TerrainKind;
use crate::truth::{projected_rect, tube_truth, TubeTruth};
use crate::tube_shape::TubeShape;
use crate::SynthError;
use nalgebra::Point3;
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde_json::{json, Map, Value};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use tubeloc_core::{files, CameraModel, CocoAnnotation, CocoCategory, CocoDataset, CocoImage, Pose, Rle, Segmentation, TubeModel};

/// One scene of a dataset.
#[derive(Clone, Debug)]
pub struct SceneSpec {
    /// `"with-tags"` or `"no-tags"`.
    pub split: &'static str,
    /// Terrain.
    pub terrain: TerrainKind,
    /// Capture session.
    pub time: TimeOfDay,
    /// Scene seed.
    pub seed: u64,
    /// Images to draw from this scene's views.
    pub images: usize,
}

/// A whole dataset to render.
#[derive(Clone, Debug)]
pub struct DatasetSpec {
    /// Preset name.
    pub preset: String,
    /// Scenes.
    pub scenes: Vec<SceneSpec>,
    /// Render scale relative to the native 5472 × 3648 cameras (0.5 in the paper protocol).
    pub scale: f64,
    /// Crop side, pixels.
    pub crop: u32,
    /// Tripod stops on the circle.
    pub stops: usize,
    /// Tripod heights, metres.
    pub heights: Vec<f64>,
    /// Terrain side, metres, and height-field spacing, metres.
    pub terrain_extent_m: f64,
    /// Height-field spacing, metres.
    pub terrain_cell_m: f64,
    /// Tube geometry and its description (for the metadata).
    pub tube_shape: Arc<TubeShape>,
    /// Where the tube geometry came from.
    pub tube_source: String,
    /// Master seed.
    pub seed: u64,
    /// Rendering options (the noise seed is set per image).
    pub render: RenderOptions,
}

/// Splits a total into `n` near-equal integer parts.
fn spread(total: usize, n: usize) -> Vec<usize> {
    (0..n).map(|i| total / n + usize::from(i < total % n)).collect()
}

impl DatasetSpec {
    /// A named preset: `"paper"` (824 images) or `"tiny"` (4 small images, for tests).
    pub fn preset(name: &str, seed: u64) -> Result<DatasetSpec, SynthError> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut scenes = Vec::new();
        let mut push = |split: &'static str, terrain, time, images| scenes.push(SceneSpec { split, terrain, time, seed: 0, images });
        let (scale, crop, extent, cell) = match name {
            "paper" => {
                let with = [TerrainKind::Flagstone, TerrainKind::Cfa6, TerrainKind::Cfa2];
                let without = [TerrainKind::Flagstone, TerrainKind::Cfa6, TerrainKind::Ditch, TerrainKind::Riverbed];
                let counts = spread(256, 6);
                for (k, (t, time)) in with.iter().flat_map(|t| [(*t, TimeOfDay::Am), (*t, TimeOfDay::Pm)]).enumerate() {
                    push("with-tags", t, time, counts[k]);
                }
                // 9 no-tags scenes (a second flagstone layout), 568 images.
                let counts = spread(568, 9);
                let mut list: Vec<(TerrainKind, TimeOfDay)> = without.iter().flat_map(|t| [(*t, TimeOfDay::Am), (*t, TimeOfDay::Pm)]).collect();
                list.push((TerrainKind::Flagstone, TimeOfDay::Am));
                for (k, (t, time)) in list.into_iter().enumerate() {
                    push("no-tags", t, time, counts[k]);
                }
                (0.5, 1024, 8.0, 0.005)
            }
            "tiny" => {
                push("with-tags", TerrainKind::Cfa6, TimeOfDay::Am, 2);
                push("no-tags", TerrainKind::Flagstone, TimeOfDay::Pm, 2);
                (0.125, 256, 5.0, 0.01)
            }
            other => return Err(SynthError::Invalid(format!("unknown preset {other:?} (known: paper, tiny)"))),
        };
        for s in &mut scenes {
            s.seed = rng.random();
        }
        Ok(DatasetSpec {
            preset: name.to_string(),
            scenes,
            scale,
            crop,
            stops: 8,
            heights: HEIGHTS_M.to_vec(),
            terrain_extent_m: extent,
            terrain_cell_m: cell,
            tube_shape: Arc::new(TubeShape::from_model(&TubeModel::default())),
            tube_source: "parametric data/tube.toml".into(),
            seed,
            render: RenderOptions::default(),
        })
    }

    /// Repeats (or truncates) the preset's scene list to `n` scenes, each new one with its own seed.
    pub fn with_scenes(mut self, n: usize) -> Result<DatasetSpec, SynthError> {
        if n == 0 {
            return Err(SynthError::Invalid("--scenes must be at least 1".into()));
        }
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed ^ 0x5ce9e5);
        let base = self.scenes.clone();
        self.scenes = (0..n)
            .map(|i| {
                let mut s = base[i % base.len()].clone();
                if i >= base.len() {
                    s.seed = rng.random();
                }
                s
            })
            .collect();
        Ok(self)
    }

    /// Checks the numbers before anything is written.
    pub fn validate(&self) -> Result<(), SynthError> {
        if !(self.scale.is_finite() && self.scale > 0.0 && self.scale <= 1.0) {
            return Err(SynthError::Invalid(format!("scale {} must be in (0, 1]", self.scale)));
        }
        let cam = paper_rig().cameras[0].model.scaled(self.scale);
        if self.crop < 16 || self.crop > cam.width.min(cam.height) {
            return Err(SynthError::Invalid(format!("crop {} px must be between 16 and {} (the scaled image is {}x{})", self.crop, cam.width.min(cam.height), cam.width, cam.height)));
        }
        if self.stops == 0 || self.heights.is_empty() || self.heights.iter().any(|h| !(h.is_finite() && *h > 0.1 && *h < 10.0)) {
            return Err(SynthError::Invalid("need at least one stop and heights between 0.1 and 10 m".into()));
        }
        for s in &self.scenes {
            let mut cfg = SceneConfig::new(s.terrain, s.time, s.split == "with-tags");
            cfg.extent_m = self.terrain_extent_m;
            cfg.cell_m = self.terrain_cell_m;
            cfg.validate()?;
        }
        Ok(())
    }

    /// Total number of images.
    pub fn total_images(&self) -> usize {
        self.scenes.iter().map(|s| s.images).sum()
    }
}

/// One planned image.
#[derive(Clone, Debug)]
struct View {
    stop: usize,
    height: f64,
    camera: usize,
    crop_x0: u32,
    crop_y0: u32,
}

/// Plans `n` views of a scene: random (stop, height, camera) without repetition, each with a
/// crop that keeps one whole tube (its projected bounding box) inside.
fn plan_views(scene: &Scene, spec: &DatasetSpec, n: usize, seed: u64) -> Result<Vec<View>, SynthError> {
    let rig = paper_rig();
    let mut all: Vec<(usize, f64, usize)> = Vec::new();
    for stop in 0..spec.stops {
        for &h in &spec.heights {
            for c in 0..rig.cameras.len() {
                all.push((stop, h, c));
            }
        }
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    all.shuffle(&mut rng);
    let mut views = Vec::new();
    let crop = spec.crop as i64;
    let mut candidates = all.into_iter().cycle().take(n.max(1) * 4 + 64);
    while views.len() < n {
        let Some((stop, height, c)) = candidates.next() else {
            return Err(SynthError::Invalid(format!("could not find {n} views with a whole tube inside a {crop} px crop (scene seed {})", scene.seed)));
        };
        let cam = rig.cameras[c].model.scaled(spec.scale);
        let t_world_cam = stop_pose(&Point3::origin(), STOP_RADIUS_M, height, stop, spec.stops, scene.stop_offset)? * rig.cameras[c].t_rig_cam;
        let Some((x0, y0)) = crop_around_a_tube(scene, &cam, &t_world_cam, crop, &mut rng) else {
            continue;
        };
        views.push(View { stop, height, camera: c, crop_x0: x0 as u32, crop_y0: y0 as u32 });
    }
    Ok(views)
}

/// A pose as JSON (`{rotation, translation}`).
pub fn pose_json(p: &Pose) -> Value {
    serde_json::to_value(p).unwrap_or(Value::Null)
}

/// Encodes RGB bytes as PNG (fast compression).
pub fn encode_png(rgb: &[u8], w: u32, h: u32) -> Result<Vec<u8>, String> {
    use image::ImageEncoder;
    let mut buf = Vec::new();
    let enc = image::codecs::png::PngEncoder::new_with_quality(&mut buf, image::codecs::png::CompressionType::Fast, image::codecs::png::FilterType::Adaptive);
    enc.write_image(rgb, w, h, image::ExtendedColorType::Rgb8).map_err(|e| e.to_string())?;
    Ok(buf)
}

/// What a finished run wrote.
#[derive(Clone, Debug)]
pub struct DatasetSummary {
    /// Output folder.
    pub out: PathBuf,
    /// Images written.
    pub images: usize,
    /// Annotations written.
    pub annotations: usize,
}

/// Renders the dataset (or shard `shard.0` of `shard.1`: scenes `s` with `s % N == I`) into
/// `out`. `overwrite` replaces an existing folder; otherwise an existing `out` is an error.
/// `progress(done, total)` is called after every image.
pub fn write_dataset(spec: &DatasetSpec, out: &Path, shard: (usize, usize), overwrite: bool, progress: &(dyn Fn(usize, usize) + Sync)) -> Result<DatasetSummary, SynthError> {
    spec.validate()?;
    let (si, sn) = shard;
    if sn == 0 || si >= sn {
        return Err(SynthError::Invalid(format!("shard {si}/{sn}: need 0 <= I < N")));
    }
    write_folder_atomically(out, overwrite, |tmp| write_into(spec, tmp, shard, progress))
}

/// Writes a dataset folder atomically: `fill` writes into `<out>.tmp-<pid>` and returns
/// `(images, annotations)`; on success the folder is renamed to `out` (replacing an existing
/// one only when `overwrite`), on failure it is removed, so `out` is never half-written.
/// Temporaries `<out>.tmp-<pid>` of processes that are no longer alive (killed runs) are
/// removed first ([`tubeloc_core::files::remove_stale_temporaries`]).
pub fn write_folder_atomically(out: &Path, overwrite: bool, fill: impl FnOnce(&Path) -> Result<(usize, usize), SynthError>) -> Result<DatasetSummary, SynthError> {
    tubeloc_core::files::remove_stale_temporaries(out)?;
    if out.exists() && !overwrite {
        return Err(SynthError::Invalid(format!("{} already exists (remove it or pass --force)", out.display())));
    }
    let name = out.file_name().ok_or_else(|| SynthError::Invalid(format!("{} has no folder name", out.display())))?;
    let tmp = out.with_file_name(format!("{}.tmp-{}", name.to_string_lossy(), std::process::id()));
    match fill(&tmp) {
        Ok((images, annotations)) => {
            if out.exists() {
                std::fs::remove_dir_all(out).map_err(|e| tubeloc_core::CoreError::io(out, e))?;
            }
            std::fs::rename(&tmp, out).map_err(|e| tubeloc_core::CoreError::io(out, e))?;
            Ok(DatasetSummary { out: out.to_path_buf(), images, annotations })
        }
        Err(e) => {
            let _ = std::fs::remove_dir_all(&tmp);
            Err(e)
        }
    }
}

fn write_into(spec: &DatasetSpec, dir: &Path, shard: (usize, usize), progress: &(dyn Fn(usize, usize) + Sync)) -> Result<(usize, usize), SynthError> {
    std::fs::create_dir_all(dir.join("images")).map_err(|e| tubeloc_core::CoreError::io(dir, e))?;
    let rig = paper_rig();
    rig.save_json(&dir.join("rig.json"))?;
    let mine: Vec<usize> = (0..spec.scenes.len()).filter(|s| s % shard.1 == shard.0).collect();
    let total: usize = mine.iter().map(|&s| spec.scenes[s].images).sum();
    let done = std::sync::atomic::AtomicUsize::new(0);
    let mut images = Vec::new();
    let mut annotations = Vec::new();
    let mut scenes_meta = Vec::new();
    for &si in &mine {
        let ss = &spec.scenes[si];
        let mut cfg = SceneConfig::new(ss.terrain, ss.time, ss.split == "with-tags");
        cfg.extent_m = spec.terrain_extent_m;
        cfg.cell_m = spec.terrain_cell_m;
        cfg.tube_shape = spec.tube_shape.clone();
        let scene = Scene::generate(&cfg, ss.seed)?;
        let views = plan_views(&scene, spec, ss.images, ss.seed ^ 0x71e3)?;
        let ground_height = scene.nominal_ground_height(STOP_RADIUS_M);
        let rendered: Vec<Result<(CocoImage, Vec<CocoAnnotation>), SynthError>> = views
            .par_iter()
            .enumerate()
            .map(|(k, v)| {
                let r = render_view(spec, &scene, ground_height, ss, si, k, v, dir, &rig);
                progress(done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1, total);
                r
            })
            .collect();
        for r in rendered {
            let (img, anns) = r?;
            images.push(img);
            annotations.extend(anns);
        }
        let tubes: Vec<Value> = scene.objects.tubes.iter().zip(&scene.tube_info).map(|(t, i)| json!({"T_world_tube": pose_json(&t.t_world_tube), "case": i.case, "dust": i.dust, "carries_tags": i.carries_tags})).collect();
        let mount = scene.mount.as_ref().map(|m| json!({"tube_index": m.tube_index, "tags": m.tags}));
        scenes_meta.push(json!({
            "scene_index": si, "split": ss.split, "terrain": ss.terrain.name(), "time": ss.time.name(), "seed": ss.seed,
            "sun": scene.sun, "solar_hour": scene.solar_hour, "day_of_year": scene.day_of_year,
            "rocks": scene.objects.rocks.len(), "tubes": tubes, "tag_mount": mount,
        }));
    }
    let n_images = images.len();
    let n_anns = annotations.len();
    let mut extra = Map::new();
    extra.insert("scenes".into(), Value::Array(scenes_meta));
    let ds = CocoDataset {
        info: Some(json!({
            "description": format!("tubeloc synthetic Mars-yard benchmark, preset {}", spec.preset),
            "generator": "tubeloc-synth", "version": env!("CARGO_PKG_VERSION"), "seed": spec.seed,
            "shard": [shard.0, shard.1], "scale": spec.scale, "crop": spec.crop, "tube": spec.tube_source,
            "frames": "world x east, y north, z up (m); cameras OpenCV; T_a_b maps b into a",
        })),
        licenses: None,
        images,
        annotations,
        categories: vec![tube_category()],
        extra,
    };
    ds.save(&dir.join("annotations.json"))?;
    Ok((n_images, n_anns))
}

/// Renders view `v` of `scene`; `ground_height`: the scene's nominal ground height
/// ([`Scene::nominal_ground_height`]), written as the image's `ground_height_m`.
#[allow(clippy::too_many_arguments)]
fn render_view(spec: &DatasetSpec, scene: &Scene, ground_height: f64, ss: &SceneSpec, si: usize, k: usize, v: &View, dir: &Path, rig: &tubeloc_core::Rig) -> Result<(CocoImage, Vec<CocoAnnotation>), SynthError> {
    let image_id = (si as u64 + 1) * 1000 + k as u64 + 1;
    let rc = &rig.cameras[v.camera];
    let cam: CameraModel = rc.model.scaled(spec.scale).cropped(v.crop_x0, v.crop_y0, spec.crop, spec.crop);
    let t_world_cam = stop_pose(&Point3::origin(), STOP_RADIUS_M, v.height, v.stop, spec.stops, scene.stop_offset)? * rc.t_rig_cam;
    let mut opts = spec.render;
    opts.noise_seed = ss.seed ^ image_id.wrapping_mul(0x2545_f491_4f6c_dd1d);
    let out = render(scene, &cam, &t_world_cam, &opts);
    let truth = tube_truth(&scene.objects, &cam, &t_world_cam, &out);
    let file_name = format!("{image_id:06}_{}_{}_{}_s{}_h{}_{}.png", ss.split, ss.terrain.name(), ss.time.name(), v.stop, v.height, rc.name);
    let png = encode_png(&out.rgb, cam.width, cam.height).map_err(|m| SynthError::Image { path: dir.join(&file_name), message: m })?;
    files::write_atomic(&dir.join("images").join(&file_name), &png)?;
    let t_cam_world = t_world_cam.inverse();
    let mut extra = Map::new();
    extra.insert("camera".into(), serde_json::to_value(&cam).unwrap_or(Value::Null));
    extra.insert("T_world_cam".into(), pose_json(&t_world_cam));
    extra.insert("terrain".into(), json!(ss.terrain.name()));
    extra.insert("time".into(), json!(ss.time.name()));
    extra.insert("height_m".into(), json!(v.height));
    extra.insert("ground_height_m".into(), json!(ground_height));
    extra.insert("stop".into(), json!(v.stop));
    extra.insert("camera_name".into(), json!(rc.name));
    extra.insert("split".into(), json!(ss.split));
    extra.insert("scene_index".into(), json!(si));
    extra.insert("scene_seed".into(), json!(ss.seed));
    extra.insert("scale".into(), json!(spec.scale));
    extra.insert("crop_origin".into(), json!([v.crop_x0, v.crop_y0]));
    extra.insert("sun".into(), json!(scene.sun));
    if let Some(m) = &scene.mount {
        let tags: Vec<Value> = m
            .tags
            .iter()
            .map(|t| {
                let corners: Vec<Option<[f64; 2]>> = t.corners_world.iter().map(|c| cam.project(&t_cam_world.transform_point(&Point3::new(c[0], c[1], c[2]))).map(|p| [p.x, p.y])).collect();
                let centre = cam.project(&t_cam_world.transform_point(&Point3::from(t.t_world_tag.translation())));
                let visible = centre.is_some_and(|c| cam.contains(&c) && out.surface.get(c.x.round().clamp(0.0, cam.width as f64 - 1.0) as usize, c.y.round().clamp(0.0, cam.height as f64 - 1.0) as usize) == SurfaceKind::Plate as u8)
                    && corners.iter().all(|c| c.is_some_and(|c| cam.contains(&nalgebra::Point2::new(c[0], c[1]))));
                json!({"id": t.id, "size_m": t.size_m, "corners_px": corners, "visible": visible, "T_cam_tag": pose_json(&(t_cam_world * t.t_world_tag)), "T_tube_tag": pose_json(&t.t_tube_tag)})
            })
            .collect();
        extra.insert("tags".into(), json!({"tube_index": m.tube_index, "tags": tags}));
    }
    let image = CocoImage { id: image_id, width: cam.width, height: cam.height, file_name, extra };
    let anns = scene_annotations(scene, &truth, image_id, &cam);
    Ok((image, anns))
}

/// A `crop` x `crop` window of the image of `cam` at `t_world_cam` that holds one whole tube
/// (a tube chosen at random among those whose projected box fits), placed at random around it:
/// its top-left corner `(x0, y0)`; `None` when no tube fits.
pub fn crop_around_a_tube(scene: &Scene, cam: &CameraModel, t_world_cam: &Pose, crop: i64, rng: &mut impl Rng) -> Option<(i64, i64)> {
    let (w, h) = (cam.width as i64, cam.height as i64);
    let mut fits: Vec<(i64, i64, i64, i64)> =
        (0..scene.objects.tubes.len()).filter_map(|i| projected_rect(&scene.objects, i, cam, t_world_cam)).filter(|&(u0, v0, u1, v1)| u0 >= 0 && v0 >= 0 && u1 < w && v1 < h && u1 - u0 < crop && v1 - v0 < crop).collect();
    if fits.is_empty() {
        return None;
    }
    fits.sort();
    let (u0, v0, u1, v1) = fits[rng.random_range(0..fits.len())];
    let xr = ((u1 - crop + 1).max(0), u0.min(w - crop));
    let yr = ((v1 - crop + 1).max(0), v0.min(h - crop));
    let x0 = rng.random_range(xr.0..=xr.1.max(xr.0));
    let y0 = rng.random_range(yr.0..=yr.1.max(yr.0));
    Some((x0, y0))
}

/// The COCO annotations of one rendered image: one per visible tube, with the scene's per-tube
/// attributes `case`, `dust`, `carries_tags`; ids `image_id * 100 + k` (k from 1).
pub fn scene_annotations(scene: &Scene, truth: &[TubeTruth], image_id: u64, cam: &CameraModel) -> Vec<CocoAnnotation> {
    truth
        .iter()
        .enumerate()
        .map(|(j, t)| {
            let info = &scene.tube_info[t.tube];
            let mut extra = Map::new();
            extra.insert("case".into(), json!(info.case));
            extra.insert("dust".into(), json!(info.dust));
            extra.insert("carries_tags".into(), json!(info.carries_tags));
            annotation_from_truth(image_id * 100 + j as u64 + 1, image_id, cam, t, extra)
        })
        .collect()
}

/// A COCO annotation (category 1, "tube") from one tube's truth: compressed-RLE visible mask,
/// its bbox and area, and the attributes `tube_index`, `visible_fraction`, `occlusion`,
/// `amodal_area`, `amodal_bbox`, `T_cam_tube`, plus `extra`.
pub fn annotation_from_truth(id: u64, image_id: u64, cam: &CameraModel, t: &crate::truth::TubeTruth, mut extra: Map<String, Value>) -> CocoAnnotation {
    let rle = Rle::from_mask(&t.visible);
    extra.insert("tube_index".into(), json!(t.tube));
    extra.insert("visible_fraction".into(), json!(t.visible_fraction));
    extra.insert("occlusion".into(), json!(t.occlusion.name()));
    extra.insert("amodal_area".into(), json!(t.amodal_area));
    extra.insert("amodal_bbox".into(), json!(t.amodal_bbox));
    extra.insert("T_cam_tube".into(), pose_json(&t.t_cam_tube));
    CocoAnnotation { id, image_id, category_id: 1, segmentation: Some(Segmentation::CompressedRle { size: [cam.height, cam.width], counts: rle.to_compressed_string() }), area: t.visible_area as f64, bbox: t.bbox, iscrowd: 0, extra }
}

/// The single COCO category of tubeloc datasets.
pub fn tube_category() -> CocoCategory {
    CocoCategory { id: 1, name: "tube".into(), extra: Map::from_iter([("supercategory".to_string(), json!("object"))]) }
}
