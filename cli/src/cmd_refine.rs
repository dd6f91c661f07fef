//! `tubeloc refine`: refine detections into grasp-ready tube poses.
//!
//! Reads one image, its camera and a detections file (COCO results with the seeds of
//! [`tubeloc_core::TubeDetection`]), fits the cylinder contour to the image edges for each
//! detection and writes a JSON array of [`tubeloc_core::TubeAxisPose`] (camera frame, metres).
//! With `--right R.png --rig rig.json` the pair is rectified, matched with SGM in the detection
//! regions and triangulated; the points inside each detection's box (or mask) add the stereo
//! term. `--ground nx,ny,nz,d` (camera frame, `n·X = d` on the ground, `n` pointing up) places
//! mask/box seeds on the ground; in stereo each tube's plane is first moved to the height of
//! the matched terrain beside it (`tubeloc_refine::local_ground`, `--no-local-ground`).
//! `--overlay` draws the fitted contours (green: converged, red: failed).
//!
//! The work (stereo matching, the fits, the stages after them and the snap-or-trim policy of
//! `--snapped-out`) is the pipeline's ([`tubeloc_pipeline`]: `Locator::refine_frame` for one
//! image, `refine_frame` per image of a dataset); this module reads and writes the files.
//!
//! Dataset mode (`--dataset DIR`, module [`dataset`]): every image of a COCO dataset directory
//! (optionally one `--split`), each with the camera of its `images[].camera` and, with
//! `--ground auto`, the nominal ground plane of its `images[].T_world_cam` and
//! `images[].ground_height_m`; seeds from `--detections`
//! (matched by image id) or from the exact annotation poses (`--gt-seeds MM,DEG`); images in
//! parallel; one JSON array of poses, each with its `image_id`. With `--stereo` (a
//! `tubeloc synth stereo` folder) each image's right image (`images[].right_file_name` under
//! `right/`) and pair geometry (`right_camera`, `T_left_right`) are read, the pair is rectified
//! and matched with SGM in the tubes' regions ([`tubeloc_pipeline::stereo`]); the triangulated points in each
//! detection's mask or box (for `--gt-seeds`: the annotation's mask, standing in for a
//! segmenter's) feed the stereo term, and after the fit the photometric stage
//! (`tubeloc_refine::photo`, `--photo-range-mm`) moves both ends of each converged axis along
//! their viewing rays to the best ZNCC of the pair under the cylinder's own disparity field
//! (SGM is biased on the ~15 px wide convex tubes; this stage is not). The SGM depth also
//! marks scene occlusion (unless `--no-scene-occlusion`): contour points and photometric
//! pixels whose scene depth lies clearly in front of the cylinder (a rock, a sand mound over
//! the tube) are left out. Last, the axis direction is re-fitted to the rims (end outlines,
//! section boundaries) in both views about the photometric centre (`--rim-max-epipolar-deg`).

use anyhow::{bail, Context, Result};
use clap::Args;
use std::io::Write as _;
use std::path::PathBuf;
use tubeloc_core::{files, Pose, Rig, RigCamera, TubeDetection, TubeModel};
use tubeloc_pipeline::{CameraSelection, ExternalDetections, GroundPlane, LocateInput, Locator, LocatorSettings, StageSettings};

pub(crate) mod dataset;
pub(crate) use dataset::ground_of;

/// `--ground`: a plane "nx,ny,nz,d", or "auto" (dataset mode: each image's nominal ground).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum GroundArg {
    /// Each image's nominal ground from its `T_world_cam` and `ground_height_m`.
    Auto,
    /// One plane for every image.
    Plane(GroundPlane),
}

fn parse_ground_arg(s: &str) -> std::result::Result<GroundArg, String> {
    if s == "auto" {
        return Ok(GroundArg::Auto);
    }
    s.parse::<GroundPlane>().map(GroundArg::Plane).map_err(|e| e.to_string())
}

