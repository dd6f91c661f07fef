//! `tubeloc locate`: the main job. One image (or a stereo pair) and a rig file in, grasp-ready
//! tube poses out; or, with `--images`, many frames in one process ([`batch`]), sharded over
//! machines and combined by `tubeloc locate merge` ([`merge`]).
//!
//! Reading files, building the detector and writing the outputs happen here; the pipeline itself
//! (detect -> (stereo) -> refine -> stages after the fit -> duplicate merging -> grasp frames)
//! is [`tubeloc_pipeline::Locator`]. A run writes one JSON document per frame (schema
//! `tubeloc.locate.v1`, documented in the README; it also holds the camera model and the
//! detections that seeded the refinement) and the overlay PNG, each atomically, both before
//! anything is printed; a failing run writes neither.

pub mod batch;
pub mod frames;
pub mod merge;
pub mod setup;
pub mod single;

use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand};
use nalgebra::Vector3;
use serde::Serialize;
pub use setup::Setup;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use tubeloc_core::{CameraModel, CocoResult, Pose, Rig, TubeDetection};
use tubeloc_pipeline::{detector, CameraSelection, ExternalDetections, GroundPlane, LocateInput, LocatedTube, Locator, LocatorSettings, TubeDetector};

/// Exit code of a run that finished but located no tube.
pub const EXIT_NO_TUBE: u8 = 3;

/// Detector that seeds the refinement.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Detector {
    /// The learned segmenter (`--model`, default: the shipped model, embedded in the program).
    Learned,
    /// Line2D template matching (`--templates LIB.tlt`; default: the default library, built in
    /// memory, each image resampled to its pixel scale).
    Line2d,
    /// The learned detections (`--model`) and Line2D's pose-verified ones (`--templates`),
    /// scored by their pose evidence (`tubeloc detect --method fused`, record 0069).
    Fused,
    /// Detections made elsewhere (`--results coco_results.json`, e.g. Detectron2).
    External,
}

impl Detector {
    /// The detector's name, as `--detector` takes it and the outputs report it.
    pub fn name(self) -> &'static str {
        match self {
            Detector::Learned => "learned",
            Detector::Line2d => "line2d",
            Detector::Fused => "fused",
            Detector::External => "external",
        }
    }
}

/// Nested `tubeloc locate` subcommands.
#[derive(Subcommand, Debug)]
pub enum LocateCommand {
    /// Combine the output folders of the shards of a batch run (`--shard I/N`) into one folder:
    /// every frame's result file and one summary. Overlapping or missing frames are refused.
    Merge(merge::MergeArgs),
}

