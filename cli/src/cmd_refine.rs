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
//! Dataset mode (`--dataset DIR`, module [`dataset`]): every image of a COCO dataset directory
//! (optionally one `--split`), each with the camera of its `images[].camera` and, with
//! `--ground auto`, the nominal ground plane of its `images[].T_world_cam` and
//! `images[].ground_height_m`; seeds from `--detections`
//! (matched by image id) or from the exact annotation poses (`--gt-seeds MM,DEG`); images in
//! parallel; one JSON array of poses, each with its `image_id`. With `--stereo` (a
//! `tubeloc synth stereo` folder) each image's right image (`images[].right_file_name` under
//! `right/`) and pair geometry (`right_camera`, `T_left_right`) are read, the pair is rectified
//! and matched with SGM in the tubes' regions (module [`stereo`]); the triangulated points in each
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
use nalgebra::{Point3, Vector3};
use std::path::{Path, PathBuf};
use tubeloc_core::{files, CameraModel, Plane, TubeAxisPose, TubeDetection, TubeModel};
use tubeloc_refine::stereo_stage::{self, PhotoStage, RectifiedPair, StereoRegion};
use tubeloc_refine::hidden_end::{anchor_visible_end, unseen_length_variance, widen_along_axis, HiddenEnd};
use tubeloc_refine::silhouette::{silhouette_mask, snap_mask, trim_kept_mask, MaskSnap};
use tubeloc_refine::{GroundPlane, RefineConfig, RefineInput, Refiner, Scene, SeedKind, SeedSettings};

