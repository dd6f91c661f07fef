//! The `line2d` method of `tubeloc detect`: Line2D template matching with a library built by
//! `tubeloc templates build`, writing COCO results with the coarse pose and template id.

use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use tubeloc_core::{CameraModel, GroundPlane};
use tubeloc_detect::line2d::{Line2dDetection, Line2dDetector, MatchParams, Verifier, VerifyParams};
use tubeloc_pipeline::pose_verifier::{PoseVerification, PoseVerifier, CLUTTER_FLOOR};

/// Line2D options of `tubeloc detect`.
#[derive(clap::Args, Clone, Debug)]
pub struct Line2dOpts {
    /// Template library (`--method line2d|fused`), from `tubeloc templates build`. Default: the
    /// default library (what `tubeloc templates build` writes at its defaults), built in memory
    /// in about 1 s; images of any camera are resampled to its pixel scale.
    #[arg(long)]
    pub templates: Option<PathBuf>,
    /// Camera JSON of the images (coarse poses; an image whose focal length differs from the
    /// library's is resampled to the library's scale). `tubeloc detect --image F` also takes a
    /// PDS camera list (`cahv_to_pinhole.py`'s JSON: F's camera, named after its file) or F's
    /// PDS3 label (`.LBL`, or an `.IMG` with its label), and the ground under the camera (unless
    /// --ground).
    #[arg(long)]
    pub camera: Option<PathBuf>,
    /// Line2D detection threshold, percent of the maximal similarity.
    #[arg(long, default_value_t = 80.0, value_parser = crate::args::percent_f32)]
    pub threshold: f32,
    /// Line2D coarse-level threshold, percent (default: --threshold).
    #[arg(long, value_parser = crate::args::percent_f32)]
    pub coarse_threshold: Option<f32>,
    /// Line2D NMS: silhouette IoU above which the weaker detection is dropped.
    #[arg(long, default_value_t = 0.3, value_parser = crate::args::unit_interval_f32)]
    pub nms_iou: f32,
    /// Line2D: maximum detections per image.
    #[arg(long, default_value_t = 100, value_parser = crate::args::positive_usize)]
    pub max_detections: usize,
    /// Line2D: minimum Sobel gradient magnitude.
    #[arg(long, default_value_t = 30.0, value_parser = crate::args::non_negative_f32)]
    pub grad_threshold: f32,
    /// Line2D verification: weight of the silhouette-vs-ring luminance contrast in the score
    /// (score = (similarity/100 + w clamp(C,-1,1)) / (1 + w)).
    #[arg(long, default_value_t = 0.5, value_parser = crate::args::non_negative_f32)]
    pub contrast_weight: f32,
    /// Line2D verification: drop matches whose contrast C is below this.
    #[arg(long, default_value_t = -0.2, allow_hyphen_values = true, value_parser = crate::args::finite_f32)]
    pub min_contrast: f32,
    /// Line2D verification: ring of background samples from this many px outside the silhouette...
    #[arg(long, default_value_t = 2)]
    pub ring_inner: u32,
    /// ...to this many px (inside samples are at least --ring-inner px inside).
    #[arg(long, default_value_t = 6, value_parser = crate::args::positive_u32)]
    pub ring_outer: u32,
    /// Line2D verification: weight of the contrast when choosing the template (mask, pose)
    /// within an NMS cluster (0 = Line2D re-ranking only).
    #[arg(long, default_value_t = 0.0, value_parser = crate::args::non_negative_f32)]
    pub rerank_contrast_weight: f32,
    /// Line2D: matches within this many similarity points of a cluster's best are re-ranked.
    #[arg(long, default_value_t = 15.0, value_parser = crate::args::non_negative_f32)]
    pub rerank_margin: f32,
    /// Line2D: re-ranking bonus `w area / max area` for larger silhouettes within a cluster.
    #[arg(long, default_value_t = 0.3, value_parser = crate::args::non_negative_f32)]
    pub rerank_area_weight: f32,
    /// Line2D: at most this many coarse candidates per template go to the full-resolution
    /// search, the best by coarse score (0 = all).
    #[arg(long, default_value_t = tubeloc_detect::line2d::params::MAX_CANDIDATES)]
    pub max_candidates: usize,
    /// Line2D: at most this many coarse candidates per megapixel over all templates go to the
    /// full-resolution search, the best by coarse similarity (0 = no budget)
    #[arg(long, default_value_t = tubeloc_detect::line2d::params::MAX_CANDIDATES_PER_MPX)]
    pub max_candidates_per_mpx: usize,
    /// Line2D: also search the image enlarged by this factor beyond the library's scale (at
    /// most --max-upsample in all), for tubes up to that many times farther than the library's
    /// farthest templates (1 = one search); "K" for every image, or COLOUR:GREY where GREY is
    /// for grey images enlarged to the library's scale (a mono camera with coarser pixels than
    /// the library's, e.g. Navcam)
    #[arg(long, default_value = DEFAULT_FAR_SCALE, value_parser = crate::args::far_scale)]
    pub far_scale: (f64, f64),
    /// Line2D: largest factor by which an image is enlarged to the library's scale: an image
    /// of a camera that needs more is not searched (with a warning), and the far search runs
    /// only where the image enlarged --far-scale times more stays within it
    #[arg(long, default_value_t = tubeloc_detect::line2d::params::MAX_UPSAMPLE, value_parser = crate::args::upsample_limit)]
    pub max_upsample: f64,
    /// Line2D ground consistency, where the image's ground plane is known (a dataset image's
    /// `ground`, or --ground): a match is kept only when its template's distance is within
    /// MIN:MAX times the ground's distance along its centre's ray (a tube lies on the ground;
    /// matches in the sky go too), or "off"
    #[arg(long, default_value = DEFAULT_GROUND_RANGE, value_parser = crate::args::ground_range)]
    pub ground_range: String,
    /// Line2D: no radiometric verification (rank by the Line2D similarity alone).
    #[arg(long)]
    pub no_verify: bool,
    /// Line2D clutter verifier: JSON of fitted weights (`tubeloc templates fit-verifier`;
    /// default: the shipped verifier, embedded in the program).
    #[arg(long)]
    pub verifier: Option<PathBuf>,
    /// Line2D clutter verifier: keep detections whose probability of being a tube is at least
    /// this (default: the verifier's own threshold, chosen on real validation composites). With
    /// the pose verifier: the least clutter probability of a candidate it refines (default 0).
    #[arg(long, value_parser = crate::args::unit_interval_f32)]
    pub min_probability: Option<f32>,
    /// Line2D: no clutter verifier (the score is the radiometric verified score, nothing is
    /// dropped by probability). Needs `--pose-verifier off`.
    #[arg(long)]
    pub no_verifier: bool,
    /// Line2D pose verification (`--method line2d`, where the image's ground is known): every
    /// candidate the clutter verifier scores is refined on the ground, its mask snapped to the
    /// pose, scored by the probability that its pose is a tube, and kept at the cut of the
    /// image's kind (record 0068). `shipped` (embedded), a file from `tubeloc eval
    /// --fit-pose-verifier`, or `off` (the clutter verifier's cut alone). With it,
    /// `--min-probability` is the clutter probability a candidate needs to reach it (default 0)
    #[arg(long, default_value = "shipped")]
    pub pose_verifier: String,
}

