//! [`Locator`]: the main job on in-memory images.

use crate::detector::{check_mask_sizes, TubeDetector};
use crate::error::{PipelineError, Result};
use crate::frame::{refine_pixels, Frame, FrameOptions, FramePixels, SeedItem, StereoView};
use crate::settings::LocatorSettings;
use image::DynamicImage;
use nalgebra::Vector3;
use rayon::prelude::*;
use serde::Serialize;
use std::time::Instant;
use tubeloc_core::{FailureReason, Plane, Pose, Rig, RigCamera, TubeAxisPose, TubeDetection};
use tubeloc_grasp::{overlapping_tubes, GraspCheck, GraspPlanner, Scene};
use tubeloc_refine::{GroundPlane, Refiner};

/// Which cameras of a rig the images come from.
#[derive(Clone, Debug, Default)]
pub struct CameraSelection {
    /// The rig camera that took the (left) image (default: the left camera of `pair`, else the
    /// rig's first camera).
    pub camera: Option<String>,
    /// The stereo pair `(left, right)` used when a right image is given (default: the rig's
    /// first stereo pair).
    pub pair: Option<(String, String)>,
}

/// The images of one [`Locator::locate`] call, with what is known about the scene.
#[derive(Clone, Copy)]
pub struct LocateInput<'a> {
    /// The (left) image, of the selected camera's size; grey or colour, 8 or 16 bits.
    pub image: &'a DynamicImage,
    /// The right image of the rig's pair: adds the stereo term and the stereo stages.
    pub right: Option<&'a DynamicImage>,
    /// Ground plane in the image's camera frame (`n · X = d`, n up, metres): places mask seeds
    /// on it, gives the fit its tilt prior and the grasp its approach direction.
    pub ground: Option<GroundPlane>,
    /// Up direction (camera frame, any length) for the grasp approach when there is no ground
    /// plane; default `-y` (a roughly level camera).
    pub up: Option<Vector3<f64>>,
    /// Where no tube is handed over: a mask of the image's size whose non-zero pixels cover
    /// rover hardware in view (the arm, the deck, wheels) or any region to leave out. A
    /// converged tube whose centre projects into it is listed as
    /// [`Rejection::InIgnoredRegion`].
    pub ignore: Option<&'a Plane<u8>>,
}

impl<'a> LocateInput<'a> {
    /// A mono input with nothing else known.
    pub fn mono(image: &'a DynamicImage) -> Self {
        LocateInput { image, right: None, ground: None, up: None, ignore: None }
    }
}

/// One located tube: the refined pose, its grasp frames and the grasp's collision check.
#[derive(Clone, Debug, Serialize)]
pub struct LocatedTube {
    /// The refined pose (camera frame, metres), flattened into this object in JSON.
    #[serde(flatten)]
    pub pose: TubeAxisPose,
    /// Grasp frame in the camera frame: the grasp chosen by the collision check
    /// ([`LocatedTube::grasp`]`.t_cam_grasp`): origin on the tube axis, +x along the flip-free
    /// axis, +z the approach, +y the direction the fingers close. It is the plain grasp from
    /// above (origin at the tube centre, approach against up) when that one is free, when no
    /// candidate is, and for rejected tubes.
    #[serde(rename = "T_cam_grasp")]
    pub t_cam_grasp: Pose,
    /// The grasp frame in the rig frame (`T_rig_cam · T_cam_grasp`).
    #[serde(rename = "T_rig_grasp")]
    pub t_rig_grasp: Pose,
    /// Probability that this is a tube: the detector's score through the score calibration
    /// ([`LocatorSettings::calibration`]), fitted on real validation composites.
    pub probability: f64,
    /// Probability that this pose is a tube from the detector's score and the fit's evidence
    /// ([`LocatorSettings::pose_evidence`]); absent without one and for unconverged fits.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pose_evidence: Option<f64>,
    /// How strongly the edges along the tube's limbs go on past its ends, against along its
    /// body ([`tubeloc_refine::limb_continuation`]; about 0.15 for a tube, 0.5-2 for a rim);
    /// absent for unconverged fits and where it cannot be measured (an end out of the image).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub limb_continuation: Option<f64>,
    /// The grasp's collision check against the ground, the other located tubes and (stereo)
    /// the terrain ([`tubeloc_grasp::GraspPlanner::check`]); for rejected tubes unchecked
    /// (`candidates_tried` 0).
    pub grasp: GraspCheck,
}

