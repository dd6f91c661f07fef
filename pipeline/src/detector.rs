//! Detectors a [`crate::Locator`] is built with: the learned segmenter, Line2D template
//! matching, the two fused, or detections made elsewhere. Each turns one in-memory image into
//! [`TubeDetection`]s (seeds for the refiner) in the image's pixel frame.

use crate::error::{PipelineError, Result};
use crate::pose_verifier::{PoseVerification, PoseVerifier};
use image::DynamicImage;
use rayon::prelude::*;
use std::collections::BTreeMap;
use tubeloc_core::GroundPlane;
use tubeloc_core::{AxisSeed, CameraModel, CocoResult, DetectionSource, Pose, PoseEvidence, Rle, Segmentation, TubeDetection};
use tubeloc_detect::learned::{detect_rgb_at_scale, DecodeConfig, LearnedModel};
use tubeloc_detect::line2d::Line2dDetector;
use tubeloc_detect::scale::RangeBand;

/// A tube detector: one image (with the camera that took it) in, detections out.
pub trait TubeDetector: Send + Sync {
    /// Short name of the detector (`learned`, `line2d`, `external`), as reported in outputs.
    fn name(&self) -> &str;
    /// Detections in `image` (taken by `camera`, whose size it has), with COCO image id
    /// `image_id`. Boxes, masks and axis seeds are in the image's pixels (pixel centres at
    /// integer coordinates); template poses in `camera`'s frame, metres. `ground` (camera
    /// frame), when known, sets the working scale of detectors built for one pixel scale.
    fn detect(&self, image: &DynamicImage, camera: &CameraModel, ground: Option<&GroundPlane>, image_id: u64) -> Result<Vec<TubeDetection>>;
    /// Where the detections come from, for error messages (a results file, a model file).
    fn origin(&self) -> String {
        self.name().to_string()
    }
    /// Why this detector will miss most tubes in images of `camera` over `ground` (camera
    /// frame), when it can tell from the geometry alone: e.g. the learned detector's
    /// [`tubeloc_detect::scale::NarrowTubes`]. `None` by default.
    fn scale_warning(&self, _camera: &CameraModel, _ground: Option<&GroundPlane>) -> Option<String> {
        None
    }
}

/// A shared detector (one model or template library for several locators, e.g. one per
/// frame's camera) is a detector.
impl<T: TubeDetector + ?Sized> TubeDetector for std::sync::Arc<T> {
    fn name(&self) -> &str {
        (**self).name()
    }

    fn detect(&self, image: &DynamicImage, camera: &CameraModel, ground: Option<&GroundPlane>, image_id: u64) -> Result<Vec<TubeDetection>> {
        (**self).detect(image, camera, ground, image_id)
    }

    fn origin(&self) -> String {
        (**self).origin()
    }

    fn scale_warning(&self, camera: &CameraModel, ground: Option<&GroundPlane>) -> Option<String> {
        (**self).scale_warning(camera, ground)
    }
}

/// The learned instance segmenter (masks and image axis seeds), run at its working scale
/// ([`tubeloc_detect::scale`]): the image is resampled so that tubes in the range band (or on
/// the ground plane) are about 16 px wide, and results are mapped back.
pub struct LearnedDetector {
    model: LearnedModel,
    decode: DecodeConfig,
    origin: String,
    /// Distances of the tubes from the camera for the working scale; `None`: the image as it is.
    pub range: Option<RangeBand>,
}

impl LearnedDetector {
    /// A detector with a loaded model and decoder settings; `origin` names the model (e.g. its
    /// file) in error messages.
    pub fn new(model: LearnedModel, decode: DecodeConfig, origin: impl Into<String>) -> Self {
        LearnedDetector { model, decode, origin: origin.into(), range: Some(RangeBand::default()) }
    }

    /// Loads the weights at `path` (safetensors, `tubeloc train`'s format).
    pub fn load(path: &std::path::Path, decode: DecodeConfig) -> Result<Self> {
        let model = LearnedModel::load(path).map_err(|e| PipelineError::Detect(format!("loading model {}: {e}", path.display())))?;
        Ok(Self::new(model, decode, path.display().to_string()))
    }
}