impl Line2dOpts {
    /// Checks the options that depend on each other (a command-line error, exit 2).
    pub fn check(&self) -> Result<()> {
        if self.no_verifier && self.pose_verifier != "off" {
            return Err(crate::args::usage("--no-verifier needs --pose-verifier off: the pose verifier scores the clutter verifier's probability"));
        }
        crate::args::require_at_most(("--ring-inner", self.ring_inner), ("--ring-outer", self.ring_outer))
    }

    /// The pose verifier of `--pose-verifier` (`None` for `off`), loaded and checked.
    pub fn pose_verifier(&self) -> Result<Option<PoseVerifier>> {
        match self.pose_verifier.as_str() {
            "off" => Ok(None),
            spec => Ok(Some(tubeloc_pipeline::shipped::line2d_pose_verifier(spec).map_err(|e| anyhow::anyhow!("--pose-verifier: {e}"))?)),
        }
    }
}

/// The learned half of a fused detection (`tubeloc detect --method fused`).
pub struct Fusion {
    /// The learned model.
    pub model: tubeloc_detect::learned::LearnedModel,
    /// Its decoder settings.
    pub decode: tubeloc_detect::learned::DecodeConfig,
    /// Its working scale's range band (`None`: the image as it is).
    pub range: Option<tubeloc_detect::scale::RangeBand>,
    /// The model's name in messages.
    pub origin: String,
}