/// Why a detection did not become a located tube.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum Rejection {
    /// The fit failed; the pose's `failure` has the reason and a message.
    FitFailed(FailureReason),
    /// The fit converged but the probability of a tube is below the acceptance threshold.
    LowProbability {
        /// The tube's probability.
        probability: f64,
        /// The threshold ([`tubeloc_core::ScoreCalibration::threshold`]).
        threshold: f64,
    },
    /// The fit converged and the probability passes the threshold, but the fit's evidence
    /// ([`LocatorSettings::pose_evidence`]) says it is unlikely a tube: few contour samples on
    /// edges, a blurred axis, no seal end showing.
    WeakPoseEvidence {
        /// The pose evidence ([`LocatedTube::pose_evidence`]).
        evidence: f64,
        /// The least accepted ([`LocatorSettings::min_pose_evidence`]).
        min: f64,
    },
    /// The fit converged and passes the probability and the pose evidence, but the edges along
    /// its limbs go on past its ends ([`LocatedTube::limb_continuation`]): a slab rim, a crack
    /// or a layer of bedrock, not a tube, which ends.
    LimbsContinue {
        /// The limb continuation.
        continuation: f64,
        /// The largest accepted ([`LocatorSettings::max_limb_continuation`]).
        max: f64,
    },
    /// The fitted tube's solid interpenetrates a stronger located tube's (two such tubes cannot
    /// both be right; [`tubeloc_grasp::overlapping_tubes`]).
    IntersectsTube {
        /// Index of the stronger tube in [`LocateOutput::tubes`].
        other: usize,
    },
    /// The frame is underexposed: its highlights ([`highlight_level`]) lie below
    /// [`LocatorSettings::min_highlight_level`], so what the detector sees is mostly sensor
    /// noise, and a tube found in it is not handed to the planner (retake the frame).
    Underexposed {
        /// The frame's highlight level, 8-bit grey level.
        highlight: f64,
        /// The least highlight level a frame's tubes are handed over from.
        min: f64,
    },
    /// The tube's centre projects into the ignored region of the frame
    /// ([`LocateInput::ignore`]).
    InIgnoredRegion {
        /// Image position (column, row) of the tube's centre, pixels.
        pixel: (f64, f64),
    },
}

impl Rejection {
    /// A short machine-readable name (`fit_failed`, `low_probability`, `weak_pose_evidence`,
    /// `limbs_continue`, `intersects_tube`, `underexposed`, `in_ignored_region`).
    pub fn name(&self) -> &'static str {
        match self {
            Rejection::FitFailed(_) => "fit_failed",
            Rejection::LowProbability { .. } => "low_probability",
            Rejection::WeakPoseEvidence { .. } => "weak_pose_evidence",
            Rejection::LimbsContinue { .. } => "limbs_continue",
            Rejection::IntersectsTube { .. } => "intersects_tube",
            Rejection::Underexposed { .. } => "underexposed",
            Rejection::InIgnoredRegion { .. } => "in_ignored_region",
        }
    }
}

/// A detection whose refinement was rejected, with its (unconverged) pose.
#[derive(Clone, Debug)]
pub struct RejectedTube {
    /// The pose where the fit stopped, with its grasp frames.
    pub tube: LocatedTube,
    /// Why it was rejected.
    pub reason: Rejection,
}

/// Wall times of the stages of one [`Locator::locate`] call, seconds.
#[derive(Clone, Debug, Default, Serialize)]
#[non_exhaustive]
pub struct Timings {
    /// Detection.
    pub detect_s: f64,
    /// Stereo matching, the fits and the stages after them.
    pub refine_s: f64,
    /// The fit alone of each detection, milliseconds, in detection order.
    pub fit_ms: Vec<f64>,
    /// The tube-tube check and the grasp checks of all located tubes (terrain included),
    /// milliseconds.
    pub grasp_ms: f64,
    /// The whole call.
    pub total_s: f64,
}