impl TubeDetector for LearnedDetector {
    fn name(&self) -> &str {
        "learned"
    }

    fn origin(&self) -> String {
        self.origin.clone()
    }

    fn scale_warning(&self, camera: &CameraModel, ground: Option<&GroundPlane>) -> Option<String> {
        tubeloc_detect::scale::NarrowTubes::of(camera, ground.map(|g| (g.normal, g.offset)), self.range?).map(|n| n.to_string())
    }

    fn detect(&self, image: &DynamicImage, camera: &CameraModel, ground: Option<&GroundPlane>, image_id: u64) -> Result<Vec<TubeDetection>> {
        // An RGB8 image is read in place; other formats go through the shared conversion.
        let rgb = tubeloc_detect::input::rgb8_pixels(image);
        let (w, h) = (image.width() as usize, image.height() as usize);
        let s = match self.range {
            Some(band) => tubeloc_detect::scale::working_scale(camera, ground.map(|g| (g.normal, g.offset)), band),
            None => 1.0,
        };
        let inst = detect_rgb_at_scale(&self.model, &rgb, w, h, s, &self.decode).map_err(|e| PipelineError::Detect(format!("{}: {e}", self.origin)))?;
        Ok(inst
            .into_par_iter()
            .map(|i| {
                let mut det = TubeDetection::new(image_id, i.score, i.bbox, DetectionSource::Learned);
                det.axis_seed = Some(i.axis);
                det.mask = Some(i.mask);
                det
            })
            .collect())
    }
}

/// Line2D template matching with a library built for the camera (coarse template poses);
/// with the ground known, matches inconsistent with a tube lying on it are dropped
/// ([`tubeloc_detect::line2d::ground`]). With a [`PoseVerification`] (the default of
/// [`crate::shipped::line2d_detector`]), the candidates are verified by their refined poses
/// ([`crate::pose_verifier`]) where the ground is known.
pub struct Line2dTubeDetector {
    detector: Line2dDetector,
    verification: Option<PoseVerification>,
}

impl Line2dTubeDetector {
    /// A detector around a Line2D detector (library and matching parameters), its candidates
    /// kept at its clutter verifier's cut.
    pub fn new(detector: Line2dDetector) -> Self {
        Line2dTubeDetector { detector, verification: None }
    }

    /// A detector whose candidates are verified by their poses: `detector`'s clutter verifier
    /// is run at the floor [`crate::pose_verifier::CLUTTER_FLOOR`], and its own cuts apply
    /// where no pose can be refined (no ground plane).
    pub fn verified(mut detector: Line2dDetector, verifier: PoseVerifier) -> Result<Self> {
        let verification = PoseVerification::for_matcher(&mut detector, verifier, crate::pose_verifier::CLUTTER_FLOOR)?;
        Ok(Line2dTubeDetector { detector, verification: Some(verification) })
    }
}

impl TubeDetector for Line2dTubeDetector {
    fn name(&self) -> &str {
        "line2d"
    }

    fn detect(&self, image: &DynamicImage, camera: &CameraModel, ground: Option<&GroundPlane>, image_id: u64) -> Result<Vec<TubeDetection>> {
        let dets = match &self.verification {
            Some(v) => v.detect(&self.detector, image, Some(camera), ground, image_id)?.0,
            None => {
                // An RGB8 image is read in place; other formats go through the shared conversion.
                let rgb = tubeloc_detect::input::rgb8_pixels(image);
                let (w, h) = (image.width() as usize, image.height() as usize);
                self.detector.detect_on_ground(&rgb, w, h, Some(camera), ground).map_err(|e| PipelineError::Detect(e.to_string()))?
            }
        };
        Ok(dets.iter().map(|d| d.to_tube_detection(image_id)).collect())
    }
}