/// Line2D alone, verified by pose, or fused with the learned segmenter
/// ([`tubeloc_pipeline::FusedTubeDetector`]).
pub enum Line2dRunner {
    /// Line2D at its verifier's cut.
    Plain(Box<Line2dDetector>),
    /// Line2D candidates verified by their poses where the ground is known
    /// ([`tubeloc_pipeline::pose_verifier`]).
    Verified(Box<Line2dDetector>, Box<PoseVerification>),
    /// The learned detections and the verified Line2D ones, scored by their pose evidence.
    Fused(Box<tubeloc_pipeline::FusedTubeDetector>),
}

impl Line2dRunner {
    /// `det` alone; verified by `pose` (its clutter verifier then runs at `floor`, its own cuts
    /// kept for images without a ground); or fused with `fusion`'s learned model (which needs
    /// `pose`).
    pub fn new(mut det: Line2dDetector, fusion: Option<Fusion>, pose: Option<PoseVerifier>, floor: f32) -> Result<Self> {
        Ok(match (fusion, pose) {
            (Some(_), None) => bail!("--method fused verifies Line2D's candidates by their poses: leave out --pose-verifier off"),
            (Some(f), Some(p)) => {
                let mut learned = tubeloc_pipeline::LearnedDetector::new(f.model, f.decode, f.origin);
                learned.range = f.range;
                let evidence = tubeloc_pipeline::shipped::pose_evidence("shipped")?;
                Line2dRunner::Fused(Box::new(tubeloc_pipeline::FusedTubeDetector::new(learned, evidence, det, p)?))
            }
            (None, Some(p)) => {
                let verification = PoseVerification::for_matcher(&mut det, p, floor)?;
                Line2dRunner::Verified(Box::new(det), Box::new(verification))
            }
            (None, None) => Line2dRunner::Plain(Box::new(det)),
        })
    }

    /// The fused detector, where this runner is one.
    pub fn fused(&self) -> Option<&tubeloc_pipeline::FusedTubeDetector> {
        match self {
            Line2dRunner::Fused(f) => Some(f),
            _ => None,
        }
    }

    /// The Line2D detector (library and matching parameters).
    pub fn line2d(&self) -> &Line2dDetector {
        match self {
            Line2dRunner::Plain(d) | Line2dRunner::Verified(d, _) => d,
            Line2dRunner::Fused(f) => f.line2d(),
        }
    }