/// Arguments of `tubeloc locate`.
#[derive(Args, Debug)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
#[command(group = clap::ArgGroup::new("cameras").args(["rig", "label_cameras", "assumed_view"]).required(true).multiple(false))]
pub struct LocateArgs {
    /// `merge`: combine the folders of a sharded batch run.
    #[command(subcommand)]
    pub command: Option<LocateCommand>,
    /// Rig file: tubeloc JSON (`tubeloc calib rig`, a synthetic dataset's `rig.json`, or one camera model: a mono rig), OpenCV YAML,
    /// a kalibr camchain, one ROS `camera_info`, a PDS camera list (`cahv_to_pinhole.py`'s JSON:
    /// each image's camera, by file name, and ground; a CAHVORE entry's model read from the
    /// label its `label_file` names) or the PDS3 label of the image (`.LBL`, or an `.IMG` with
    /// its label: its CAHV/CAHVOR camera in the rover frame, and ground), recognised by content.
    /// A CAHVORE fisheye's image is resampled into the model's linear camera.
    #[arg(long)]
    pub rig: Option<PathBuf>,
    /// Instead of --rig: each image is a PDS3 product (`.IMG` with its label, or a `.LBL` beside
    /// its data) whose own label gives its camera (CAHV/CAHVOR, in the rover frame) and ground;
    /// a CAHVORE fisheye's image is resampled into the model's linear camera first. A batch of
    /// products then needs no rig file; each frame's camera is named after its file.
    /// An image in another format (a raw-gallery JPEG, a PNG) takes its detached label: the
    /// `.LBL` beside it (or in --label-dir) with its product name, also where the image's name
    /// has `_` for the product's version character (`NLA_..._M_.jpg` for `NLA_..._M1.LBL`).
    /// With --right (a product of the same moment), the two labels make the stereo pair.
    #[arg(long, conflicts_with_all = ["camera_name", "pair", "right_images"])]
    pub label_cameras: bool,
    /// With --label-cameras: the folder where the detached labels of images that are no PDS3
    /// products lie (default: each image's own folder).
    #[arg(long)]
    pub label_dir: Option<PathBuf>,
    /// Instead of --rig, for frames that come without a camera model: each image's camera and
    /// ground (unless --ground) are assumed from its size. `navcam`: a 45 degree horizontal
    /// field of view, 1.9 m above level ground, looking 30 degrees down (how `tubeloc bench`
    /// judges grey frames without a model); `mast`: the same with a 20 degree field (its
    /// colour frames; Curiosity's Mastcam M-34); `m100` (6.8 degrees), `m2020-navcam` (96
    /// degrees, 2 m), `mastcam-z-F` (Perseverance's Mastcam-Z at F mm, 2 m), `mer-navcam`
    /// (45 degrees, 1.5 m), `mer-pancam` (16 degrees, 1.5 m); `auto`: the view of the camera
    /// each frame's product name names (e.g. `0079MR...`: m100, `ZL0_..._110085J01`:
    /// mastcam-z-110), else `navcam` for a grey frame, `mast` for a colour one (as the bench
    /// judges them); or the view's numbers,
    /// `HFOV_DEG,HEIGHT_M,PITCH_DEG` (e.g. `90,2,25` for a wide mast camera: the field of view
    /// sets the pixel scale the detectors work at). Poses are then only as good as the
    /// assumption, and so is detection: within about 20 % of the true pixel scale the learned
    /// detector keeps its AP50, at twice or half of it between a fifth and two thirds of it
    /// (docs/design/0083-pixel-scale-tolerance.md). Mono only.
    #[arg(long, value_parser = crate::args::assumed_view, conflicts_with_all = ["camera_name", "pair", "right", "right_images"])]
    pub assumed_view: Option<crate::args::AssumedViewArg>,
    /// Focal length of the pinhole a fisheye (CAHVORE) image is resampled into, relative to the
    /// model's linear part: below 1 keeps more of the fisheye's field (its rim, the near
    /// ground of a hazard camera) at a coarser scale; the corners beyond the field are black.
    #[arg(long, default_value_t = 1.0, value_parser = crate::args::fisheye_scale)]
    pub fisheye_scale: f64,
    /// The (left) image.
    #[arg(long, required_unless_present = "images", conflicts_with = "images")]
    pub image: Option<PathBuf>,
    /// Right image of a stereo pair: adds the stereo term to the refinement.
    #[arg(long, conflicts_with = "images")]
    pub right: Option<PathBuf>,
    /// Batch run: the (left) frames, a folder (its image files: PNG, JPEG, TIFF, PGM/PPM/PNM, BMP,
    /// WebP, PDS3 .img, or the detached .lbl beside an .img) or a list file (one image path a
    /// line, relative to the list's folder; blank lines and `#` comments skipped).
    /// Frames are taken in sorted path order; each frame's result is `--out DIR/frames/<image
    /// file stem>.json` (image file stems must be unique), plus `DIR/summary.json`. A frame
    /// whose result file exists and is complete is skipped, so a killed run resumes by running
    /// the same command again.
    #[arg(long)]
    pub images: Option<PathBuf>,
    /// Batch run: the right frames (folder or list as --images); the k-th right frame in sorted
    /// order pairs with the k-th left frame.
    #[arg(long)]
    pub right_images: Option<PathBuf>,
    /// Batch run: process only shard I of N ("I/N", 0 <= I < N): frame k of the sorted list
    /// goes to shard k mod N. Run each shard with its own --out folder, then `tubeloc locate
    /// merge`.
    #[arg(long, value_parser = crate::args::shard)]
    pub shard: Option<(usize, usize)>,
    /// Batch run: also write each frame's overlay PNG (`frames/<stem>.overlay.png`).
    #[arg(long)]
    pub overlays: bool,
    /// Rig camera that took `--image` (default: the left camera of `--pair`, or of the rig's first
    /// stereo pair).
    #[arg(long)]
    pub camera_name: Option<String>,
    /// Stereo pair "LEFT,RIGHT" of the rig (default: the rig's first stereo pair).
    #[arg(long)]
    pub pair: Option<String>,
    /// Detector that seeds the refinement.
    #[arg(long, value_enum, default_value = "learned")]
    pub detector: Detector,
    /// Learned model weights (default: the shipped model, embedded in the program).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Line2D template library (`--detector line2d|fused`; `tubeloc templates build`). Default:
    /// the default library (what `tubeloc templates build` writes at its defaults), built in
    /// memory in about 1 s; images of any camera are resampled to its pixel scale.
    #[arg(long)]
    pub templates: Option<PathBuf>,
    /// External COCO results (`--detector external`). Entries are selected by the image's file
    /// name: by an entry's own "file_name" field, or through --results-images; results for a
    /// single image id are taken whole.
    #[arg(long)]
    pub results: Option<PathBuf>,
    /// With --results: a COCO file whose images[] (id, file_name) tell which results belong to
    /// --image (e.g. the dataset's annotations.json).
    #[arg(long, requires = "results")]
    pub results_images: Option<PathBuf>,
    /// Ground plane "nx,ny,nz,d" in the camera frame (`n·X = d`, n up), metres: places seeds on
    /// the ground and gives the grasp approach direction.
    #[arg(long, allow_hyphen_values = true)]
    pub ground: Option<GroundPlane>,
    /// Up direction "ux,uy,uz" in the camera frame for the grasp approach when no --ground is
    /// given (default: -y, i.e. the camera is roughly level).
    #[arg(long, allow_hyphen_values = true, value_parser = parse_up)]
    pub up: Option<Vector3<f64>>,
    /// Score calibration JSON (probability of a tube and acceptance threshold; `tubeloc eval
    /// --calibrate` writes one). Default for the learned detector: the shipped model's
    /// (embedded) or the one beside --model (`<model>.calibration.json`); fused: its embedded
    /// one (fitted with the shipped model and the default template library); Line2D: none
    /// (probability = score).
    #[arg(long)]
    pub calibration: Option<PathBuf>,
    /// Accept tubes whose probability is at least this (default: the calibration's threshold,
    /// chosen for precision >= 0.95 on real validation composites).
    #[arg(long, value_parser = probability)]
    pub min_probability: Option<f64>,
    /// Hand over no tube from a frame whose highlights (the 99th percentile of its 8-bit grey
    /// levels) lie below this level: an underexposed frame, mostly sensor noise; its tubes are
    /// listed as `underexposed` (0: off).
    #[arg(long, default_value_t = tubeloc_pipeline::settings::DEFAULT_MIN_HIGHLIGHT_LEVEL, value_parser = crate::args::grey_level)]
    pub min_highlight_level: f64,
    /// Hand over a learned detection's tube only where the probability that its pose is a tube,
    /// from the detector's score and the fit's evidence (contour on edges, a sharp axis, a seal
    /// end that shows; the model's pose evidence, `tubeloc eval --fit-pose-evidence`), reaches
    /// this; below it the tube is listed as `weak_pose_evidence` (0: off). The shipped model's
    /// evidence is embedded; a --model file's is `<model>.pose_evidence.json` beside it.
    #[arg(long, default_value_t = tubeloc_pipeline::settings::DEFAULT_MIN_POSE_EVIDENCE, value_parser = probability)]
    pub min_pose_evidence: f64,
    /// Hand over a tube only where the edges along its limbs go on past its ends by at most
    /// this much, against along its body (a slab rim, a crack or a layer of bedrock goes on; a
    /// tube ends: about 0.15 for a tube, 0.5-2 for a rim); beyond it the tube is listed as
    /// `limbs_continue` (`off`: no such check).
    #[arg(long, default_value = "0.6", value_parser = limb_continuation_cut)]
    pub max_limb_continuation: LimbCut,
    /// Mask image of the frames' size whose non-zero pixels cover what no tube is handed over
    /// from: rover hardware in view (the arm, the deck, wheels) or any other region; or a
    /// folder of masks, one per frame named after the image (`<image stem>.png`; a frame
    /// without one is not masked), as the arm moves between frames. A tube whose centre falls
    /// there is listed as `in_ignored_region`. A fisheye frame's mask is drawn on the raw
    /// frame and resampled with it.
    #[arg(long)]
    pub ignore_mask: Option<PathBuf>,
    /// Distances of the tubes from the camera, "NEAR:FAR" metres: the learned detector runs at
    /// the working scale of this band (or of --ground), or "off" (the image as it is).
    #[arg(long, default_value = "1:4", value_parser = crate::args::range_band)]
    pub range_m: String,
    /// Output: the poses JSON file (schema tubeloc.locate.v1) for one image; the output folder
    /// for a batch run (--images).
    #[arg(long, required = true)]
    pub out: Option<PathBuf>,
    /// Overlay PNG with the fitted contours (default: `<out stem>.overlay.png` next to --out).
    #[arg(long, conflicts_with = "images")]
    pub overlay: Option<PathBuf>,
}