/// Fused detection (record 0069): the learned segmenter's detections and Line2D's
/// pose-verified ones in one list, each scored by the probability that its refined pose is a
/// tube. Each learned detection is refined on the frame's ground, its mask snapped to the pose
/// and scored by the learned model's [`PoseEvidence`]; Line2D's candidates are verified as
/// [`Line2dTubeDetector::verified`] keeps them. Most probable first, a detection whose mask
/// overlaps a kept one at IoU above [`FusedTubeDetector::NMS_IOU`] is dropped.
pub struct FusedTubeDetector {
    learned: LearnedDetector,
    line2d: Line2dDetector,
    verification: PoseVerification,
    learned_evidence: PoseVerifier,
}

/// One fused detection: the detection, and its Line2D record when Line2D found it.
#[derive(Clone, Debug)]
pub struct FusedDetection {
    /// The detection (snapped mask, the pose evidence as its score).
    pub detection: TubeDetection,
    /// Line2D's record (template, clutter probability, `pose_probability`), when it is Line2D's.
    pub line2d: Option<tubeloc_detect::line2d::Line2dDetection>,
}

impl FusedTubeDetector {
    /// Mask IoU above which the less probable of two detections is dropped.
    pub const NMS_IOU: f64 = 0.5;

    /// The learned detector with its model's pose evidence `learned_evidence`, and the Line2D
    /// matcher `line2d` (with its clutter verifier) verified by `line2d_verifier`.
    pub fn new(learned: LearnedDetector, learned_evidence: PoseEvidence, mut line2d: Line2dDetector, line2d_verifier: PoseVerifier) -> Result<Self> {
        let verification = PoseVerification::for_matcher(&mut line2d, line2d_verifier, crate::pose_verifier::CLUTTER_FLOOR)?;
        let learned_evidence = PoseVerifier { evidence: learned_evidence, threshold: 0.0, threshold_grey: 0.0, nms_iou: 1.0, max_limb_continuation: None, fitted_on: String::new() };
        Ok(FusedTubeDetector { learned, line2d, verification, learned_evidence })
    }

    /// The Line2D matcher (library and matching parameters).
    pub fn line2d(&self) -> &Line2dDetector {
        &self.line2d
    }

    /// The fused detections of `image` (of `camera`, on `ground` when known), most probable
    /// first. Without a ground, the learned detections are refined without one and Line2D's
    /// candidates are kept at the clutter verifier's cut with its probability as their score.
    pub fn detect_fused(&self, image: &DynamicImage, camera: &CameraModel, ground: Option<&GroundPlane>, image_id: u64) -> Result<Vec<FusedDetection>> {
        let (line2d, _) = self.line2d_verified(image, Some(camera), ground, image_id)?;
        self.fuse(image, camera, ground, image_id, line2d)
    }

    /// Line2D's candidates of `image` verified by their poses as the fused list takes them
    /// ([`PoseVerification::detect`] with this detector's matcher and verifier), and whether
    /// poses verified them (a camera of the image's size and a ground).
    pub fn line2d_verified(&self, image: &DynamicImage, camera: Option<&CameraModel>, ground: Option<&GroundPlane>, image_id: u64) -> Result<(Vec<tubeloc_detect::line2d::Line2dDetection>, bool)> {
        self.verification.detect(&self.line2d, image, camera, ground, image_id)
    }