/// Arguments of `tubeloc refine`.
#[derive(Args, Debug)]
pub struct RefineArgs {
    /// Left (or only) image (or --dataset).
    #[arg(long, required_unless_present = "dataset")]
    pub(crate) image: Option<PathBuf>,
    /// A COCO dataset directory (annotations.json + images/): refine in every image, with the
    /// camera of images[].camera; see the module docs.
    #[arg(long, conflicts_with_all = ["image", "right", "rig", "overlay"])]
    pub(crate) dataset: Option<PathBuf>,
    /// Dataset mode: only images whose images[].split is this value.
    #[arg(long, requires = "dataset")]
    pub(crate) split: Option<String>,
    /// Dataset mode: only the first N images (after --split).
    #[arg(long, requires = "dataset")]
    pub(crate) max_images: Option<usize>,
    /// Dataset mode, instead of --detections: seeds from the annotations' exact T_cam_tube,
    /// perturbed by "MM,DEG" (centre uniform within ±MM per coordinate, axis turned by DEG);
    /// "0,0" gives exact seeds. Only tubes with visible_fraction >= --min-visible.
    #[arg(long, requires = "dataset")]
    pub(crate) gt_seeds: Option<String>,
    /// Dataset mode with --gt-seeds: random seed of the perturbation.
    #[arg(long, default_value_t = 0)]
    pub(crate) seed: u64,
    /// Dataset mode with --gt-seeds: least visible fraction of a tube to seed it.
    #[arg(long, default_value_t = 0.5)]
    pub(crate) min_visible: f64,
    /// Dataset mode: camera JSON the detector assumed (e.g. `tubeloc detect` without the crop's
    /// own camera); template poses are re-anchored to each image's camera (same pixel, same
    /// distance, see `tubeloc_refine::seed::reanchored`).
    #[arg(long, requires = "dataset")]
    pub(crate) detections_camera: Option<PathBuf>,
    /// Dataset mode: also write the seeds as poses (JSON array of TubeAxisPose), to evaluate the
    /// seeds alone: those the fit starts from, a mask seed's axis already turned to the seal end
    /// by its mask's colours (unless --no-colour-ends; `Refiner::seed`).
    #[arg(long, requires = "dataset")]
    pub(crate) seeds_out: Option<PathBuf>,
    /// Camera model JSON of the image, or its PDS3 label (ignored for the left image when --rig
    /// is given).
    #[arg(long)]
    pub(crate) camera: Option<PathBuf>,
    /// Detections: JSON array of COCO results with tubeloc seeds (`tubeloc detect --out`).
    #[arg(long, required_unless_present = "gt_seeds")]
    pub(crate) detections: Option<PathBuf>,
    /// Only refine detections of this COCO image id (default: all in the file).
    #[arg(long)]
    pub(crate) image_id: Option<u64>,
    /// Output poses (JSON array of TubeAxisPose).
    #[arg(long)]
    pub(crate) out: PathBuf,
    /// Overlay PNG with the fitted contours.
    #[arg(long)]
    pub(crate) overlay: Option<PathBuf>,
    /// Also write the detections with each mask snapped to its converged pose's silhouette
    /// (`tubeloc_refine::silhouette`: silhouette ∩ mask dilated by `stages.snap.dilate_px`, 8 px,
    /// where they agree at IoU >= `stages.snap.min_agreement`, 0.3; `--config`); same format as
    /// --detections, in the order of --out. A pose that kept its detector seed snaps only for
    /// tubes narrower than `stages.snap.kept_seed_max_width_px` (8 px). Detections without a
    /// converged pose or agreement keep their mask (eroded by `stages.snap.kept_erode_px`, 0 by
    /// default).
    #[arg(long)]
    pub(crate) snapped_out: Option<PathBuf>,
    /// With --snapped-out: each snapped detection's score becomes the probability that its
    /// pose is a tube, from the detector's score and the evidence of the fit (the share of
    /// contour samples on an edge, their number, the seal-end confidence, the axis's σ;
    /// `tubeloc_core::PoseEvidence`), so that the detections rank by both. `shipped`: the one
    /// fitted on the shipped learned model's detections of real validation composites
    /// (data/models/tubenet.pose_evidence.json, embedded); or a file from `tubeloc eval
    /// --fit-pose-evidence` (fit your own for another model or detector). The poses (--out)
    /// keep the detector's score. Default: the detector's scores are kept.
    #[arg(long, value_name = "shipped|FILE", requires = "snapped_out")]
    pub(crate) pose_evidence: Option<String>,
    /// Decide which end is the seal end from the image's edges only. By default the tube's
    /// colours decide where the fitted pose shows enough of the gold seal section and the white
    /// body (`tubeloc_refine::seal_end`; grey images: the seal is the darker section).
    #[arg(long)]
    pub(crate) no_colour_ends: bool,
    /// With stereo, leave the centres of tubes with one end hidden where the fit put them. By
    /// default a mask detection whose mask covers under 90 % of its fitted tube's length, with
    /// something nearer than the tube (or the image border) beyond exactly one mask end, is
    /// moved along its axis until its other end meets the mask's end there
    /// (`tubeloc_refine::hidden_end`; the pose's `end_anchored` says so).
    #[arg(long)]
    pub(crate) no_hidden_end: bool,
    /// Right image of a stereo pair (needs --rig).
    #[arg(long)]
    pub(crate) right: Option<PathBuf>,
    /// Rig file with both cameras (tubeloc JSON, OpenCV YAML or kalibr camchain).
    #[arg(long)]
    pub(crate) rig: Option<PathBuf>,
    /// Camera names of the pair in the rig, "LEFT,RIGHT" (default: the rig's first stereo pair).
    #[arg(long)]
    pub(crate) pair: Option<String>,
    /// Number of disparities searched (multiple of 16; default 256, or the settings file's
    /// `stages.disparities`); the window starts at the disparity of the farthest seed + 0.5 m.
    #[arg(long)]
    pub(crate) disparities: Option<usize>,
    /// Dataset mode: add the stereo term, with each image's right image (images[].right_file_name
    /// under DIR/right/, images[].right_camera, images[].T_left_right).
    #[arg(long, requires = "dataset")]
    pub(crate) stereo: bool,
    /// Stereo (--rig or --stereo): after the fit, move each converged tube along its centre's viewing
    /// ray to the best photometric agreement of the pair within ±this many millimetres
    /// (`tubeloc_refine::photo`); 0 disables (default 30, or the settings file's
    /// `stages.photo_range_mm`).
    #[arg(long, value_parser = crate::args::non_negative_f64)]
    pub(crate) photo_range_mm: Option<f64>,
    /// Stereo: turn off the scene-occlusion test (on by default: contour points whose SGM
    /// scene depth lies more than `CylinderModel::occlusion_margin` in front of the cylinder,
    /// i.e. rocks or sand over the tube, are left out of the edge fit
    /// (`tubeloc_refine::Scene::depth`), and so are such pixels in the photometric stage).
    #[arg(long = "no-scene-occlusion", action = clap::ArgAction::SetFalse)]
    pub(crate) scene_occlusion: bool,
    /// Stereo: turn off the last stage, the fit of the whole contour (limbs and rims) in both
    /// rectified views over all five pose parameters (`tubeloc_refine::two_view`; with the
    /// ground's tilt prior when a ground plane is given). On by default.
    #[arg(long = "no-two-view", action = clap::ArgAction::SetFalse)]
    pub(crate) two_view: bool,
    /// Dataset mode: mask-agreement term instead of image edges: the silhouette is fitted to the
    /// boundary of each detection's mask (for --gt-seeds: the annotation's mask, i.e. a perfect
    /// segmenter, an upper bound).
    #[arg(long, requires = "dataset")]
    pub(crate) mask_term: bool,
    /// Ground plane "nx,ny,nz,d" in the camera frame (`n·X = d`, n up), metres; with
    /// --dataset, "auto" takes it from images[].T_world_cam and images[].ground_height_m (ground
    /// = world z = ground_height_m, the median terrain height within the capture stops, written
    /// by `tubeloc synth`; z = 0 where absent). The terrain has relief about it: its tilt is a
    /// prior, its height places mask seeds in mono.
    #[arg(long, allow_hyphen_values = true, value_parser = parse_ground_arg)]
    pub(crate) ground: Option<GroundArg>,
    /// Stereo with a ground plane: keep the given plane's height for every tube. By default each
    /// tube's plane is moved to the median height of the matched terrain beside it (the 300
    /// terrain points nearest its box, within 160 px, outside every tube's mask), which places
    /// the tubes that get no stereo points of their own (outside the right camera's view) on
    /// the terrain instead of the nominal ground.
    #[arg(long)]
    pub(crate) no_local_ground: bool,
    /// Settings file, TOML (`.toml`) or JSON: any of the refiner's groups (edge_search,
    /// seed_search, solver, acceptance, end_decision, priors, mono_depth, seeds, mask; see
    /// refine/README.md) and the `stages` table of the stages after the fit (stereo erosion,
    /// photometric ZNCC and centre-only search, rims, `stages.two_view`, `stages.snap` for
    /// --snapped-out; `tubeloc_pipeline::StageSettings`); missing fields keep their defaults,
    /// unknown ones are refused. Flags given on the command line win over the file.
    #[arg(long)]
    pub(crate) config: Option<PathBuf>,
    /// Tube model TOML (default: the built-in model of data/tube.toml).
    #[arg(long)]
    pub(crate) tube: Option<PathBuf>,
}

