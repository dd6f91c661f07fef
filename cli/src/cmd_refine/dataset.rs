//! `tubeloc refine --dataset DIR`: refine in every image of a COCO dataset directory.

use super::{GroundArg, RefineArgs};
use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::path::PathBuf;
use tubeloc_core::{files, CameraModel, CocoDataset, CocoImage, Pose, Segmentation, TubeAxisPose, TubeDetection};
use tubeloc_eval::pose_summary::percentile;
use tubeloc_pipeline::{refine_frame, Frame, FrameOptions, GroundPlane, SeedItem, StereoView};
use tubeloc_refine::seed::{axis_state_of, perturbed};
use tubeloc_refine::{AxisState, Refiner};

/// What to refine in one image: detections, or seeds made from exact poses.
enum Work {
    Detection(TubeDetection),
    /// Seed state from an annotation's exact pose, with the annotation's box and segmentation
    /// (the region of its stereo points, standing in for a segmenter's mask).
    GtSeed(AxisState, [f64; 4], Option<Segmentation>),
}

impl Work {
    /// The item's mask (image `w x h`): the detection's, or the annotation's segmentation;
    /// `None` when absent or not decodable.
    fn mask(&self, h: u32, w: u32) -> Option<tubeloc_core::BinaryMask> {
        match self {
            Work::Detection(d) => d.mask.as_ref().and_then(|m| m.to_mask().ok()),
            Work::GtSeed(_, _, seg) => seg.as_ref().and_then(|s| s.to_rle(h, w).ok()).and_then(|r| r.to_mask().ok()),
        }
    }
}

/// The nominal ground plane in the camera frame of an image with `T_world_cam`: world
/// `z = ground_height_m` (the image's field, written by `tubeloc synth`: the median terrain
/// height within the capture stops), or world `z = 0` for datasets without it
/// ([`tubeloc_core::geometry::ground_plane_at_height`]).
pub(crate) fn ground_of(img: &CocoImage) -> Result<Option<GroundPlane>> {
    let Some(v) = img.extra.get("T_world_cam") else { return Ok(None) };
    let t: Pose = serde_json::from_value(v.clone()).with_context(|| format!("image {}: T_world_cam", img.id))?;
    let h = match img.extra.get("ground_height_m") {
        None => 0.0,
        Some(v) => v.as_f64().filter(|h| h.is_finite()).with_context(|| format!("image {}: ground_height_m must be a finite number of metres, got {v}", img.id))?,
    };
    let (normal, offset) = tubeloc_core::geometry::ground_plane_at_height(&t, h);
    Ok(Some(GroundPlane { normal, offset }))
}

pub(crate) fn camera_of(img: &CocoImage) -> Result<CameraModel> {
    let v = img.extra.get("camera").with_context(|| format!("image {} has no \"camera\" (needed in dataset mode)", img.id))?;
    let c: CameraModel = serde_json::from_value(v.clone()).with_context(|| format!("image {}: camera", img.id))?;
    c.validate().with_context(|| format!("image {}: camera", img.id))?;
    Ok(c)
}

/// The right view of an image (`--stereo`): the right image and the pair geometry from
/// `images[]` (`right_file_name` under `DIR/right/`, `right_camera`, `T_left_right`).
pub(crate) fn right_view_of(dir: &std::path::Path, im: &CocoImage) -> Result<(image::DynamicImage, CameraModel, Pose)> {
    let field = |k: &str| im.extra.get(k).with_context(|| format!("image {} has no {k:?} (needed by --stereo)", im.id));
    let rname = field("right_file_name")?.as_str().with_context(|| format!("image {}: right_file_name is not a string", im.id))?;
    let rcam: CameraModel = serde_json::from_value(field("right_camera")?.clone()).with_context(|| format!("image {}: right_camera", im.id))?;
    let t_lr: Pose = serde_json::from_value(field("T_left_right")?.clone()).with_context(|| format!("image {}: T_left_right", im.id))?;
    let rpath = dir.join("right").join(rname);
    let right = tubeloc_detect::input::open_eight_bit(&rpath).with_context(|| format!("cannot read image {}", rpath.display()))?;
    Ok((right, rcam, t_lr))
}