impl LocateArgs {
    /// The arguments of a one-image run with every option at its default.
    pub fn single(rig: PathBuf, image: PathBuf, out: PathBuf) -> Self {
        LocateArgs {
            command: None,
            rig: Some(rig),
            label_cameras: false,
            label_dir: None,
            assumed_view: None,
            fisheye_scale: 1.0,
            image: Some(image),
            right: None,
            images: None,
            right_images: None,
            shard: None,
            overlays: false,
            camera_name: None,
            pair: None,
            detector: Detector::Learned,
            model: None,
            templates: None,
            results: None,
            results_images: None,
            ground: None,
            up: None,
            calibration: None,
            min_probability: None,
            min_highlight_level: tubeloc_pipeline::settings::DEFAULT_MIN_HIGHLIGHT_LEVEL,
            min_pose_evidence: tubeloc_pipeline::settings::DEFAULT_MIN_POSE_EVIDENCE,
            max_limb_continuation: LimbCut(Some(tubeloc_pipeline::settings::DEFAULT_MAX_LIMB_CONTINUATION)),
            ignore_mask: None,
            range_m: "1:4".into(),
            out: Some(out),
            overlay: None,
        }
    }

    /// `--rig` (required by the command line).
    fn rig_path(&self) -> Result<&Path> {
        self.rig.as_deref().ok_or_else(|| crate::args::usage("the following required argument was not provided: --rig <RIG>"))
    }