mod colour;
mod dataset;
pub(crate) use dataset::ground_of;
mod stereo;

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
    /// by its mask's colours (unless --no-colour-ends; `Refiner::seed_with_colour`).
    #[arg(long, requires = "dataset")]
    pub(crate) seeds_out: Option<PathBuf>,
    /// Camera model JSON of the image (ignored for the left image when --rig is given).
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
    /// (`tubeloc_refine::silhouette`: silhouette ∩ mask dilated by --snap-dilate-px, where it
    /// agrees with the mask); same format as --detections, in the order of --out. Detections
    /// without a converged pose or agreement keep their mask, eroded by --snap-kept-erode-px.
    #[arg(long)]
    pub(crate) snapped_out: Option<PathBuf>,
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
    /// --snapped-out: the silhouette is kept within this many pixels of the detector's mask.
    #[arg(long, default_value_t = MaskSnap::default().dilate_px)]
    pub(crate) snap_dilate_px: usize,
    /// --snapped-out: least IoU of the snapped mask with the detector's for the snap to be used.
    #[arg(long, default_value_t = MaskSnap::default().min_agreement)]
    pub(crate) snap_min_agreement: f64,
    /// --snapped-out: masks that are not snapped are eroded by this many pixels (the
    /// segmenter's masks are wider than the tube; 0 keeps them as they are).
    #[arg(long, default_value_t = MaskSnap::default().kept_erode_px)]
    pub(crate) snap_kept_erode_px: usize,
    /// --snapped-out: masks of fewer pixels than this are not snapped (they are trimmed like
    /// the masks that disagree with their pose; 0 snaps every mask).
    #[arg(long, default_value_t = MaskSnap::default().min_area_px)]
    pub(crate) snap_min_area_px: u64,
    /// Right image of a stereo pair (needs --rig).
    #[arg(long)]
    pub(crate) right: Option<PathBuf>,
    /// Rig JSON with both cameras.
    #[arg(long)]
    pub(crate) rig: Option<PathBuf>,
    /// Camera names of the pair in the rig, "LEFT,RIGHT" (default: the rig's first stereo pair).
    #[arg(long)]
    pub(crate) pair: Option<String>,
    /// Number of disparities searched (multiple of 16); the window starts at the disparity of
    /// the farthest seed + 0.5 m.
    #[arg(long, default_value_t = 256)]
    pub(crate) disparities: usize,
    /// Dataset mode: add the stereo term, with each image's right image (images[].right_file_name
    /// under DIR/right/, images[].right_camera, images[].T_left_right).
    #[arg(long, requires = "dataset")]
    pub(crate) stereo: bool,
    /// Stereo (--rig or --stereo): after the fit, move each converged tube along its centre's viewing
    /// ray to the best photometric agreement of the pair within ±this many millimetres
    /// (`tubeloc_refine::photo`); 0 disables.
    #[arg(long, default_value_t = 30.0)]
    pub(crate) photo_range_mm: f64,
    /// Photometric stage: move only the centre along its ray (distance) instead of each end of
    /// the axis along its own ray (distance and tilt, the default without a ground plane; with
    /// `--ground` the ground's tilt prior fixes the tilt better and only the centre moves).
    #[arg(long)]
    pub(crate) photo_centre_only: bool,
    /// Stereo: turn off the scene-occlusion test (on by default: contour points whose SGM
    /// scene depth lies more than `CylinderModel::occlusion_margin` in front of the cylinder,
    /// i.e. rocks or sand over the tube, are left out of the edge fit
    /// (`tubeloc_refine::Scene::depth`), and so are such pixels in the photometric stage).
    #[arg(long = "no-scene-occlusion", action = clap::ArgAction::SetFalse)]
    pub(crate) scene_occlusion: bool,
    /// Stereo: after the photometric stage, take the axis direction from the rims (end
    /// outlines) fitted in both views (`tubeloc_refine::rims`), about the photometric centre,
    /// for axes whose image direction lies within this angle of the epipolar lines, degrees
    /// (90: all, the default; 0: never). The photometric search barely sees the tilt of a tube
    /// along the rows; the rims cross them.
    #[arg(long, default_value_t = 90.0)]
    pub(crate) rim_max_epipolar_deg: f64,
    /// Stereo: turn off the last stage, the fit of the whole contour (limbs and rims) in both
    /// rectified views over all five pose parameters (`tubeloc_refine::two_view`; with the
    /// ground's tilt prior when a ground plane is given). On by default.
    #[arg(long = "no-two-view", action = clap::ArgAction::SetFalse)]
    pub(crate) two_view: bool,
    /// Settings of the two-view fit: JSON of `TwoViewConfig` fields (missing fields keep their
    /// defaults; for experiments).
    #[arg(long)]
    pub(crate) two_view_config: Option<PathBuf>,
    /// The two-view settings read from --two-view-config (filled in by `run`).
    #[arg(skip)]
    pub(crate) two_view_settings: tubeloc_refine::two_view::TwoViewConfig,
    /// Least ZNCC for the photometric depth to be applied.
    #[arg(long, default_value_t = 0.5)]
    pub(crate) photo_min_zncc: f64,
    /// Dataset mode: mask-agreement term instead of image edges: the silhouette is fitted to the
    /// boundary of each detection's mask (for --gt-seeds: the annotation's mask, i.e. a perfect
    /// segmenter, an upper bound).
    #[arg(long, requires = "dataset")]
    pub(crate) mask_term: bool,
    /// Stereo: erode each detection mask by this many pixels before keeping its points (SGM
    /// fattens the foreground at the tube's outline; on the synthetic stereo set erosion made the
    /// points' bias worse, hence 0).
    #[arg(long, default_value_t = 0)]
    pub(crate) stereo_erode: usize,
    /// Ground plane "nx,ny,nz,d" in the camera frame (`n·X = d`, n up), metres; with
    /// --dataset, "auto" takes it from images[].T_world_cam and images[].ground_height_m (ground
    /// = world z = ground_height_m, the median terrain height within the capture stops, written
    /// by `tubeloc synth`; z = 0 where absent). The terrain has relief about it: its tilt is a
    /// prior, its height places mask seeds in mono.
    #[arg(long, allow_hyphen_values = true)]
    pub(crate) ground: Option<String>,
    /// Stereo with a ground plane: keep the given plane's height for every tube. By default each
    /// tube's plane is moved to the median height of the matched terrain beside it (the 300
    /// terrain points nearest its box, within 160 px, outside every tube's mask), which places
    /// the tubes that get no stereo points of their own (outside the right camera's view) on
    /// the terrain instead of the nominal ground.
    #[arg(long)]
    pub(crate) no_local_ground: bool,
    /// Refiner configuration JSON (fields of RefineConfig; missing fields keep their defaults).
    #[arg(long)]
    pub(crate) config: Option<PathBuf>,
    /// Tube model TOML (default: the built-in model of data/tube.toml).
    #[arg(long)]
    pub(crate) tube: Option<PathBuf>,
}