/// What [`Locator::locate`] found.
#[derive(Clone, Debug)]
#[non_exhaustive]
pub struct LocateOutput {
    /// Located tubes (converged fits), one per physical tube, best score first.
    pub tubes: Vec<LocatedTube>,
    /// Rejected detections, best score first.
    pub rejected: Vec<RejectedTube>,
    /// The detections that seeded the refinement, as the detector gave them (the refinement
    /// takes each in its file form, [`crate::detector::canonical`]).
    pub detections: Vec<TubeDetection>,
    /// How many converged poses were merged into a better pose of the same tube.
    pub merged: usize,
    /// Whether the grasp checks saw terrain (a stereo run): `false` in mono, where grasps are
    /// checked against the ground plane and the other tubes only.
    pub terrain_checked: bool,
    /// Unit up direction used for the grasp frames, camera frame.
    pub up_cam: Vector3<f64>,
    /// The frame's highlight level ([`highlight_level`]); under
    /// [`LocatorSettings::min_highlight_level`] no tube is located.
    pub highlight_level: f64,
    /// What makes this frame's result unreliable, as the detector sees it from the camera
    /// and ground ([`TubeDetector::scale_warning`]): e.g. tubes too narrow for the learned
    /// detector's working scale. (An underexposed frame shows in `highlight_level` and in
    /// its rejections.)
    pub warnings: Vec<String>,
    /// Stage timings.
    pub timings: Timings,
}

impl LocateOutput {
    /// All tubes in output order: located, then rejected.
    pub fn all_tubes(&self) -> impl Iterator<Item = &LocatedTube> {
        self.tubes.iter().chain(self.rejected.iter().map(|r| &r.tube))
    }
}

/// The pipeline: detect -> (stereo) -> refine -> stages after the fit -> duplicate merging ->
/// tube-tube consistency -> grasp frames checked for collisions, for images of one rig camera
/// (or stereo pair).
pub struct Locator {
    rig: Rig,
    camera: RigCamera,
    pair: Option<(String, String)>,
    detector: Box<dyn TubeDetector>,
    refiner: Refiner,
    planner: GraspPlanner,
    settings: LocatorSettings,
}

/// Most pixels of an image the locator takes (100 megapixels, e.g. 10000 x 10000). Peak
/// memory is about 200 MB plus 12 bytes per pixel (the decoded image, its grey levels and
/// the refiner's float copy at full resolution; the detector runs at its working scale in
/// bands of bounded size): ~290 MB at 5472 x 3648 with either detector, ~1.4 GB at this
/// bound (80 megapixels: 760 MB learned, 820 MB Line2D).
pub const MAX_IMAGE_PIXELS: u64 = 100_000_000;

/// Refuses cameras whose images exceed [`MAX_IMAGE_PIXELS`], before any image is read.
fn check_image_pixels(width: u32, height: u32, camera: &str) -> Result<()> {
    let n = width as u64 * height as u64;
    if n > MAX_IMAGE_PIXELS {
        return Err(PipelineError::Input(format!(
            "camera {camera:?} takes {width}x{height} images ({:.0} megapixels): more than the {} megapixels tubeloc locates in (about {:.1} GB of memory); downsample the image and its camera model",
            n as f64 / 1e6,
            MAX_IMAGE_PIXELS / 1_000_000,
            (200e6 + 12.0 * n as f64) / 1e9
        )));
    }
    Ok(())
}