    /// [`Self::detect_fused`] with Line2D's verified detections of the image given: `line2d`
    /// is what [`Self::line2d_verified`] returns for `image` with `Some(camera)` and `ground`
    /// (e.g. kept from a Line2D run on the same image), so that Line2D is not matched twice.
    pub fn fuse(&self, image: &DynamicImage, camera: &CameraModel, ground: Option<&GroundPlane>, image_id: u64, line2d: Vec<tubeloc_detect::line2d::Line2dDetection>) -> Result<Vec<FusedDetection>> {
        let learned = self.learned.detect(image, camera, ground, image_id)?;
        let grey = tubeloc_detect::input::is_grey_rgb8(&tubeloc_detect::input::rgb8_pixels(image));
        let mut all: Vec<FusedDetection> = Vec::new();
        if !learned.is_empty() {
            let frame = crate::frame::Frame { image, camera, image_id, ground: ground.copied(), stereo: None };
            let (refiner, settings) = self.verification.refinement();
            let verdicts = self.learned_evidence.verify(refiner, settings, &frame, &learned, grey)?;
            all.extend(verdicts.into_iter().map(|v| FusedDetection { detection: v.detection, line2d: None }));
        }
        all.extend(line2d.into_iter().map(|d| FusedDetection { detection: d.to_tube_detection(image_id), line2d: Some(d) }));
        all.sort_by(|a, b| b.detection.score.total_cmp(&a.detection.score));
        let keep = tubeloc_core::keep_by_iou(&all.iter().map(|d| d.detection.mask.as_ref()).collect::<Vec<_>>(), Self::NMS_IOU);
        Ok(all.into_iter().zip(keep).filter_map(|(d, k)| k.then_some(d)).collect())
    }
}

impl TubeDetector for FusedTubeDetector {
    fn name(&self) -> &str {
        "fused"
    }

    fn scale_warning(&self, camera: &CameraModel, ground: Option<&GroundPlane>) -> Option<String> {
        self.learned.scale_warning(camera, ground)
    }

    fn detect(&self, image: &DynamicImage, camera: &CameraModel, ground: Option<&GroundPlane>, image_id: u64) -> Result<Vec<TubeDetection>> {
        Ok(self.detect_fused(image, camera, ground, image_id)?.into_iter().map(|d| d.detection).collect())
    }
}

/// A detection in the form it has after a round trip through a detections file: the template
/// pose's rotation is taken through its 3x3 matrix, as [`Pose`]'s JSON form stores it, so that
/// refining in-memory detections and refining `tubeloc detect`'s file give the same poses to
/// the bit.
pub fn canonical(mut det: TubeDetection) -> TubeDetection {
    if let Some(t) = det.t_cam_tube {
        if let Ok(p) = Pose::try_from_matrix(&t.rotation(), t.translation()) {
            det.t_cam_tube = Some(p);
        }
    }
    det
}

/// Detections made elsewhere (a COCO results file from another detector, or a detections
/// file), handed to the pipeline as they are.
pub struct ExternalDetections {
    detections: Vec<TubeDetection>,
    origin: String,
}

impl ExternalDetections {
    /// Detections for the image(s) the locator will see; `origin` names their file in error
    /// messages.
    pub fn new(detections: Vec<TubeDetection>, origin: impl Into<String>) -> Self {
        ExternalDetections { detections, origin: origin.into() }
    }

    /// The detections.
    pub fn detections(&self) -> &[TubeDetection] {
        &self.detections
    }
}

impl TubeDetector for ExternalDetections {
    fn name(&self) -> &str {
        "external"
    }

    fn origin(&self) -> String {
        self.origin.clone()
    }

    /// The stored detections, whatever their image id (`image_id` is not applied).
    fn detect(&self, _image: &DynamicImage, _camera: &CameraModel, _ground: Option<&GroundPlane>, _image_id: u64) -> Result<Vec<TubeDetection>> {
        Ok(self.detections.clone())
    }
}