/// Writes the snapped detections of `--snapped-out` (if given), each scored by `evidence` from
/// its pose (`poses`, in the same order) when given, and reports how many masks were snapped.
pub(crate) fn write_snapped(path: Option<&std::path::Path>, snapped: &[(TubeDetection, bool)], poses: &[tubeloc_core::TubeAxisPose], evidence: Option<&tubeloc_core::PoseEvidence>) -> Result<()> {
    let Some(path) = path else { return Ok(()) };
    anyhow::ensure!(snapped.len() == poses.len(), "internal: {} snapped detections for {} poses", snapped.len(), poses.len());
    let dets: Vec<TubeDetection> = snapped.iter().zip(poses).map(|((d, _), p)| TubeDetection { score: evidence.map_or(d.score, |e| e.probability(p)), ..d.clone() }).collect();
    files::write_json(path, &dets).with_context(|| format!("writing {}", path.display()))?;
    let scored = if evidence.is_some() { ", scored by their poses' evidence" } else { "" };
    eprintln!("{} of {} masks snapped to their poses{scored} -> {}", snapped.iter().filter(|(_, s)| *s).count(), snapped.len(), path.display());
    Ok(())
}

/// The pose evidence of `--pose-evidence`, loaded and checked.
pub(crate) fn pose_evidence_of(spec: Option<&str>) -> Result<Option<tubeloc_core::PoseEvidence>> {
    spec.map(|s| tubeloc_pipeline::shipped::pose_evidence(s).map_err(|e| anyhow::anyhow!("--pose-evidence: {e}"))).transpose()
}