impl Locator {
    /// A locator for images of the selected camera of `rig`, seeded by `detector`.
    pub fn new(rig: &Rig, selection: &CameraSelection, detector: Box<dyn TubeDetector>, settings: LocatorSettings) -> Result<Self> {
        let pair = selection.pair.clone().or_else(|| rig.stereo_pairs.first().cloned());
        let name = match (&selection.camera, &pair) {
            (Some(n), _) => n.clone(),
            (None, Some((l, _))) => l.clone(),
            (None, None) => rig.cameras.first().map(|c| c.name.clone()).ok_or_else(|| PipelineError::Input("the rig has no cameras".into()))?,
        };
        let camera = rig.camera(&name).ok_or_else(|| PipelineError::Input(format!("the rig has no camera named {name:?}")))?.clone();
        camera.model.validate()?;
        check_image_pixels(camera.model.width, camera.model.height, &camera.name)?;
        settings.validate_cuts().map_err(|e| PipelineError::Input(format!("locator settings: {e}")))?;
        let refiner = Refiner::new(&settings.tube, settings.refine.clone())?;
        let planner = GraspPlanner::new(settings.gripper.clone(), settings.grasp.clone(), &settings.tube)?;
        Ok(Locator { rig: rig.clone(), camera, pair, detector, refiner, planner, settings })
    }

    /// Makes the rig camera `name` the one the (left) images come from, e.g. per frame for a
    /// rig of one camera per image (a PDS camera list). The stereo pair stays: a right image
    /// is refused unless `name` is its left camera.
    pub fn select_camera(&mut self, name: &str) -> Result<()> {
        if self.camera.name == name {
            return Ok(());
        }
        let camera = self.rig.camera(name).ok_or_else(|| PipelineError::Input(format!("the rig has no camera named {name:?}")))?.clone();
        camera.model.validate()?;
        check_image_pixels(camera.model.width, camera.model.height, &camera.name)?;
        self.camera = camera;
        Ok(())
    }

    /// The rig camera the (left) images come from.
    pub fn camera(&self) -> &RigCamera {
        &self.camera
    }

    /// The refiner (tube model and configuration).
    pub fn refiner(&self) -> &Refiner {
        &self.refiner
    }

    /// The grasp planner (gripper and candidate settings).
    pub fn planner(&self) -> &GraspPlanner {
        &self.planner
    }

    /// The settings.
    pub fn settings(&self) -> &LocatorSettings {
        &self.settings
    }

    /// The detector.
    pub fn detector(&self) -> &dyn TubeDetector {
        self.detector.as_ref()
    }

    /// The right camera and `T_left_right` of the stereo pair whose left camera is this
    /// locator's camera.
    fn right_view(&self) -> Result<(RigCamera, Pose)> {
        let (l, r) = match &self.pair {
            Some((l, r)) if *l == self.camera.name => (l, r),
            Some((l, r)) => return Err(PipelineError::Input(format!("right image: the image's camera {:?} is not the left camera of pair {l},{r}", self.camera.name))),
            None => return Err(PipelineError::Input("right image: the rig has no stereo pair; select one (--pair LEFT,RIGHT)".into())),
        };
        let right = self.rig.camera(r).ok_or_else(|| PipelineError::Input(format!("the rig has no camera named {r:?}")))?.clone();
        Ok((right, self.rig.relative_pose(l, r)?))
    }

    fn check_size(&self, image: &DynamicImage, what: &str, cam: &RigCamera) -> Result<()> {
        let (w, h) = (image.width(), image.height());
        if (w, h) != (cam.model.width, cam.model.height) {
            return Err(PipelineError::Input(format!("the {what} is {w}x{h} but rig camera {:?} is {}x{}", cam.name, cam.model.width, cam.model.height)));
        }
        Ok(())
    }

    /// Detects with this locator's detector (COCO image id 0) and checks the masks' sizes.
    /// (A detector working at its own pixel scale wraps the detector: it resamples the image
    /// for the camera and maps its detections back to the image's pixels before they return.)
    pub fn detect(&self, image: &DynamicImage, ground: Option<&GroundPlane>) -> Result<Vec<TubeDetection>> {
        self.check_size(image, "image", &self.camera)?;
        let dets = self.detector.detect(image, &self.camera.model, ground, 0)?;
        check_mask_sizes(&dets, image.width(), image.height(), &self.detector.origin())?;
        Ok(dets)
    }