pub(crate) fn parse_ground(s: &str) -> Result<GroundPlane> {
    let v: Vec<f64> = s.split(',').map(|t| t.trim().parse::<f64>()).collect::<std::result::Result<_, _>>().with_context(|| format!("--ground {s:?}: expected nx,ny,nz,d"))?;
    if v.len() != 4 || v.iter().any(|x| !x.is_finite()) {
        bail!("--ground {s:?}: expected 4 finite numbers nx,ny,nz,d");
    }
    let n = Vector3::new(v[0], v[1], v[2]);
    let norm = n.norm();
    if norm < 1e-9 {
        bail!("--ground {s:?}: the normal is zero");
    }
    Ok(GroundPlane { normal: n / norm, offset: v[3] / norm })
}


/// Stereo points (left camera frame) per detection: SGM in the detections' regions of the
/// rectified pair, triangulated, kept where they project into the detection's mask (eroded by
/// `--stereo-erode`) or box (see [`stereo`]).
fn stereo_points(args: &RefineArgs, left: &Plane<u8>, rig_path: &Path, dets: &[TubeDetection], ground: Option<&GroundPlane>) -> Result<(CameraModel, stereo::StereoRegions, RectifiedPair)> {
    let right_path = args.right.as_ref().context("--rig needs --right")?;
    let (_, lcam, rect) = crate::cmd_stereo::rectification_from_rig(rig_path, args.pair.as_deref())?;
    let right = crate::cmd_stereo::load_gray(right_path)?;
    let left_path = args.image.as_deref().unwrap_or(Path::new("left image"));
    let regions: Vec<StereoRegion> = dets.iter().map(stereo::region_of).collect();
    let (per, pair) = stereo::match_regions(&rect, &lcam, left, &right, &regions, args.disparities, args.stereo_erode, ground)
        .with_context(|| format!("stereo {} / {}", left_path.display(), right_path.display()))?;
    Ok((lcam, per, pair))
}

/// Draws the fitted contour of each pose into an RGB copy of the image.
fn overlay(path: &Path, gray: &Plane<u8>, refiner: &Refiner, cam: &CameraModel, poses: &[TubeAxisPose]) -> Result<()> {
    let (w, h) = (gray.width as u32, gray.height as u32);
    let mut img = image::RgbImage::from_fn(w, h, |x, y| {
        let v = gray.get(x as usize, y as usize);
        image::Rgb([v, v, v])
    });
    for p in poses {
        let col = if p.converged { [40, 230, 60] } else { [240, 40, 40] };
        for u in refiner.contour_pixels(cam, p, 0.5) {
            let (x, y) = (u.x.round(), u.y.round());
            if x >= 0.0 && y >= 0.0 && x < w as f64 && y < h as f64 {
                img.put_pixel(x as u32, y as u32, image::Rgb(col));
            }
        }
        if let Some(c) = cam.project(&Point3::from(p.centre)) {
            for k in -3i64..=3 {
                for (x, y) in [(c.x.round() as i64 + k, c.y.round() as i64), (c.x.round() as i64, c.y.round() as i64 + k)] {
                    if x >= 0 && y >= 0 && x < w as i64 && y < h as i64 {
                        img.put_pixel(x as u32, y as u32, image::Rgb(col));
                    }
                }
            }
        }
    }
    let mut buf = std::io::Cursor::new(Vec::new());
    img.write_to(&mut buf, image::ImageFormat::Png).context("cannot encode PNG")?;
    files::write_atomic(path, &buf.into_inner())?;
    Ok(())
}