/// The refiner's configuration and tube model of the arguments (config and tube model files).
impl RefineArgs {
    /// The pipeline settings of the arguments: the settings file's (or the defaults), with the
    /// command line's flags over them.
    pub(crate) fn settings(&self) -> Result<LocatorSettings> {
        let (refine, mut stages) = match &self.config {
            Some(p) => tubeloc_pipeline::load_settings_file(p)?,
            None => (Default::default(), StageSettings::default()),
        };
        let tube = match &self.tube {
            Some(p) => TubeModel::load(p).with_context(|| format!("tube model {}", p.display()))?,
            None => TubeModel::default(),
        };
        if let Some(d) = self.disparities {
            stages.disparities = d;
        }
        if let Some(r) = self.photo_range_mm {
            stages.photo_range_mm = r;
        }
        stages.local_ground &= !self.no_local_ground;
        stages.scene_occlusion &= self.scene_occlusion;
        stages.hidden_end &= !self.no_hidden_end;
        if !self.two_view {
            stages.two_view = None;
        }
        stages.validate().map_err(|e| anyhow::anyhow!("{e} (--disparities / --photo-range-mm)"))?;
        let mut s = LocatorSettings::default();
        s.refine = refine;
        s.tube = tube;
        s.colour_ends = !self.no_colour_ends;
        s.stages = stages;
        s.merge_duplicates = false;
        Ok(s)
    }
}