    /// Detections in `image` of `camera` with its ground, when known, as COCO results entries
    /// with image id `image_id`, and whether poses verified Line2D's candidates (a verified or
    /// fused runner's, on an image with a camera of its size and a ground).
    pub fn detect(&self, image: &image::DynamicImage, camera: Option<&CameraModel>, ground: Option<&GroundPlane>, image_id: u64) -> Result<(Vec<serde_json::Value>, bool)> {
        let json = |dets: Vec<Line2dDetection>| dets.iter().map(|d| d.to_coco_json(image_id)).collect::<Vec<_>>();
        match self {
            Line2dRunner::Verified(d, v) => {
                let (dets, verified) = v.detect(d, image, camera, ground, image_id)?;
                Ok((json(dets), verified))
            }
            Line2dRunner::Fused(f) => {
                let (camera, own) = fused_camera(f, image, camera);
                let found = f.detect_fused(image, &camera, ground, image_id)?;
                Ok((fused_json(found, image_id), own && ground.is_some()))
            }
            Line2dRunner::Plain(d) => {
                let rgb = tubeloc_detect::input::rgb8_pixels(image);
                let (w, h) = (image.width() as usize, image.height() as usize);
                Ok((json(d.detect_on_ground(&rgb, w, h, camera, ground)?), false))
            }
        }
    }
}

/// The camera the fused detector takes `image` under: `camera` where it is of the image's size
/// (and `true`), else the template library's focal lengths centred on the image (and `false`).
pub fn fused_camera(f: &tubeloc_pipeline::FusedTubeDetector, image: &image::DynamicImage, camera: Option<&CameraModel>) -> (CameraModel, bool) {
    let (w, h) = (image.width(), image.height());
    match camera.filter(|c| (c.width, c.height) == (w, h)) {
        Some(c) => (c.clone(), true),
        None => {
            let k = &f.line2d().library.params.camera;
            (CameraModel { width: w, height: h, fx: k.fx, fy: k.fy, cx: (w as f64 - 1.0) / 2.0, cy: (h as f64 - 1.0) / 2.0, distortion: Default::default() }, false)
        }
    }
}

/// Fused detections as COCO results entries of image `image_id`: Line2D's with their template
/// and probabilities, the learned ones as detections.
pub fn fused_json(found: Vec<tubeloc_pipeline::FusedDetection>, image_id: u64) -> Vec<serde_json::Value> {
    found
        .into_iter()
        .map(|d| match d.line2d {
            Some(l) => l.to_coco_json(image_id),
            None => serde_json::to_value(&d.detection).unwrap_or_default(),
        })
        .collect()
}

/// Default `--far-scale` (colour:grey): [`MatchParams::far_scale`] and
/// [`MatchParams::far_scale_grey`] of [`MatchParams::default`].
pub const DEFAULT_FAR_SCALE: &str = "1:1.4";

/// Default `--ground-range`: [`tubeloc_detect::line2d::GroundRange::default`].
pub const DEFAULT_GROUND_RANGE: &str = "0.55:1.25";

/// The Line2D detector and the fallback camera (`--camera`) that `opts` describe.
pub fn detector_from_opts(opts: &Line2dOpts) -> Result<(Line2dDetector, Option<CameraModel>)> {
    let lib = tubeloc_pipeline::shipped::template_library(opts.templates.as_deref())?;
    let camera = opts.camera.as_deref().map(|p: &Path| CameraModel::load_json(p).with_context(|| format!("reading {}", p.display()))).transpose()?;
    let mut params = MatchParams {
        threshold: opts.threshold,
        coarse_threshold: opts.coarse_threshold,
        nms_iou: opts.nms_iou,
        max_detections: opts.max_detections,
        rerank_margin: opts.rerank_margin,
        rerank_area_weight: opts.rerank_area_weight,
        max_candidates: opts.max_candidates,
        max_candidates_per_mpx: opts.max_candidates_per_mpx,
        far_scale: opts.far_scale.0,
        far_scale_grey: opts.far_scale.1,
        max_upsample: opts.max_upsample,
        ground_range: crate::args::parse_ground_range(&opts.ground_range).map_err(|e| anyhow::anyhow!("--ground-range {e}"))?,
        ..MatchParams::default()
    };
    params.gradient.mag_threshold = opts.grad_threshold;
    params.verify = (!opts.no_verify).then(|| VerifyParams {
        contrast_weight: opts.contrast_weight,
        min_contrast: opts.min_contrast,
        ring_inner: opts.ring_inner,
        ring_outer: opts.ring_outer,
        rerank_weight: opts.rerank_contrast_weight,
        ..VerifyParams::default()
    });
    params.verifier = if opts.no_verifier {
        None
    } else {
        let mut v = match &opts.verifier {
            Some(p) => {
                let text = std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?;
                Verifier::from_json(&text).map_err(|e| anyhow::anyhow!("{}: {e}", p.display()))?
            }
            None => Verifier::shipped(),
        };
        if let Some(t) = opts.min_probability {
            v.set_threshold(t);
        }
        Some(v)
    };
    Ok((Line2dDetector::new(lib, params)?, camera))
}

