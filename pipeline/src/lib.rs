//! tubeloc-pipeline: the main job of tubeloc as a library.
//!
//! A [`Locator`] is built from a rig (the camera that took the images, and the stereo pair
//! when a right image is given), a detector ([`TubeDetector`]: the learned segmenter, Line2D
//! template matching, or detections made elsewhere) and [`LocatorSettings`]. It takes images
//! in memory and owns the order of the stages and their policies:
//!
//! detect -> (stereo: rectify, SGM in the detections' regions, triangulate, local ground) ->
//! cylinder fit per detection -> stages after the fit ([`stages::after_fit`]: hidden-end
//! anchoring, photometric / rims / two-view stage, covariance widening over the unseen part
//! of the tube) -> duplicate merging -> tube-tube consistency (of two located tubes whose solids
//! interpenetrate, the weaker is rejected) -> grasps checked for collisions with the ground,
//! the other tubes and, in stereo, the terrain near each tube ([`tubeloc_grasp`]) -> grasp
//! frames.
//!
//! Frames and units: poses are in the (left) camera frame (OpenCV: x right, y down, z
//! forward), metres; grasp frames also in the rig frame; pixel centres at integer coordinates.
//! The ground plane is [`GroundPlane`] (`n · X = d`, `n` up, camera frame).
//!
//! ```
//! use image::{DynamicImage, GrayImage, Luma};
//! use nalgebra::Vector3;
//! use tubeloc_core::{AxisSeed, CameraModel, DetectionSource, Pose, Rig, RigCamera, Rle, TubeAxisPose, TubeDetection};
//! use tubeloc_pipeline::{CameraSelection, ExternalDetections, LocateInput, Locator, LocatorSettings};
//! use tubeloc_refine::{silhouette::silhouette_mask, CylinderModel};
//!
//! // A 320x240 camera and a tube lying 0.6 m in front of it, across the view.
//! let camera = CameraModel::from_hfov(320, 240, 60.0);
//! let truth = TubeAxisPose::new(0, 1.0, Vector3::new(0.0, 0.0, 0.6), Vector3::new(1.0, 0.0, 0.1), 0.5).unwrap();
//! let settings = LocatorSettings::default();
//! let model = CylinderModel::new(&settings.tube).unwrap();
//! let mask = silhouette_mask(&model, &truth, &camera);
//! // The image: a bright tube on a darker, gently shaded ground.
//! let image = DynamicImage::ImageLuma8(GrayImage::from_fn(320, 240, |x, y| {
//!     Luma([if mask.get(x as usize, y as usize) { 210 } else { 60 + ((x + 2 * y) % 23) as u8 }])
//! }));
//! // A segmenter's detection: the mask with its principal axis.
//! let mut det = TubeDetection::new(0, 0.9, mask.bbox(), DetectionSource::External);
//! det.mask = Some(Rle::from_mask(&mask));
//! det.axis_seed = det.axis_seed_from_mask().unwrap();
//!
//! let rig = Rig { cameras: vec![RigCamera { name: "cam".into(), model: camera, t_rig_cam: Pose::identity() }], stereo_pairs: vec![] };
//! let detector = Box::new(ExternalDetections::new(vec![det], "example"));
//! let locator = Locator::new(&rig, &CameraSelection::default(), detector, settings).unwrap();
//! let out = locator.locate(&LocateInput::mono(&image)).unwrap();
//! assert_eq!(out.tubes.len(), 1);
//! let tube = &out.tubes[0];
//! // The axis is found to within a few degrees and the centre to a few centimetres (mono).
//! assert!(tube.pose.axis.dot(&truth.axis).abs() > 0.99);
//! assert!((tube.pose.centre - truth.centre).norm() < 0.05);
//! println!("tube at {:?}, grasp {:?}", tube.pose.centre, tube.t_cam_grasp.translation());
//! ```
//!
//! Extension points: [`LocatorSettings`] and [`LocateOutput`] take new fields (a working scale
//! for detection on large or small images, a per-tube probability of being a tube with an
//! acceptance threshold); [`Rejection`] takes new reasons.
#![warn(missing_docs)]

pub mod detector;
pub mod error;
pub mod frame;
pub mod locator;
pub mod overlay;
pub mod pose_verifier;
pub mod settings;
pub mod shipped;
pub mod stages;
pub mod stereo;

pub use detector::{ExternalDetections, FusedDetection, FusedTubeDetector, LearnedDetector, Line2dTubeDetector, TubeDetector};
pub use error::PipelineError;
pub use frame::{refine_frame, Frame, FrameOptions, FrameRefinement, SeedItem, StereoView};
pub use locator::{frame_highlight_level, highlight_level, ignore_mask_of, CameraSelection, LocateInput, LocateOutput, LocatedTube, Locator, RejectedTube, Rejection, Timings, MAX_IMAGE_PIXELS};
pub use settings::{load_settings_file, LocatorSettings, StageSettings};
pub use shipped::shipped_calibration;
pub use tubeloc_core::GroundPlane;