/// A plain COCO results entry as a detection: the mask's principal axis becomes the axis seed
/// (the box diagonal when there is no mask). Polygon masks need the image size `(width,
/// height)`. `context` names the entry in errors.
pub fn detection_from_coco_result(r: &CocoResult, size: Option<(u32, u32)>, context: &str) -> Result<TubeDetection> {
    let bad = |m: String| PipelineError::Input(format!("{context}: {m}"));
    let mask = match &r.segmentation {
        None => None,
        Some(seg) => {
            let (h, w) = match seg {
                Segmentation::CompressedRle { size, .. } | Segmentation::UncompressedRle { size, .. } => (size[0], size[1]),
                Segmentation::Polygons(_) => size.map(|(w, h)| (h, w)).ok_or_else(|| bad("polygon mask needs the image size (--image or --dataset)".into()))?,
            };
            Some(seg.to_rle(h, w).and_then(|x| x.to_mask()).map_err(|e| bad(e.to_string()))?)
        }
    };
    let bbox = match (r.bbox, &mask) {
        (Some(b), _) => b,
        (None, Some(m)) => m.bbox(),
        (None, None) => return Err(bad("neither bbox nor segmentation".into())),
    };
    let mut det = TubeDetection::new(r.image_id, r.score, bbox, DetectionSource::External);
    det.category_id = r.category_id;
    det.axis_seed = Some(match &mask {
        Some(m) => {
            let px = m.data.iter().enumerate().filter(|(_, &v)| v != 0).map(|(i, _)| ((i % m.width) as f64, (i / m.width) as f64));
            AxisSeed::from_pixels(px).unwrap_or_else(|| det.axis_seed_from_bbox())
        }
        None => det.axis_seed_from_bbox(),
    });
    det.mask = mask.as_ref().map(Rle::from_mask);
    det.validate().map_err(|e| bad(e.to_string()))?;
    Ok(det)
}

/// The entries of a COCO results list that belong to the image named `image_name` (a file
/// name; only its last path component counts):
/// - entries that carry a `file_name` field are matched by it;
/// - otherwise, with `names` (image id to file name, e.g. a COCO dataset's `images[]`), the
///   entries whose image id names this file;
/// - otherwise, all entries when they hold a single image id.
///
/// Fails when nothing matches, or when the entries hold several images and cannot be told
/// apart. `origin` names the results in errors.
pub fn select_results_for_image(results: Vec<CocoResult>, image_name: &str, names: Option<&BTreeMap<u64, String>>, origin: &str) -> Result<Vec<CocoResult>> {
    let base = |s: &str| std::path::Path::new(s).file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or_else(|| s.to_string());
    let want = base(image_name);
    let ids: std::collections::BTreeSet<u64> = results.iter().map(|r| r.image_id).collect();
    let named = |r: &CocoResult| r.extra.get("file_name").and_then(|v| v.as_str()).map(base);
    if results.iter().any(|r| named(r).is_some()) {
        let kept: Vec<CocoResult> = results.into_iter().filter(|r| named(r).as_deref() == Some(want.as_str())).collect();
        if kept.is_empty() {
            return Err(PipelineError::Input(format!("{origin}: no entry has file_name {want:?}")));
        }
        return Ok(kept);
    }
    if let Some(names) = names {
        let mine: std::collections::BTreeSet<u64> = names.iter().filter(|(_, n)| base(n) == want).map(|(id, _)| *id).collect();
        if mine.is_empty() {
            return Err(PipelineError::Input(format!("{origin}: no image named {want:?} in the image list")));
        }
        let kept: Vec<CocoResult> = results.into_iter().filter(|r| mine.contains(&r.image_id)).collect();
        if kept.is_empty() && ids.len() > 1 {
            return Err(PipelineError::Input(format!("{origin}: no entry for image {want:?} (image ids {mine:?})")));
        }
        return Ok(kept);
    }
    if ids.len() > 1 {
        let shown: Vec<String> = ids.iter().take(8).map(u64::to_string).collect();
        return Err(PipelineError::Input(format!(
            "{origin}: the results hold detections for {} images (image ids {}{}); select {want:?}'s: give each entry a \"file_name\", or pass the image list (--results-images annotations.json)",
            ids.len(),
            shown.join(", "),
            if ids.len() > 8 { ", ..." } else { "" }
        )));
    }
    Ok(results)
}

/// Checks that every detection's mask has the image's size (`width x height` pixels).
/// `origin` names the detections in the error, which also gives the detection's index.
pub fn check_mask_sizes(dets: &[TubeDetection], width: u32, height: u32, origin: &str) -> Result<()> {
    for (k, d) in dets.iter().enumerate() {
        if let Some(m) = &d.mask {
            if m.size != [height, width] {
                return Err(PipelineError::Input(format!("{origin}: detection {k} (image {}): its mask is {}x{} but the image is {width}x{height}", d.image_id, m.size[1], m.size[0])));
            }
        }
    }
    Ok(())
}