    /// `--out` (required by the command line).
    fn out_path(&self) -> Result<&Path> {
        self.out.as_deref().ok_or_else(|| crate::args::usage("the following required argument was not provided: --out <OUT>"))
    }
}

/// Runs `tubeloc locate` (one image, a batch, or `merge`); returns the process exit code:
/// [`EXIT_NO_TUBE`] when the run finished but located no tube, else 0.
pub fn run(a: LocateArgs) -> Result<u8> {
    if let Some(LocateCommand::Merge(m)) = a.command {
        return merge::run(m).map(|()| 0);
    }
    if a.images.is_none() {
        // Batch-only flags (clap's `requires` does not see them through the subcommand setup).
        for (given, flag) in [(a.shard.is_some(), "--shard"), (a.right_images.is_some(), "--right-images"), (a.overlays, "--overlays")] {
            if given {
                return Err(crate::args::usage(format!("{flag} is for batch runs (--images LIST_OR_DIR); a one-image run takes --image, --right and --overlay FILE")));
            }
        }
    }
    if a.label_dir.is_some() && !a.label_cameras {
        return Err(crate::args::usage("--label-dir is where --label-cameras looks for detached labels: give --label-cameras"));
    }
    let located = if a.images.is_some() { batch::run(&a)? } else { single::run(&a)? };
    Ok(if located == 0 { EXIT_NO_TUBE } else { 0 })
}

/// A probability in [0, 1].
fn probability(s: &str) -> std::result::Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(p) if (0.0..=1.0).contains(&p) => Ok(p),
        _ => Err(format!("{s:?}: expected a probability in [0, 1]")),
    }
}

/// `--max-limb-continuation`: a cut, or none (`off`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LimbCut(pub Option<f64>);

/// Parses `--max-limb-continuation`: a positive number, or `off`.
fn limb_continuation_cut(s: &str) -> std::result::Result<LimbCut, String> {
    match s.trim() {
        "off" => Ok(LimbCut(None)),
        t => match t.parse::<f64>() {
            Ok(c) if c.is_finite() && c > 0.0 => Ok(LimbCut(Some(c))),
            _ => Err(format!("{s:?}: expected a positive number, or off")),
        },
    }
}

/// `--up ux,uy,uz`: three finite numbers, not all zero (normalized).
fn parse_up(s: &str) -> std::result::Result<Vector3<f64>, String> {
    let v: Vec<f64> = s.split(',').map(|t| t.trim().parse::<f64>()).collect::<std::result::Result<_, _>>().map_err(|_| format!("{s:?}: expected three numbers ux,uy,uz"))?;
    if v.len() != 3 || v.iter().any(|x| !x.is_finite()) {
        return Err(format!("{s:?}: expected three finite numbers ux,uy,uz"));
    }
    let n = Vector3::new(v[0], v[1], v[2]);
    if n.norm() < 1e-9 {
        return Err(format!("{s:?}: the vector is zero"));
    }
    Ok(n.normalize())
}