    /// Refines `detections` in the input's images: stereo points (with a right image), the
    /// fit, and the stages after it; one pose per detection, in order (camera frame), with
    /// each fit's time in milliseconds. No merging, no grasp frames.
    pub fn refine(&self, input: &LocateInput, detections: &[TubeDetection]) -> Result<(Vec<TubeAxisPose>, Vec<f64>)> {
        let r = self.refine_items(input, &FramePixels::of(input.image, self.settings.colour_ends), detections)?;
        Ok((r.poses, r.fit_ms))
    }

    /// [`Locator::refine`] returning the whole frame refinement (stereo points, scene depth).
    pub fn refine_frame(&self, input: &LocateInput, detections: &[TubeDetection]) -> Result<crate::frame::FrameRefinement> {
        self.refine_items(input, &FramePixels::of(input.image, self.settings.colour_ends), detections)
    }

    fn refine_items(&self, input: &LocateInput, px: &FramePixels, detections: &[TubeDetection]) -> Result<crate::frame::FrameRefinement> {
        self.check_size(input.image, "image", &self.camera)?;
        check_mask_sizes(detections, input.image.width(), input.image.height(), &self.detector.origin())?;
        let right = match input.right {
            Some(img) => {
                let (cam, t) = self.right_view()?;
                self.check_size(img, "right image", &cam)?;
                Some((img, cam, t))
            }
            None => None,
        };
        let frame = Frame { image: input.image, camera: &self.camera.model, image_id: 0, ground: input.ground, stereo: right.as_ref().map(|(img, cam, t)| StereoView { right: img, right_camera: &cam.model, t_left_right: *t }) };
        let items: Vec<SeedItem> = detections.iter().cloned().map(SeedItem::Detection).collect();
        refine_pixels(&self.refiner, &self.settings, &frame, px, &items, &FrameOptions::default())
    }

    /// The unit up direction for grasp frames: the ground normal, else `input.up`, else -y.
    pub fn up_direction(input: &LocateInput) -> Result<Vector3<f64>> {
        if let Some(g) = &input.ground {
            return Ok(g.normal);
        }
        match input.up {
            Some(u) if u.iter().all(|c| c.is_finite()) && u.norm() >= 1e-9 => Ok(u.normalize()),
            Some(u) => Err(PipelineError::Input(format!("up direction {:?} is zero or not finite", u.as_slice()))),
            None => Ok(-Vector3::y()),
        }
    }