/// Runs Line2D on `images` (`(image_id, path)`) and returns COCO result entries. The coarse
/// pose of a detection uses the image's own camera from `cameras` (a dataset's
/// `images[].camera`: crops have their own principal points) when present, else `--camera`;
/// an image whose camera's focal length differs from the library's is matched resampled to
/// the library's scale and its detections mapped back. The image's ground from `grounds` (a
/// dataset's `images[].ground`), else `ground` (`--ground`), drives the ground-consistency
/// check.
///
/// With `fusion`, the learned detections of each image join Line2D's verified ones, all scored
/// by their pose evidence ([`tubeloc_pipeline::FusedTubeDetector`]).
pub fn run_line2d(opts: &Line2dOpts, images: &[(u64, PathBuf)], cameras: &BTreeMap<u64, CameraModel>, grounds: &BTreeMap<u64, GroundPlane>, ground: Option<&GroundPlane>, fusion: Option<Fusion>) -> Result<Vec<serde_json::Value>> {
    let (det, camera) = detector_from_opts(opts)?;
    let runner = Line2dRunner::new(det, fusion, opts.pose_verifier()?, opts.min_probability.unwrap_or(CLUTTER_FLOOR))?;
    let det = runner.line2d();
    let bar = ProgressBar::new(images.len() as u64);
    bar.set_style(ProgressStyle::with_template("{bar:40} {pos}/{len} images {elapsed}").unwrap_or_else(|_| ProgressStyle::default_bar()));
    let mut out = Vec::new();
    let mut warned_no_camera = false;
    let mut warned_unverified = false;
    for (id, path) in images {
        let img = tubeloc_detect::input::open_eight_bit(path).with_context(|| format!("reading {}", path.display()))?;
        if let Some(warn) = crate::cmd_detect::underexposure_warning(path, &img) {
            bar.suspend(|| eprintln!("{warn}"));
        }
        let cam = cameras.get(id).or(camera.as_ref());
        if cam.is_none() && !warned_no_camera {
            warned_no_camera = true;
            let fx = det.library.params.camera.fx;
            bar.suspend(|| eprintln!("note: {} has no camera (--camera, or a dataset's images[].camera): matched at the library's focal length ({fx:.0} px); an image of a camera with another pixel scale misses its tubes", path.display()));
        }
        if !det.resolvable(cam) {
            let (sx, sy) = det.scale_for(cam);
            bar.suspend(|| eprintln!("warning: {}: its camera would need {:.1}x enlargement to the library's scale (at most {}, --max-upsample): too coarse for the library's tubes, not searched", path.display(), sx.max(sy), det.params.max_upsample));
        }
        let g = grounds.get(id).or(ground);
        let (dets, verified) = runner.detect(&img, cam, g, *id).with_context(|| format!("detecting in {}", path.display()))?;
        if !matches!(runner, Line2dRunner::Plain(..)) && !verified && !warned_unverified {
            warned_unverified = true;
            bar.suspend(|| eprintln!("note: {}: no ground plane (--ground, or a dataset's images[].ground) or no camera of its size: Line2D detections kept at the clutter verifier's cut, not verified by their poses", path.display()));
        }
        out.extend(dets);
        bar.inc(1);
    }
    bar.finish_and_clear();
    Ok(out)
}