/// The document `tubeloc locate` writes for each frame.
#[derive(Serialize, Debug)]
pub struct LocateDoc<'a> {
    /// Schema name and version: `tubeloc.locate.v1`.
    pub schema: &'static str,
    /// The input image.
    pub image: &'a Path,
    /// The right image, when stereo was used.
    pub right_image: Option<&'a Path>,
    /// Rig camera of `image`.
    pub camera: &'a str,
    /// Detector that seeded the refinement.
    pub detector: &'a str,
    /// Up direction used for the grasp frames, unit vector in the camera frame.
    pub up_cam: Vector3<f64>,
    /// Pose of the camera in the rig frame.
    #[serde(rename = "T_rig_cam")]
    pub t_rig_cam: Pose,
    /// Located tubes, best score first, then the rejected detections (`status` says why).
    pub tubes: Vec<TubeOut<'a>>,
    /// The probability threshold tubes were accepted at.
    pub min_probability: f64,
    /// The least pose evidence tubes were accepted at (`--min-pose-evidence`); absent when no
    /// pose evidence was checked (off, or a detector without one).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub min_pose_evidence: Option<f64>,
    /// The largest limb continuation tubes were accepted at (`--max-limb-continuation`); absent
    /// when off.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_limb_continuation: Option<f64>,
    /// Run statistics of a one-image run: wall time (s) and peak resident memory (MiB) of the
    /// whole run. Absent from the frames of a batch run (its `run.json` holds them), so that a
    /// frame's document depends on its inputs only.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub run: Option<serde_json::Value>,
    /// The model of the camera that took `image`.
    pub camera_model: &'a CameraModel,
    /// `CAHVORE` when `image` was taken through a fisheye (a CAHVORE label) and resampled into
    /// `camera_model`, the model's linear part: the detections' pixels and the overlay are then
    /// those of the resampled image.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub resampled_from: Option<&'static str>,
    /// The view `camera_model` and the ground were assumed from (`--assumed-view`: a named
    /// view such as `navcam`, `mast`, `m100` (given, or by `auto`), or
    /// `HFOV_DEG,HEIGHT_M,PITCH_DEG`) when the frame came without a camera model: the poses
    /// rest on that assumption.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub assumed_view: Option<&'a str>,
    /// What was printed as warnings about the frame (underexposed; tubes narrower than the
    /// detectors can enlarge to their working width; an assumed view that does not fit the
    /// camera its product name names); absent when none.
    #[serde(skip_serializing_if = "<[String]>::is_empty")]
    pub warnings: &'a [String],
    /// The detections that seeded the refinement (COCO results with tubeloc's seed fields).
    pub detections: &'a [TubeDetection],
}

/// Schema name of a frame's document.
pub const FRAME_SCHEMA: &str = "tubeloc.locate.v1";

/// One tube of the document: the pose, grasp frames and probability, and what became of it.
#[derive(Serialize, Debug)]
pub struct TubeOut<'a> {
    /// The tube.
    #[serde(flatten)]
    pub tube: &'a LocatedTube,
    /// `located` (handed to the planner), or why not: `fit_failed`, `low_probability`,
    /// `weak_pose_evidence`, `limbs_continue`, `intersects_tube`, `underexposed` or
    /// `in_ignored_region`.
    pub status: &'static str,
}

/// The inputs of one frame.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Frame {
    /// The (left) image.
    pub image: PathBuf,
    /// The right image of a stereo pair.
    pub right: Option<PathBuf>,
}

/// What locating one frame gave: its document and overlay, encoded, and the tubes.
pub struct FrameOutcome {
    /// The frame's document (JSON, schema [`FRAME_SCHEMA`]).
    pub json: Vec<u8>,
    /// The overlay PNG, when asked for.
    pub overlay_png: Option<Vec<u8>>,
    /// What the pipeline found.
    pub found: tubeloc_pipeline::LocateOutput,
    /// What the caller should print about the frame: why its tubes could not be handed over
    /// as a whole (an underexposed frame), or why few are found (tubes narrower in it than the
    /// detectors can enlarge to their working width).
    pub warnings: Vec<String>,
}