/// Runs `tubeloc refine`.
pub fn run(args: RefineArgs) -> Result<()> {
    if args.dataset.is_some() {
        return dataset::run(&args);
    }
    let settings = args.settings()?;
    let evidence = pose_evidence_of(args.pose_evidence.as_deref())?;
    let ground = match args.ground {
        Some(GroundArg::Auto) => bail!("--ground auto needs --dataset (each image's nominal ground); give nx,ny,nz,d"),
        Some(GroundArg::Plane(g)) => Some(g),
        None => None,
    };
    let det_path = args.detections.as_ref().context("--detections is required without --dataset")?;
    let image_path = args.image.as_ref().context("--image is required without --dataset")?;
    let mut dets = tubeloc_core::detection::read_coco_results(det_path)?;
    if let Some(id) = args.image_id {
        dets.retain(|d| d.image_id == id);
    }
    // The camera(s): the rig's pair (stereo), or --camera alone.
    let (rig, selection) = match &args.rig {
        Some(p) => {
            let rig = tubeloc_calib::read_rig(p).context("rig")?;
            let pair = match &args.pair {
                Some(s) => Some(s.split_once(',').map(|(l, r)| (l.trim().to_string(), r.trim().to_string())).with_context(|| format!("--pair {s:?}: expected LEFT,RIGHT"))?),
                None => Some(rig.stereo_pairs.first().cloned().with_context(|| format!("{}: no stereo_pairs; pass --pair LEFT,RIGHT", p.display()))?),
            };
            if args.right.is_none() {
                bail!("--rig needs --right");
            }
            (rig, CameraSelection { camera: None, pair })
        }
        None => {
            if args.right.is_some() {
                bail!("--right needs --rig (the pair's calibration)");
            }
            let p = args.camera.as_ref().context("--camera is required without --rig")?;
            let model = tubeloc_calib::read_camera(p).with_context(|| format!("camera {}", p.display()))?;
            (Rig { cameras: vec![RigCamera { name: "camera".into(), model, t_rig_cam: Pose::identity() }], stereo_pairs: Vec::new() }, CameraSelection::default())
        }
    };
    let detector = Box::new(ExternalDetections::new(Vec::new(), det_path.display().to_string()));
    let locator = Locator::new(&rig, &selection, detector, settings)?;
    let image = tubeloc_detect::input::open_eight_bit(image_path).with_context(|| format!("cannot read image {}", image_path.display()))?;
    let right = match &args.right {
        Some(r) => Some(tubeloc_detect::input::open_eight_bit(r).with_context(|| format!("cannot read image {}", r.display()))?),
        None => None,
    };
    let input = LocateInput { image: &image, right: right.as_ref(), ground, up: None, ignore: None };
    let refined = locator.refine_frame(&input, &dets).with_context(|| format!("refining {}", image_path.display()))?;
    let poses = refined.poses;
    let camera = &locator.camera().model;
    let mut stdout = std::io::stdout().lock();
    for (i, p) in poses.iter().enumerate() {
        let c = p.centre * 1e3;
        let status = match &p.failure {
            None => "ok".to_string(),
            Some(f) => format!("FAILED {:?}: {}", f.reason, f.message),
        };
        let line = format!(
            "tube {i} (image {}, score {:.2}): centre [{:.1}, {:.1}, {:.1}] mm, axis [{:.3}, {:.3}, {:.3}], end conf {:.2}, rms {:.2} px, {}/{} inliers, {} stereo pts: {status}",
            p.image_id,
            p.score,
            c.x,
            c.y,
            c.z,
            p.axis.x,
            p.axis.y,
            p.axis.z,
            p.end_confidence,
            p.residuals.rms_px,
            p.residuals.inliers,
            p.residuals.count,
            refined.stereo_points.get(i).map_or(0, Vec::len)
        );
        if writeln!(stdout, "{line}").is_err() {
            break;
        }
    }
    drop(stdout);
    files::write_json(&args.out, &poses).with_context(|| format!("writing {}", args.out.display()))?;
    if args.snapped_out.is_some() {
        let snap = locator.settings().stages.snap;
        let snapped: Vec<(TubeDetection, bool)> = dets
            .iter()
            .zip(&poses)
            .map(|(d, p)| {
                let mut d = d.clone();
                let s = tubeloc_pipeline::stages::snapped_detection(&mut d, p, locator.refiner(), camera, &snap);
                (d, s)
            })
            .collect();
        write_snapped(args.snapped_out.as_deref(), &snapped, &poses, evidence.as_ref())?;
    }
    if let Some(o) = &args.overlay {
        let png = tubeloc_pipeline::overlay::png_bytes(&locator.overlay(&image, &poses)).context("cannot encode PNG")?;
        files::write_atomic(o, &png).with_context(|| format!("writing {}", o.display()))?;
    }
    eprintln!("{} poses ({} converged) -> {}", poses.len(), poses.iter().filter(|p| p.converged).count(), args.out.display());
    Ok(())
}