    /// The main job: detect, (stereo,) refine, the stages after the fit, one pose per physical
    /// tube, the weaker of two interpenetrating tubes rejected, grasps checked for collisions
    /// ([`tubeloc_grasp`]) and their frames.
    pub fn locate(&self, input: &LocateInput) -> Result<LocateOutput> {
        let t0 = Instant::now();
        let up = Self::up_direction(input)?;
        if let Some(m) = input.ignore {
            let (w, h) = (input.image.width() as usize, input.image.height() as usize);
            if (m.width, m.height) != (w, h) || m.data.len() != w * h {
                return Err(PipelineError::Input(format!("the ignore mask is {}x{} but the image is {w}x{h}", m.width, m.height)));
            }
        }
        let detections = self.detect(input.image, input.ground.as_ref())?;
        let px = FramePixels::of(input.image, self.settings.colour_ends);
        let detect_s = t0.elapsed().as_secs_f64();
        let t1 = Instant::now();
        // Each detection is refined in the form it has in a detections file, so that `locate`
        // and `detect` + `refine` give the same poses.
        let seeds: Vec<TubeDetection> = detections.iter().cloned().map(crate::detector::canonical).collect();
        let refined = self.refine_items(input, &px, &seeds)?;
        let refine_s = t1.elapsed().as_secs_f64();
        // Poses best first with the index of their seed item (its ground plane), then one per
        // physical tube; merging keeps the order, so the kept poses are matched in sequence.
        let mut order: Vec<usize> = (0..refined.poses.len()).collect();
        order.sort_by(|&a, &b| {
            let (x, y) = (&refined.poses[a], &refined.poses[b]);
            y.converged.cmp(&x.converged).then(y.score.total_cmp(&x.score))
        });
        let mut poses: Vec<TubeAxisPose> = order.iter().map(|&k| refined.poses[k].clone()).collect();
        let merged = if self.settings.merge_duplicates { tubeloc_refine::duplicates::merge_duplicates(&mut poses, &self.settings.tube) } else { 0 };
        let mut items = order.iter().copied();
        let seed_item: Vec<usize> = poses.iter().map(|p| items.by_ref().find(|&k| refined.poses[k] == *p).expect("merging keeps a subsequence of the poses")).collect();
        let (mut tubes, mut rejected) = (Vec::new(), Vec::new());
        let mut tube_items = Vec::new();
        let cal = &self.settings.calibration;
        let (highlight, min_highlight) = (highlight_level(&px.gray), self.settings.min_highlight_level);
        for (pose, item) in poses.into_iter().zip(seed_item) {
            let t_cam_grasp = pose.grasp_frame(&up);
            let failure = pose.failure.as_ref().map(|f| f.reason);
            let probability = cal.probability(pose.score);
            let ignored = ignored_pixel(input.ignore, &self.camera.model, &pose);
            let evidence = self.settings.pose_evidence.as_ref().filter(|_| pose.converged).map(|m| m.probability(&pose));
            let weak = evidence.filter(|&e| e < self.settings.min_pose_evidence);
            let limbs = if pose.converged { tubeloc_refine::limb_continuation::limb_continuation(&px.gray, &self.camera.model, &self.settings.tube, &pose) } else { None };
            let going_on = limbs.zip(self.settings.max_limb_continuation).filter(|&(c, max)| c > max);
            let tube = LocatedTube { t_rig_grasp: self.camera.t_rig_cam * t_cam_grasp, t_cam_grasp, grasp: GraspCheck::unchecked(t_cam_grasp), pose, probability, pose_evidence: evidence, limb_continuation: limbs };
            match (tube.pose.converged, failure, ignored, weak, going_on) {
                (true, _, _, _, _) if probability >= cal.threshold && highlight < min_highlight => rejected.push(RejectedTube { tube, reason: Rejection::Underexposed { highlight, min: min_highlight } }),
                (true, _, Some(pixel), _, _) if probability >= cal.threshold => rejected.push(RejectedTube { tube, reason: Rejection::InIgnoredRegion { pixel } }),
                (true, _, None, Some(evidence), _) if probability >= cal.threshold => rejected.push(RejectedTube { tube, reason: Rejection::WeakPoseEvidence { evidence, min: self.settings.min_pose_evidence } }),
                (true, _, None, None, Some((continuation, max))) if probability >= cal.threshold => rejected.push(RejectedTube { tube, reason: Rejection::LimbsContinue { continuation, max } }),
                (true, _, None, None, None) if probability >= cal.threshold => {
                    tubes.push(tube);
                    tube_items.push(item);
                }
                (true, _, _, _, _) => rejected.push(RejectedTube { tube, reason: Rejection::LowProbability { probability, threshold: cal.threshold } }),
                (false, reason, _, _, _) => rejected.push(RejectedTube { tube, reason: Rejection::FitFailed(reason.unwrap_or(FailureReason::Diverged)) }),
            }
        }
        let t2 = Instant::now();
        // Tube-tube consistency: of two located tubes whose solids interpenetrate, the weaker
        // (later: lower probability) is rejected.
        let poses: Vec<TubeAxisPose> = tubes.iter().map(|t| t.pose.clone()).collect();
        let verdict = overlapping_tubes(&self.settings.tube, &poses, self.settings.grasp.tube_overlap_mm * 1e-3);
        let mut kept_index = Vec::with_capacity(tubes.len());
        let (mut kept, mut kept_items, mut overlapping) = (Vec::new(), Vec::new(), Vec::new());
        for ((tube, item), v) in tubes.into_iter().zip(tube_items).zip(&verdict) {
            match v {
                None => {
                    kept_index.push(kept.len());
                    kept.push(tube);
                    kept_items.push(item);
                }
                Some(other) => {
                    kept_index.push(usize::MAX);
                    overlapping.push(RejectedTube { tube, reason: Rejection::IntersectsTube { other: kept_index[*other] } });
                }
            }
        }
        let mut tubes = kept;
        let terrain_checked = self.check_grasps(&mut tubes, &kept_items, &refined, input.ground.as_ref(), &up);
        let grasp_ms = t2.elapsed().as_secs_f64() * 1e3;
        overlapping.extend(rejected);
        let rejected = overlapping;
        let warnings = self.detector.scale_warning(&self.camera().model, input.ground.as_ref()).into_iter().collect();
        Ok(LocateOutput { tubes, rejected, detections, merged, terrain_checked, up_cam: up, highlight_level: highlight, warnings, timings: Timings { detect_s, refine_s, fit_ms: refined.fit_ms, grasp_ms, total_s: t0.elapsed().as_secs_f64() } })
    }