/// Locates the tubes of one frame and encodes its document (with run statistics since
/// `started` when given) and, with `overlay`, the overlay PNG. Nothing is written.
pub fn locate_frame(setup: &Setup, a: &LocateArgs, frame: &Frame, started: Option<std::time::Instant>, overlay: bool) -> Result<FrameOutcome> {
    let size = tubeloc_detect::input::image_size(&frame.image).with_context(|| format!("reading {}", frame.image.display()))?;
    setup.check_size(&frame.image, size)?;
    setup.with_locator(&frame.image, size, |locator| {
        let cam = locator.camera().clone();
        let (image, resampled_from) = setup.as_seen_by(&cam, open_image(&frame.image)?);
        // The right camera: the pair's second (with --label-cameras, named after its file).
        let right_cam = setup.selection.pair.as_ref().and_then(|(_, r)| setup.rig.camera(r));
        let right = match (frame.right.as_deref(), right_cam) {
            (Some(p), Some(rc)) => Some(setup.as_seen_by(rc, open_image(p)?).0),
            (Some(p), None) => Some(open_image(p)?),
            (None, _) => None,
        };
        let ignore = setup.ignore_mask_for(&cam, &frame.image, size)?;
        let input = LocateInput { image: &image, right: right.as_ref(), ground: a.ground.or_else(|| setup.pds.iter().find(|c| c.camera.name == cam.name).map(|c| c.ground)), up: a.up, ignore: ignore.as_deref() };
        let found = locator.locate(&input).with_context(|| format!("locating tubes in {}", frame.image.display()))?;
        // The detector's scale limits (Line2D warns of its own as it searches).
        let mut warnings: Vec<String> = found.warnings.iter().map(|w| format!("{}: {w}", frame.image.display())).collect();
        warnings.extend((found.highlight_level < setup.settings.min_highlight_level).then(|| {
            format!(
                "{} is underexposed (its highlights lie at grey level {:.0} < {:.0}): no tube is handed over from it; retake the frame, or lower --min-highlight-level",
                frame.image.display(),
                found.highlight_level,
                setup.settings.min_highlight_level
            )
        }));
        // The view assumed for the frame, and why it may not fit the camera.
        let assumed = frame.image.file_name().and_then(|n| setup.assumed_views.get(n.to_string_lossy().as_ref()));
        warnings.extend(assumed.and_then(|(_, note)| note.clone()));
        let tubes: Vec<TubeOut> = found.tubes.iter().map(|t| TubeOut { tube: t, status: "located" }).chain(found.rejected.iter().map(|r| TubeOut { tube: &r.tube, status: r.reason.name() })).collect();
        let overlay_png = match overlay {
            true => {
                let mut shown = locator.overlay_located(&image, &found);
                if let Some(m) = &ignore {
                    tubeloc_pipeline::overlay::tint_ignored(&mut shown, m);
                }
                Some(tubeloc_pipeline::overlay::png_bytes(&shown).context("encoding the overlay PNG")?)
            }
            false => None,
        };
        let doc = LocateDoc {
            schema: FRAME_SCHEMA,
            image: &frame.image,
            right_image: frame.right.as_deref(),
            camera: &cam.name,
            detector: &setup.detector_name,
            up_cam: found.up_cam,
            t_rig_cam: cam.t_rig_cam,
            tubes,
            min_probability: setup.settings.calibration.threshold,
            min_pose_evidence: setup.settings.pose_evidence.as_ref().map(|_| setup.settings.min_pose_evidence),
            max_limb_continuation: setup.settings.max_limb_continuation,
            run: started.map(|t0| {
                let t = &found.timings;
                serde_json::json!({"seconds": t0.elapsed().as_secs_f64(), "peak_rss_mb": crate::memory::peak_rss_mb(), "detect_s": t.detect_s, "refine_s": t.refine_s, "grasp_ms": t.grasp_ms, "locate_s": t.total_s})
            }),
            camera_model: &cam.model,
            resampled_from,
            assumed_view: assumed.map(|(v, _)| v.as_str()),
            warnings: &warnings,
            detections: &found.detections,
        };
        let json = serde_json::to_vec_pretty(&doc).context("serializing the poses")?;
        Ok(FrameOutcome { json, overlay_png, found, warnings })
    })
}

fn open_image(p: &Path) -> Result<image::DynamicImage> {
    tubeloc_detect::input::open_eight_bit(p).with_context(|| format!("cannot read image {}", p.display()))
}