fn parse_pair(s: &str) -> Result<(f64, f64)> {
    let v: Vec<f64> = s.split(',').map(|t| t.trim().parse::<f64>()).collect::<std::result::Result<_, _>>().with_context(|| format!("--gt-seeds {s:?}: expected MM,DEG"))?;
    if v.len() != 2 || v.iter().any(|x| !x.is_finite() || *x < 0.0) {
        bail!("--gt-seeds {s:?}: expected two non-negative numbers MM,DEG");
    }
    Ok((v[0], v[1]))
}

/// Where the seeds of a dataset refinement come from.
#[derive(Clone, Debug)]
pub(crate) enum DatasetSeeds {
    /// A detections file (COCO results with seeds), matched to the images by image id.
    Detections(PathBuf),
    /// The annotations' exact poses perturbed by `pos_mm` (uniform per coordinate) and
    /// `deg` (axis turn), random seed `seed`, for tubes at least `min_visible` visible.
    Gt { pos_mm: f64, deg: f64, seed: u64, min_visible: f64 },
}

/// A refinement over a COCO dataset directory (`tubeloc refine --dataset`), as `demo` and
/// `bench` run it without going through command-line words.
#[derive(Clone, Debug)]
pub(crate) struct DatasetJob {
    /// The dataset directory (annotations.json + images/).
    pub dataset: PathBuf,
    /// Only images of this split.
    pub split: Option<String>,
    /// Only the first N images.
    pub max_images: Option<usize>,
    /// The seeds.
    pub seeds: DatasetSeeds,
    /// The camera the detections' template poses were computed with, if not each image's.
    pub detections_camera: Option<PathBuf>,
    /// The ground plane: one plane, or each image's nominal ground.
    pub ground: Option<GroundArg>,
    /// Add the stereo term with each image's right image.
    pub stereo: bool,
    /// Fit to the seeds' mask boundaries instead of the image edges.
    pub mask_term: bool,
    /// Refiner and stage settings.
    pub settings: tubeloc_pipeline::LocatorSettings,
    /// Output poses.
    pub out: PathBuf,
    /// Output seeds (as poses).
    pub seeds_out: Option<PathBuf>,
    /// Output detections with snapped masks.
    pub snapped_out: Option<PathBuf>,
    /// Scores of the snapped detections from their poses' evidence (`--pose-evidence`).
    pub pose_evidence: Option<tubeloc_core::PoseEvidence>,
}

impl DatasetJob {
    /// The job with the shipped settings: refine every image of `dataset` from `seeds`, poses
    /// to `out`.
    pub fn new(dataset: PathBuf, seeds: DatasetSeeds, out: PathBuf) -> Self {
        DatasetJob { dataset, split: None, max_images: None, seeds, detections_camera: None, ground: None, stereo: false, mask_term: false, settings: Default::default(), out, seeds_out: None, snapped_out: None, pose_evidence: None }
    }
}

/// Runs the dataset mode of the arguments.
pub fn run(args: &RefineArgs) -> Result<()> {
    let seeds = match (&args.detections, &args.gt_seeds) {
        (Some(p), None) => DatasetSeeds::Detections(p.clone()),
        (None, Some(spec)) => {
            let (pos_mm, deg) = parse_pair(spec)?;
            DatasetSeeds::Gt { pos_mm, deg, seed: args.seed, min_visible: args.min_visible }
        }
        _ => bail!("dataset mode needs exactly one of --detections or --gt-seeds"),
    };
    let job = DatasetJob {
        dataset: args.dataset.clone().context("--dataset")?,
        split: args.split.clone(),
        max_images: args.max_images,
        seeds,
        detections_camera: args.detections_camera.clone(),
        ground: args.ground,
        stereo: args.stereo,
        mask_term: args.mask_term,
        settings: args.settings()?,
        out: args.out.clone(),
        seeds_out: args.seeds_out.clone(),
        snapped_out: args.snapped_out.clone(),
        pose_evidence: super::pose_evidence_of(args.pose_evidence.as_deref())?,
    };
    refine_dataset(&job)
}

