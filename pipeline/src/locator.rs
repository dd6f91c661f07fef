//! [`Locator`]: the main job on in-memory images.

use crate::detector::{check_mask_sizes, TubeDetector};
use crate::error::{PipelineError, Result};
use crate::frame::{refine_pixels, Frame, FrameOptions, FramePixels, SeedItem, StereoView};
use crate::settings::LocatorSettings;
use image::DynamicImage;
use nalgebra::Vector3;
use serde::Serialize;
use std::time::Instant;
use tubeloc_core::{FailureReason, Pose, Rig, RigCamera, TubeAxisPose, TubeDetection};
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
}

impl<'a> LocateInput<'a> {
    /// A mono input with nothing else known.
    pub fn mono(image: &'a DynamicImage) -> Self {
        LocateInput { image, right: None, ground: None, up: None }
    }
}

/// One located tube: the refined pose and its grasp frames.
#[derive(Clone, Debug, Serialize)]
pub struct LocatedTube {
    /// The refined pose (camera frame, metres), flattened into this object in JSON.
    #[serde(flatten)]
    pub pose: TubeAxisPose,
    /// Grasp frame in the camera frame: origin at the tube centre, +x along the axis, +z the
    /// approach (from above, against up), +y the direction the fingers close.
    #[serde(rename = "T_cam_grasp")]
    pub t_cam_grasp: Pose,
    /// The grasp frame in the rig frame (`T_rig_cam · T_cam_grasp`).
    #[serde(rename = "T_rig_grasp")]
    pub t_rig_grasp: Pose,
    /// Probability that this is a tube: the detector's score through the score calibration
    /// ([`LocatorSettings::calibration`]), fitted on real validation composites.
    pub probability: f64,
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
}

impl Rejection {
    /// A short machine-readable name (`fit_failed`, `low_probability`).
    pub fn name(&self) -> &'static str {
        match self {
            Rejection::FitFailed(_) => "fit_failed",
            Rejection::LowProbability { .. } => "low_probability",
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
    /// Unit up direction used for the grasp frames, camera frame.
    pub up_cam: Vector3<f64>,
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
/// grasp frames, for images of one rig camera (or stereo pair).
pub struct Locator {
    rig: Rig,
    camera: RigCamera,
    pair: Option<(String, String)>,
    detector: Box<dyn TubeDetector>,
    refiner: Refiner,
    settings: LocatorSettings,
}

/// Most pixels of an image the locator takes (100 megapixels, e.g. 10000 x 10000). Peak
/// memory is about 200 MB plus 12 bytes per pixel (the decoded image, its grey levels and
/// the refiner's float copy at full resolution; the detector runs at its working scale in
/// bands of bounded size): ~290 MB at 5472 x 3648, ~1.4 GB at this bound.
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
        let refiner = Refiner::new(&settings.tube, settings.refine.clone())?;
        Ok(Locator { rig: rig.clone(), camera, pair, detector, refiner, settings })
    }

    /// The rig camera the (left) images come from.
    pub fn camera(&self) -> &RigCamera {
        &self.camera
    }

    /// The refiner (tube model and configuration).
    pub fn refiner(&self) -> &Refiner {
        &self.refiner
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
    /// tube, grasp frames.
    pub fn locate(&self, input: &LocateInput) -> Result<LocateOutput> {
        let t0 = Instant::now();
        let up = Self::up_direction(input)?;
        let detections = self.detect(input.image, input.ground.as_ref())?;
        let px = FramePixels::of(input.image, self.settings.colour_ends);
        let detect_s = t0.elapsed().as_secs_f64();
        let t1 = Instant::now();
        // Each detection is refined in the form it has in a detections file, so that `locate`
        // and `detect` + `refine` give the same poses.
        let seeds: Vec<TubeDetection> = detections.iter().cloned().map(crate::detector::canonical).collect();
        let refined = self.refine_items(input, &px, &seeds)?;
        let refine_s = t1.elapsed().as_secs_f64();
        let mut poses = refined.poses;
        poses.sort_by(|x, y| y.converged.cmp(&x.converged).then(y.score.total_cmp(&x.score)));
        let merged = if self.settings.merge_duplicates { tubeloc_refine::duplicates::merge_duplicates(&mut poses, &self.settings.tube) } else { 0 };
        let (mut tubes, mut rejected) = (Vec::new(), Vec::new());
        let cal = &self.settings.calibration;
        for pose in poses {
            let t_cam_grasp = pose.grasp_frame(&up);
            let failure = pose.failure.as_ref().map(|f| f.reason);
            let probability = cal.probability(pose.score);
            let tube = LocatedTube { t_rig_grasp: self.camera.t_rig_cam * t_cam_grasp, t_cam_grasp, pose, probability };
            match (tube.pose.converged, failure) {
                (true, _) if probability >= cal.threshold => tubes.push(tube),
                (true, _) => rejected.push(RejectedTube { tube, reason: Rejection::LowProbability { probability, threshold: cal.threshold } }),
                (false, reason) => rejected.push(RejectedTube { tube, reason: Rejection::FitFailed(reason.unwrap_or(FailureReason::Diverged)) }),
            }
        }
        Ok(LocateOutput { tubes, rejected, detections, merged, up_cam: up, timings: Timings { detect_s, refine_s, fit_ms: refined.fit_ms, total_s: t0.elapsed().as_secs_f64() } })
    }

    /// The input image in grey with each tube's fitted contour and centre drawn (green:
    /// converged, red: rejected).
    pub fn overlay<'a>(&self, image: &DynamicImage, tubes: impl IntoIterator<Item = &'a TubeAxisPose>) -> image::RgbImage {
        crate::overlay::draw(&FramePixels::of(image, false).gray, &self.refiner, &self.camera.model, tubes)
    }
}