/// The refiner of the arguments (config and tube model files).
pub(crate) fn refiner_of(args: &RefineArgs) -> Result<Refiner> {
    let config = match &args.config {
        Some(p) => files::read_json::<RefineConfig>(p).with_context(|| format!("refine config {}", p.display()))?,
        None => RefineConfig::default(),
    };
    let tube = match &args.tube {
        Some(p) => TubeModel::load(p).with_context(|| format!("tube model {}", p.display()))?,
        None => TubeModel::default(),
    };
    Refiner::new(&tube, config).context("building the refiner")
}

/// The stages after the fit of one pose, in order: with a scene depth map (stereo) and unless
/// `--no-hidden-end`, a pose refined from a mask detection `det` is moved along its axis onto its
/// visible end when its other end is hidden ([`anchor_visible_end`]; template-pose detections'
/// masks are the template's silhouette, not what is visible); then, with a rectified `pair`, the
/// photometric / rims / two-view stage with the settings of the pose's seed kind
/// ([`RefineArgs::photo_stage`]; `det` is `None` for an explicit seed). The anchoring comes
/// first so that the two-view fit starts from the anchored centre.
#[allow(clippy::too_many_arguments)]
pub(crate) fn after_fit(args: &RefineArgs, pose: &mut TubeAxisPose, det: Option<&TubeDetection>, depth: Option<&Plane<f32>>, pair: Option<&RectifiedPair>, ground: Option<&GroundPlane>, refiner: &Refiner, camera: &CameraModel) {
    // The mask of a mask seed (the learned segmenter's kind; not a template pose's).
    let mask = det.filter(|d| d.t_cam_tube.is_none()).and_then(|d| d.mask.as_ref()).and_then(|m| m.to_mask().ok());
    if let (Some(depth), Some(mask), false) = (depth, &mask, args.no_hidden_end) {
        anchor_visible_end(pose, refiner.model.length, mask, depth, camera, &HiddenEnd::default());
    }
    if let (Some(pair), true) = (pair, args.photo_range_mm > 0.0) {
        let kind = det.map_or(SeedKind::Explicit, SeedKind::of);
        stereo_stage::photo_refine(pose, &refiner.model, pair, &args.photo_stage(ground, refiner, kind));
    }
    // The centre's along-axis freedom over the part of the tube the mask does not show.
    if let Some(v) = mask.as_ref().and_then(|m| unseen_length_variance(pose, refiner.model.length, m, camera, UNSEEN_ANCHOR_PX)) {
        widen_along_axis(pose, v);
    }
}

/// The uncertainty (pixels along the axis) of a visible end that anchors a tube
/// ([`unseen_length_variance`]): the detector's mask ends within about this of the tube's.
const UNSEEN_ANCHOR_PX: f64 = 3.0;

/// `det` with its mask snapped to `pose`'s silhouette ([`snap_mask`]) when the pose converged
/// (and is the fit's, not a kept seed) and agrees with the mask; otherwise with its mask
/// trimmed ([`trim_kept_mask`]), or unchanged without a mask. Returns whether it was snapped.
pub(crate) fn snapped_detection(det: &mut TubeDetection, pose: &TubeAxisPose, refiner: &Refiner, camera: &CameraModel, snap: &MaskSnap) -> bool {
    let Some(mask) = det.mask.as_ref().and_then(|m| m.to_mask().ok()) else { return false };
    let fitted = pose.converged && pose.seed_kept.is_none();
    let snapped = fitted.then(|| snap_mask(&mask, &silhouette_mask(&refiner.model, pose, camera), snap)).flatten();
    let was_snapped = snapped.is_some();
    if let Some(m) = snapped.or_else(|| trim_kept_mask(&mask, snap)) {
        det.bbox = m.bbox();
        det.mask = Some(tubeloc_core::Rle::from_mask(&m));
    }
    was_snapped
}