/// Runs a dataset refinement: images in parallel, each through the pipeline's
/// [`refine_frame`]; writes the poses (and seeds, snapped detections) and reports the fit time
/// per seed on stderr.
pub(crate) fn refine_dataset(args: &DatasetJob) -> Result<()> {
    let dir = &args.dataset;
    let ann = dir.join("annotations.json");
    let ds = CocoDataset::load(&ann).with_context(|| format!("reading {}", ann.display()))?;
    let mut settings = args.settings.clone();
    if args.snapped_out.is_some() && !matches!(args.seeds, DatasetSeeds::Detections(_)) {
        bail!("--snapped-out needs --detections (the masks to snap)");
    }
    let auto_ground = args.ground == Some(GroundArg::Auto);
    if auto_ground {
        // The nominal ground (world z = ground_height_m of the tripod pose) is the terrain's
        // level, but the terrain has relief about it: its orientation is a prior (tubes lie
        // parallel to it), its height is not a constraint (mask seeds' settings weigh it).
        settings.refine.priors.ground_height_known = false;
    }
    let refiner = Refiner::new(&settings.tube, settings.refine.clone()).context("building the refiner")?;
    let snap = settings.stages.snap;
    let mut images: Vec<&CocoImage> = ds.images.iter().filter(|im| args.split.as_ref().is_none_or(|s| im.extra.get("split").and_then(|v| v.as_str()) == Some(s.as_str()))).collect();
    if let Some(n) = args.max_images {
        images.truncate(n);
    }
    if images.is_empty() {
        bail!("{}: no images{}", ann.display(), args.split.as_ref().map(|s| format!(" in split {s:?}")).unwrap_or_default());
    }
    // Work per image.
    let mut work: BTreeMap<u64, Vec<Work>> = images.iter().map(|im| (im.id, Vec::new())).collect();
    match &args.seeds {
        DatasetSeeds::Detections(p) => {
            for d in tubeloc_core::detection::read_coco_results(p)? {
                if let Some(w) = work.get_mut(&d.image_id) {
                    w.push(Work::Detection(d));
                }
            }
        }
        DatasetSeeds::Gt { pos_mm, deg, seed, min_visible } => {
            let (pos, deg) = (pos_mm * 1e-3, *deg);
            for a in &ds.annotations {
                let Some(w) = work.get_mut(&a.image_id) else { continue };
                let vis = a.extra.get("visible_fraction").and_then(|v| v.as_f64()).unwrap_or(1.0);
                let Some(v) = a.extra.get("T_cam_tube") else { continue };
                if vis < *min_visible {
                    continue;
                }
                let t: Pose = serde_json::from_value(v.clone()).with_context(|| format!("{}: annotation {}: T_cam_tube", ann.display(), a.id))?;
                w.push(Work::GtSeed(perturbed(&axis_state_of(&t), pos, deg, seed ^ a.id.wrapping_mul(0x9E37_79B9_7F4A_7C15)), a.bbox, a.segmentation.clone()));
            }
        }
    }
    let det_camera = match &args.detections_camera {
        Some(p) => Some(tubeloc_calib::read_camera(p).with_context(|| format!("detections camera {}", p.display()))?),
        None => None,
    };
    let fixed_ground = match args.ground {
        Some(GroundArg::Plane(g)) => Some(g),
        _ => None,
    };
    let opts = FrameOptions { mask_term: args.mask_term, seeds: args.seeds_out.is_some(), detections_camera: det_camera };
    let bar = ProgressBar::new(images.len() as u64);
    bar.set_style(ProgressStyle::with_template("refine {bar:30} {pos}/{len} images {elapsed}<{eta}").expect("template"));
    type ImageResult = (Vec<TubeAxisPose>, Vec<TubeAxisPose>, Vec<(TubeDetection, bool)>, Vec<f64>);
    let per_image: Vec<ImageResult> = images
        .par_iter()
        .map(|im| -> Result<_> {
            let items = &work[&im.id];
            if items.is_empty() {
                bar.inc(1);
                return Ok((Vec::new(), Vec::new(), Vec::new(), Vec::new()));
            }
            let camera = camera_of(im)?;
            let ground = if auto_ground { ground_of(im)? } else { fixed_ground };
            let path = {
                let p = dir.join(&im.file_name);
                if p.exists() {
                    p
                } else {
                    dir.join("images").join(&im.file_name)
                }
            };
            let image = tubeloc_detect::input::open_eight_bit(&path).with_context(|| format!("cannot read image {}", path.display()))?;
            if image.width() != camera.width || image.height() != camera.height {
                bail!("{} is {}x{} but its camera is {}x{}", path.display(), image.width(), image.height(), camera.width, camera.height);
            }
            let right = if args.stereo { Some(right_view_of(dir, im)?) } else { None };
            let (h, w) = (camera.height, camera.width);
            let seeds: Vec<SeedItem> = items
                .iter()
                .map(|it| match it {
                    Work::Detection(d) => SeedItem::Detection(d.clone()),
                    Work::GtSeed(st, bbox, _) => SeedItem::Explicit { state: *st, bbox: *bbox, mask: it.mask(h, w) },
                })
                .collect();
            let frame = Frame { image: &image, camera: &camera, image_id: im.id, ground, stereo: right.as_ref().map(|(img, rcam, t)| StereoView { right: img, right_camera: rcam, t_left_right: *t }) };
            let refined = refine_frame(&refiner, &settings, &frame, &seeds, &opts).with_context(|| match &right {
                Some(_) => format!("refining {} (stereo, {})", path.display(), dir.join("right").display()),
                None => format!("refining {}", path.display()),
            })?;
            // Diagnostics: TUBELOC_DEBUG_STEREO_DIR=D writes each image's stereo points (left
            // camera frame, metres, one list per work item) to D/<image id>.json and, with
            // the scene-occlusion test on, its scene depth map to D/<image id>_depth_f32.bin.
            if let (Ok(dbg), true) = (std::env::var("TUBELOC_DEBUG_STEREO_DIR"), args.stereo) {
                let pts: Vec<Vec<[f64; 3]>> = refined.stereo_points.iter().map(|v| v.iter().map(|p| [p.x, p.y, p.z]).collect()).collect();
                files::write_json(&std::path::Path::new(&dbg).join(format!("{}.json", im.id)), &pts)?;
                if let (Some(d), true) = (&refined.scene_depth, settings.stages.scene_occlusion) {
                    // The scene depth map as raw little-endian f32 (width x height, NaN unknown).
                    let bytes: Vec<u8> = d.data.iter().flat_map(|v| v.to_le_bytes()).collect();
                    files::write_atomic(&std::path::Path::new(&dbg).join(format!("{}_depth_f32.bin", im.id)), &bytes)?;
                }
            }
            let (poses, seeds, fit_ms) = (refined.poses, refined.seeds, refined.fit_ms);
            let snapped = match args.snapped_out {
                Some(_) => items
                    .iter()
                    .zip(&poses)
                    .filter_map(|(w, p)| match w {
                        Work::Detection(d) => {
                            let mut d = d.clone();
                            let s = tubeloc_pipeline::stages::snapped_detection(&mut d, p, &refiner, &camera, &snap);
                            Some((d, s))
                        }
                        Work::GtSeed(..) => None,
                    })
                    .collect(),
                None => Vec::new(),
            };
            bar.inc(1);
            Ok((poses, seeds, snapped, fit_ms))
        })
        .collect::<Result<_>>()?;
    bar.finish_and_clear();
    let (mut poses, mut seeds, mut snapped, mut fit_ms) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for (p, s, m, t) in per_image {
        poses.extend(p);
        seeds.extend(s);
        snapped.extend(m);
        fit_ms.extend(t);
    }
    let mut reasons: BTreeMap<String, usize> = BTreeMap::new();
    for p in &poses {
        if let Some(f) = &p.failure {
            *reasons.entry(format!("{:?}", f.reason)).or_default() += 1;
        }
    }
    files::write_json(&args.out, &poses).with_context(|| format!("writing {}", args.out.display()))?;
    if let Some(s) = &args.seeds_out {
        files::write_json(s, &seeds).with_context(|| format!("writing {}", s.display()))?;
    }
    super::write_snapped(args.snapped_out.as_deref(), &snapped, &poses, args.pose_evidence.as_ref())?;
    let out: PathBuf = args.out.clone();
    eprintln!("{} images, {} poses ({} converged; failures {:?}) -> {}", images.len(), poses.len(), poses.iter().filter(|p| p.converged).count(), reasons, out.display());
    fit_ms.sort_by(f64::total_cmp);
    if let (Some(median), Some(p90)) = (percentile(&fit_ms, 50.0), percentile(&fit_ms, 90.0)) {
        eprintln!("refinement time per seed (the fit alone, without loading, stereo matching or the stages after it): median {median:.2} ms, p90 {p90:.2} ms over {} seeds on {} threads", fit_ms.len(), rayon::current_num_threads());
    }
    let without_points = poses.iter().filter(|p| p.converged && p.residuals.stereo_points == 0).count();
    if args.stereo && without_points > 0 {
        eprintln!("{without_points} converged poses have no stereo points (outside the right camera's view, or unmatched): they are mono poses");
    }
    Ok(())
}