    /// The grasp check of each located tube (seed item `items[k]` of `refined`): the scene is
    /// the tube's ground plane ([`ground_under`] of its local ground in stereo, else of
    /// `ground`), the other located tubes and, in stereo, the terrain from the scene depth
    /// around the tube (relief above its local ground, or `ground`, before lowering). Sets each tube's grasp and grasp frames;
    /// returns whether terrain was available (stereo).
    fn check_grasps(&self, tubes: &mut [LocatedTube], items: &[usize], refined: &crate::frame::FrameRefinement, ground: Option<&GroundPlane>, up: &Vector3<f64>) -> bool {
        let poses: Vec<TubeAxisPose> = tubes.iter().map(|t| t.pose.clone()).collect();
        let radius = self.planner.terrain_radius();
        let checks: Vec<GraspCheck> = poses
            .par_iter()
            .enumerate()
            .map(|(k, pose)| {
                let given = refined.grounds.get(items[k]).copied().flatten().or(ground.copied());
                let checked = ground_under(given, pose, &self.settings.tube, up);
                let others: Vec<TubeAxisPose> = poses.iter().enumerate().filter(|&(j, _)| j != k).map(|(_, p)| p.clone()).collect();
                let terrain = refined.scene_depth.as_ref().map(|depth| {
                    let points = crate::stereo::points_near(depth, &self.camera.model, &pose.centre, radius, 2);
                    let cam = &self.camera.model;
                    // Relief above the tube's (local) ground, not above the lowered plane: the
                    // stereo terrain and that ground are measured by the same matcher.
                    self.planner.terrain(&points, &given.unwrap_or(checked), pose, &poses, pose.centre.z.max(0.0) / cam.fx.min(cam.fy))
                });
                self.planner.check(pose, up, &Scene { ground: checked, tubes: &others, terrain: terrain.as_ref() })
            })
            .collect();
        for (t, check) in tubes.iter_mut().zip(checks) {
            t.t_cam_grasp = check.t_cam_grasp;
            t.t_rig_grasp = self.camera.t_rig_cam * check.t_cam_grasp;
            t.grasp = check;
        }
        refined.scene_depth.is_some()
    }

    /// The input image in grey with what [`Locator::locate`] found in it drawn: each tube's
    /// fitted contour and centre, coloured by its status (located, rejected, fit failed), and
    /// the chosen gripper poses ([`crate::overlay::draw_located`]).
    pub fn overlay_located(&self, image: &DynamicImage, found: &LocateOutput) -> image::RgbImage {
        crate::overlay::draw_located(&FramePixels::of(image, false).gray, &self.refiner, &self.planner, &self.camera.model, found)
    }

    /// The input image in grey with each tube's fitted contour and centre drawn (green:
    /// converged, red: rejected).
    pub fn overlay<'a>(&self, image: &DynamicImage, tubes: impl IntoIterator<Item = &'a TubeAxisPose>) -> image::RgbImage {
        crate::overlay::draw(&FramePixels::of(image, false).gray, &self.refiner, &self.camera.model, tubes)
    }
}