impl RefineArgs {
    /// The mask snap of `--snapped-out`.
    pub(crate) fn mask_snap(&self) -> Result<MaskSnap> {
        if !(0.0..=1.0).contains(&self.snap_min_agreement) {
            bail!("--snap-min-agreement {}: expected a value in [0, 1]", self.snap_min_agreement);
        }
        Ok(MaskSnap { dilate_px: self.snap_dilate_px, min_agreement: self.snap_min_agreement, kept_erode_px: self.snap_kept_erode_px, min_area_px: self.snap_min_area_px })
    }

    /// Writes the snapped detections of `--snapped-out` (if given) and reports how many masks
    /// were snapped.
    pub(crate) fn write_snapped(&self, snapped: &[(TubeDetection, bool)]) -> Result<()> {
        let Some(path) = &self.snapped_out else { return Ok(()) };
        let dets: Vec<&TubeDetection> = snapped.iter().map(|(d, _)| d).collect();
        files::write_json(path, &dets).with_context(|| format!("writing {}", path.display()))?;
        eprintln!("{} of {} masks snapped to their poses -> {}", snapped.iter().filter(|(_, s)| *s).count(), snapped.len(), path.display());
        Ok(())
    }
    /// The ground plane the stereo matcher measures local grounds against: `ground`, unless
    /// `--no-local-ground` (then none, and no terrain is matched for it).
    pub(crate) fn local_ground_reference<'a>(&self, ground: Option<&'a GroundPlane>) -> Option<&'a GroundPlane> {
        ground.filter(|_| !self.no_local_ground)
    }

    /// Whether the photometric stage moves each end along its own ray (distance and tilt)
    /// rather than the centre alone: not with `--photo-centre-only`, and not with a ground
    /// plane, whose tilt prior fixes the tilt better.
    pub(crate) fn photo_moves_ends(&self, has_ground: bool) -> bool {
        !self.photo_centre_only && !has_ground
    }

    /// The photometric / rims stage's settings ([`stereo_stage::photo_refine`]) for a pose
    /// refined from a seed of `kind`; with a ground plane the two-view fit's tilt prior and the
    /// rims' tilt change have the deviation of that kind's ground tilt prior
    /// ([`SeedSettings::ground_tilt_sigma_deg`]), as in the fit before them: mask seeds are taken
    /// to lie parallel to the ground (`mask_seed_tilt_sigma_deg`), other seeds may tilt
    /// (`ground_tilt_sigma_deg`).
    pub(crate) fn photo_stage(&self, ground: Option<&GroundPlane>, refiner: &Refiner, kind: SeedKind) -> PhotoStage {
        let has_ground = ground.is_some();
        let tilt_sigma_deg = SeedSettings::new(&refiner.config, kind, has_ground).ground_tilt_sigma_deg;
        PhotoStage {
            two_view: self.two_view.then_some(self.two_view_settings),
            ground: ground.map(|g| (g.normal, tilt_sigma_deg)),
            range_m: self.photo_range_mm * 1e-3,
            min_zncc: self.photo_min_zncc,
            ends: self.photo_moves_ends(has_ground),
            occlusion: self.scene_occlusion,
            rim_max_epipolar_deg: self.rim_max_epipolar_deg,
            rim_tilt_prior_deg: has_ground.then_some(tilt_sigma_deg),
        }
    }
}

/// Runs `tubeloc refine`.
pub fn run(mut args: RefineArgs) -> Result<()> {
    if let Some(p) = &args.two_view_config {
        args.two_view_settings = files::read_json(p).with_context(|| format!("two-view config {}", p.display()))?;
    }
    if args.dataset.is_some() {
        return dataset::run(&args);
    }
    let refiner = refiner_of(&args)?;
    let snap = args.mask_snap()?;
    let ground = args.ground.as_deref().map(parse_ground).transpose()?;
    let det_path = args.detections.as_ref().context("--detections is required without --dataset")?;
    let image_path = args.image.as_ref().context("--image is required without --dataset")?;
    let mut dets = tubeloc_core::detection::read_coco_results(det_path)?;
    if let Some(id) = args.image_id {
        dets.retain(|d| d.image_id == id);
    }
    let loaded = colour::load(image_path)?;
    let colour = loaded.colour(!args.no_colour_ends);
    let gray = &loaded.gray;
    let (camera, stereo, depth, pair, grounds) = match &args.rig {
        Some(rig) => {
            let (c, s, p) = stereo_points(&args, &gray, rig, &dets, args.local_ground_reference(ground.as_ref()))?;
            let grounds = s.tube_grounds(ground);
            (c, s.points, Some(s.depth), Some(p), grounds)
        }
        None => {
            if args.right.is_some() {
                bail!("--right needs --rig (the pair's calibration)");
            }
            let p = args.camera.as_ref().context("--camera is required without --rig")?;
            (CameraModel::load_json(p).with_context(|| format!("camera {}", p.display()))?, vec![Vec::new(); dets.len()], None, None, vec![ground; dets.len()])
        }
    };
    if gray.width != camera.width as usize || gray.height != camera.height as usize {
        bail!("{} is {}x{} but the camera is {}x{}", image_path.display(), gray.width, gray.height, camera.width, camera.height);
    }
    let image = Plane::from_vec(gray.width, gray.height, gray.data.iter().map(|&v| v as f32 / 255.0).collect());
    let bar = indicatif::ProgressBar::new(dets.len() as u64);
    let mut poses = Vec::with_capacity(dets.len());
    for (i, d) in dets.iter().enumerate() {
        let input = RefineInput { image: &image, camera: &camera, ground: grounds[i], scene: Scene { depth: depth.as_ref().filter(|_| args.scene_occlusion).map(|d| (d, &camera)), stereo_points: &stereo[i], ground: None, mask: None, image_axis: None, shown: None } };
        poses.push(refiner.refine_with_colour(&input, d, colour.as_ref()));
        bar.inc(1);
    }
    bar.finish_and_clear();
    for ((p, d), g) in poses.iter_mut().zip(&dets).zip(&grounds) {
        after_fit(&args, p, Some(d), depth.as_ref(), pair.as_ref(), g.as_ref(), &refiner, &camera);
    }
    for (i, p) in poses.iter().enumerate() {
        let c = p.centre * 1e3;
        let status = match &p.failure {
            None => "ok".to_string(),
            Some(f) => format!("FAILED {:?}: {}", f.reason, f.message),
        };
        println!(
            "tube {i} (image {}, score {:.2}): centre [{:.1}, {:.1}, {:.1}] mm, axis [{:.3}, {:.3}, {:.3}], end conf {:.2}, rms {:.2} px, {}/{} inliers, {} stereo pts: {status}",
            p.image_id, p.score, c.x, c.y, c.z, p.axis.x, p.axis.y, p.axis.z, p.end_confidence, p.residuals.rms_px, p.residuals.inliers, p.residuals.count, stereo[i].len()
        );
    }
    files::write_json(&args.out, &poses).with_context(|| format!("writing {}", args.out.display()))?;
    if args.snapped_out.is_some() {
        let snapped: Vec<(TubeDetection, bool)> = dets
            .iter()
            .zip(&poses)
            .map(|(d, p)| {
                let mut d = d.clone();
                let s = snapped_detection(&mut d, p, &refiner, &camera, &snap);
                (d, s)
            })
            .collect();
        args.write_snapped(&snapped)?;
    }
    if let Some(o) = &args.overlay {
        overlay(o, &gray, &refiner, &camera, &poses).with_context(|| format!("writing {}", o.display()))?;
    }
    eprintln!("{} poses ({} converged) -> {}", poses.len(), poses.iter().filter(|p| p.converged).count(), args.out.display());
    Ok(())
}