/// [`highlight_level`] of an image as [`Locator::locate`] reads it: its grey levels at its real
/// bit depth.
pub fn frame_highlight_level(image: &image::DynamicImage) -> f64 {
    highlight_level(&crate::frame::grey_levels(image))
}

/// The ignore mask ([`LocateInput::ignore`]) drawn in `image`: a pixel is ignored where any
/// of its colour channels is not zero (alpha is not read), whatever the sample depth.
pub fn ignore_mask_of(image: &DynamicImage) -> Plane<u8> {
    let rgb = image.to_rgb16();
    Plane { width: rgb.width() as usize, height: rgb.height() as usize, data: rgb.pixels().map(|p| u8::from(p.0.iter().any(|&c| c != 0))).collect() }
}

/// The image position (column, row) of `pose`'s centre under `camera` when it falls on a
/// non-zero pixel of `ignore` (nearest pixel), else `None`.
fn ignored_pixel(ignore: Option<&Plane<u8>>, camera: &tubeloc_core::CameraModel, pose: &TubeAxisPose) -> Option<(f64, f64)> {
    let mask = ignore?;
    let p = camera.project(&nalgebra::Point3::from(pose.centre))?;
    let (x, y) = (p.x.round(), p.y.round());
    let inside = x >= 0.0 && y >= 0.0 && (x as usize) < mask.width && (y as usize) < mask.height;
    (inside && mask.data[y as usize * mask.width + x as usize] != 0).then_some((p.x, p.y))
}

/// The grey level of a frame's highlights: the 99th percentile of its 8-bit grey levels. A
/// well-exposed rover frame's lie far up the range (every well-exposed real frame of the shared
/// data at 81 or more, as tubeloc reads it); an underexposed frame's, low, with sensor noise a
/// large part of what is left.
pub fn highlight_level(gray: &tubeloc_core::Plane<u8>) -> f64 {
    let mut hist = [0u64; 256];
    for &v in &gray.data {
        hist[v as usize] += 1;
    }
    let need = ((0.99 * gray.data.len() as f64).ceil() as u64).max(1);
    let mut seen = 0;
    // The least level at or below which 99 % of the pixels lie (0 for an empty image).
    hist.iter()
        .position(|&c| {
            seen += c;
            seen >= need
        })
        .unwrap_or(0) as f64
}

/// The ground plane a tube's grasp is checked against: `given` (camera frame, n up), lowered to
/// the tube's underside where it stands above it (a tube rests on the ground, so a plane above
/// its underside is an error of the pose's height or of the plane; the terrain columns then
/// show any relief around the tube); without a plane, the plane under the tube's underside with
/// normal `up`. The underside is the lowest point of the tube's cylinder of largest radius.
pub fn ground_under(given: Option<GroundPlane>, pose: &TubeAxisPose, model: &tubeloc_core::TubeModel, up: &Vector3<f64>) -> GroundPlane {
    let normal = given.map_or(*up, |g| g.normal);
    let along = pose.axis.dot(&normal).abs().min(1.0);
    let underside = pose.centre - normal * (model.length / 2.0 * along + model.max_radius() * (1.0 - along * along).sqrt());
    match given {
        Some(g) if g.height_of(&underside) >= 0.0 => g,
        _ => GroundPlane::from_point_normal(&underside, &normal),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tubeloc_core::Plane;

    #[test]
    fn the_highlight_level_is_the_99th_percentile_of_the_levels() {
        // Levels 0..=99, 10 pixels each: 99 % of the pixels lie at or below 98.
        let ramp = Plane::from_vec(100, 10, (0..1000).map(|k| (k % 100) as u8).collect());
        assert_eq!(highlight_level(&ramp), 98.0);
        // A dark frame with a few bright outliers (under 1 %) has dark highlights.
        let mut dark = Plane::from_vec(100, 100, vec![20u8; 10_000]);
        dark.data[..90].fill(255);
        assert_eq!(highlight_level(&dark), 20.0);
        assert_eq!(highlight_level(&Plane::from_vec(0, 0, Vec::new())), 0.0);
    }
}
