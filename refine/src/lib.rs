//! tubeloc-refine: edge-based 6D pose refinement of sample tubes with a cylinder model.
//!
//! A detection ([`TubeDetection`]: Line2D template pose, learned mask axis, or box) seeds a
//! robust Levenberg-Marquardt fit of the tube's projected occluding contour
//! ([`contour`]) to image edges ([`edges`]), coarse to fine over an image pyramid, with an
//! optional stereo term ([`fit::Scene`]). The fitted parameters are the centre and the axis
//! direction (rotation about the axis is not observable and not optimized). Which end is the
//! seal end is decided afterwards by fitting both end hypotheses and comparing their edge
//! support ([`Refiner::refine`]). The output is a [`TubeAxisPose`] with a flip-free axis,
//! covariance, residual statistics and a failure reason instead of NaN when the fit fails.
#![warn(missing_docs)]

pub mod contour;
pub mod duplicates;
pub mod edges;
pub mod error;
pub mod fit;
pub mod hidden_end;
pub mod jacobian;
pub mod local_ground;
pub mod model;
mod mono;
pub mod photo;
pub mod priors;
pub mod rims;
pub mod robust;
pub mod seal_end;
pub mod search;
pub mod seed;
pub mod seed_policy;
pub mod silhouette;
pub mod stereo_stage;
pub mod two_view;

pub use contour::AxisState;
pub use error::RefineError;
pub use fit::{FitResult, Scene};
pub use model::CylinderModel;
pub use seed::{seed_from_detection, GroundPlane, Seed};
pub use seed_policy::{SeedKind, SeedSettings};

use nalgebra::{Point2, Point3, Vector3};
use seal_end::ColourImage;
use serde::{Deserialize, Serialize};
use tubeloc_core::{BinaryMask, CameraModel, FailureReason, Plane, TubeAxisPose, TubeDetection, TubeModel};

/// Tuning of the refiner. Pixel values are in pixels of the level they apply to unless noted.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct RefineConfig {
    /// Half length of the 1D edge search along contour normals at the coarsest level.
    pub search_radius_px: usize,
    /// Half length of the edge search at the finer levels (at most `search_radius_px`).
    pub fine_search_radius_px: usize,
    /// When the coarsest level is full resolution (narrow tubes), run it once more with the fine
    /// search radius, in mono fits (no stereo points and no depth map; not in the stereo edge
    /// polish, so stereo refinements are unaffected). On by default: chosen on
    /// three generated validation sets (seed-21 and seed-33 no-tags halves, val9; learned seeds
    /// from the with-tags cross-split model, mono + `--ground auto`), mono axis p90 1.09 / 1.36 /
    /// 1.17 -> 1.05 / 1.36 / 1.02 deg, and on the seed-21 set from exact-pose seeds 2.80 ->
    /// 2.43 deg, perpendicular p90 1.23 -> 1.09 mm (`docs/design/0018-fine-polish-in-mono.md`).
    /// Before narrow tubes were fitted on unsmoothed gradients it took the exact-seed
    /// perpendicular p90 on a paper-preset subset from 2.8 to 6.2 mm.
    pub fine_polish: bool,
    /// Smooth the full-resolution level before differentiating for the fit even for narrow
    /// tubes (those fitted at full resolution alone; wider ones always are smoothed, as are the
    /// coarser levels; a fit's acceptance and statistics use the smoothed level).
    /// Off by default: on a paper-preset subset the unsmoothed gradients took the exact-seed
    /// mono axis error from 0.55 to 0.31 degrees (median) and 10 mm / 5 degree seeds' from
    /// 3.87 / 5.22 to 3.67 / 5.01 degrees (median / p90), the smoothing having merged the
    /// shading ramp inside a limb with its step.
    pub blur_full_resolution: bool,
    /// Spacing of contour samples along the projected contour.
    pub sample_spacing_px: f64,
    /// Most contour samples per level: the spacing is widened beyond `sample_spacing_px` for
    /// large tubes so that the cost per iteration stays bounded.
    pub max_samples: usize,
    /// Minimum `|∇I · n|` (intensity per pixel, images in [0, 1]) for an edge.
    pub min_gradient: f32,
    /// Edge hypotheses weaker than this fraction of the strongest along a normal are dropped.
    pub rel_edge_strength: f32,
    /// Most image motion of any contour sample in one step, level pixels (trust region).
    pub max_step_px: f64,
    /// Re-run the edge search when the contour has moved more than this since the last search
    /// (level pixels).
    pub reassociate_px: f64,
    /// A level has converged when a step moves no contour sample more than this (level pixels)
    /// right after a fresh edge search.
    pub converged_px: f64,
    /// Outer iterations at the coarsest level (half of it at the finer levels).
    pub max_iterations: usize,
    /// Coarsest level is chosen so the body is at least this wide (pixels).
    pub min_body_width_px: f64,
    /// Align the seed's contour at the coarsest level over image translations and axis
    /// rotations before the fit ([`search`]), widening the basin to ~10 mm / 5 degrees.
    pub seed_search: bool,
    /// Half width of the seed search's translation grid, pixels of the coarsest level.
    pub seed_search_radius_px: usize,
    /// Largest axis rotation tried by the seed search, degrees.
    pub seed_search_rotation_deg: f64,
    /// Most fits tried (seed-search hypotheses and the seed) until one succeeds.
    pub max_hypotheses: usize,
    /// With stereo points: after the fit, re-place the tube in the image from the edges alone
    /// with its distance and tilt kept (the mono keep-depth mode of [`fit`], forced).
    pub stereo_edge_polish: bool,
    /// Weight of the limb residuals of the sections other than the body (foot flange, seal
    /// section) relative to the body's. Their limb edges are biased by shading (0.5 px inside
    /// at the median, single tubes 3 px, against 0.25 px for the body on the paper preset) and
    /// turned the fitted axis in the image by ~1 degree at the median from exact poses.
    pub end_limb_weight: f64,
    /// The fit from the seed itself beats the best search hypothesis' fit unless that one's
    /// score ([`FitResult::score`]) is lower by more than this.
    pub seed_score_margin: f64,
    /// Most pyramid levels.
    pub max_levels: usize,
    /// Nominal edge localization noise, full-resolution pixels (residual normalization).
    pub edge_sigma_px: f64,
    /// Nominal stereo point noise, metres.
    pub stereo_sigma_m: f64,
    /// Stereo points per independent measurement, for the output covariance only: SGM
    /// disparities of neighbouring pixels are correlated (census window, path aggregation), so
    /// the stereo rows' information is divided by this count when the covariance is computed
    /// (the fit itself weighs every point). 1 treats every point as independent; the default
    /// 63 is the area of the default SGM census window (9 x 7 px), within which two pixels'
    /// matching costs share most of their census bits. Checked on a calibration stereo set
    /// (`tubeloc synth stereo --seed 11`, not the benchmark's seed 3): stereo + ground median
    /// axis error / σ 1.61 -> 0.64, centre 3.02 -> 1.19
    /// (`docs/design/0024-stereo-covariance-census-window.md`).
    pub stereo_points_per_measurement: f64,
    /// A sample is an inlier when its edge lies within this many full-resolution pixels.
    pub inlier_px: f64,
    /// Fits with a smaller inlier fraction are rejected as `empty_terrain`.
    pub min_inlier_fraction: f64,
    /// Fits whose visible contour lies less than this fraction inside the image (tube cut by
    /// the border) are flagged `out_of_image`.
    pub min_in_image_fraction: f64,
    /// Fewer visible (or matched) samples than this fail the fit.
    pub min_samples: usize,
    /// A fit moving the centre by more than this fraction of the seed distance diverged.
    pub max_centre_shift_frac: f64,
    /// A fit turning the axis by more than this (degrees, undirected) diverged.
    pub max_axis_change_deg: f64,
    /// Decide which end is the seal end by fitting both hypotheses.
    pub decide_end: bool,
    /// When the seed claims which end is the seal end (`Seed::end_known`), the image must favour
    /// the other end with at least this confidence to flip it.
    pub end_override_confidence: f64,
    /// Score difference (mean truncated cost) that gives `end_confidence` ≈ 0.73 (logistic scale).
    pub end_score_scale: f64,
    /// Fix each limb's edge polarity (tube brighter/darker than the ground) after the first
    /// iteration of each level.
    pub limb_polarity: bool,
    /// Once a limb's polarity is fixed, associate each of its samples with the outermost edge of
    /// that polarity only (shading boundaries inside the tube share the polarity).
    pub outermost_limb_edge: bool,
    /// Ground prior: standard deviation of the centre height above the ground (expected
    /// height: the largest radius), metres.
    pub ground_sigma_m: f64,
    /// The tube rests on the given ground plane itself (centre `max_radius` above it). False
    /// when only the plane's orientation is trusted (e.g. the world's z = 0 of a tripod pose over
    /// terrain with relief): then only the tilt prior is used and seeds keep their height.
    pub ground_height_known: bool,
    /// Prior on the centre's distance from the camera: standard deviation as a fraction of the
    /// seed's distance; 0 disables it.
    pub seed_distance_sigma_frac: f64,
    /// Ground prior: standard deviation of the axis elevation above the ground plane, degrees.
    pub ground_tilt_sigma_deg: f64,
    /// Mono (no stereo points, no mask): keep the seed's distance along the centre's viewing
    /// ray and fit only what one image determines well: the centre across the ray, the axis
    /// turn about the ray, and (with a ground plane) the axis tilt toward the camera. The
    /// distance from the limbs' separation is ill-conditioned (0.1 px of width on a 12 px wide
    /// tube is ~1% of the distance) and biased by shading at the limbs; see [`fit`].
    /// Applied only to tubes narrow enough that the width fixes the distance worse than the
    /// seed: `mono_width_sigma_px / body_width_px > mono_depth_sigma_frac`.
    pub mono_keep_depth: bool,
    /// Systematic uncertainty of a mono limb-to-limb width, full-resolution pixels (shading at
    /// the limbs biases edges by 0.25 px at the median on the paper preset).
    pub mono_width_sigma_px: f64,
    /// Mono with a ground plane: uncertainty of the seed's distance as a fraction of it, which
    /// weighs the seed distance against the ground height when the centre is finally moved
    /// along its ray ([`fit`]).
    pub mono_depth_sigma_frac: f64,
    /// [`Refiner::refine`] (detector seeds): `mono_depth_sigma_frac` used instead of the
    /// configured one (Line2D template distances are off by ~1 % at the median on the paper
    /// preset, and the keep-depth mode also keeps a template's tilt).
    pub detection_depth_sigma_frac: f64,
    /// [`Refiner::refine`] (detector seeds): `end_limb_weight` used instead of the configured
    /// one (the end sections' limbs tell a flipped template's ends apart).
    pub detection_end_limb_weight: f64,
    /// Mono keep-depth mode without a ground plane: the axis tilt toward the camera is fitted
    /// too (the foreshortened length fixes it where the tube is tilted), with this prior on its
    /// change from the seed's, degrees; 0 keeps the seed's tilt (the default: on a paper-preset
    /// subset with 10 mm / 5 degree seeds, 2 degrees took the axis error median from 3.9 to
    /// 2.4 degrees but its p90 from 5.2 to 7.5, the length being foreshortened either way).
    pub mono_tilt_sigma_deg: f64,
    /// The mono tilt fit (`mono_tilt_sigma_deg > 0`) applies only to seeds whose axis leaves
    /// the image plane by at least this angle, degrees.
    pub mono_tilt_min_deg: f64,
    /// Ground whose height is not known exactly (`ground_height_known = false`, e.g. world
    /// z = 0 over terrain with relief): standard deviation of the tube's height above it,
    /// metres (mono depth prior); 0 ignores the height (the default: on the paper preset's
    /// terrain, 30 mm moved 10 mm / 5 degree seeds 7 mm too far at the median).
    pub ground_relief_sigma_m: f64,
    /// [`Refiner::refine`], mask and box seeds (no template pose): always fit in the mono
    /// keep-depth mode (the seed's distance, from the ground plane or the mask width, is kept
    /// along the centre's viewing ray). The full fit took the distance from the limbs'
    /// separation (biased by shading) and a wrong distance made the fit tilt the axis to match
    /// the foreshortened length: on the paper preset (learned seeds, `--ground auto`, 80
    /// images) the axis error went 1.31 -> 5.06 degrees (median), the perpendicular error
    /// 32 -> 81 mm.
    pub mask_seed_keep_depth: bool,
    /// [`Refiner::refine`], mask and box seeds with a ground plane: the ground tilt prior's
    /// standard deviation (degrees) instead of `ground_tilt_sigma_deg`. The seed's axis lies
    /// parallel to the ground (tilt error 0.7 degrees at the median against the truth on the
    /// paper preset) while its distance is off by centimetres, so a fitted tilt follows the
    /// wrong foreshortened length (3 degrees: axis error 1.31 -> 2.99 degrees median).
    /// The CLI's stereo stages after the fit (photometric ends, rims, two-view contour fit) use
    /// it too for these seeds (instead of `ground_tilt_sigma_deg`: the stereo axis p90 on
    /// three calibration stereo sets went 2.56 -> 1.24 deg). It assumes the tubes
    /// lie parallel to the given ground plane: raise it on sloped terrain.
    pub mask_seed_tilt_sigma_deg: f64,
    /// [`Refiner::refine`], mask and box seeds: `end_limb_weight` used (instead of
    /// `detection_end_limb_weight`, which is for template poses whose ends may be flipped).
    pub mask_seed_end_limb_weight: f64,
    /// Mono keep-depth mode with a ground plane: also fit the distance along the centre's
    /// viewing ray, from the end outlines only (the foreshortened length, the tilt being fixed
    /// by the ground; the limbs do not inform it).
    pub mono_length_depth: bool,
    /// [`Refiner::refine`], mask and box seeds: `ground_relief_sigma_m` used (metres; 0 keeps
    /// the configured one). The seed's distance came from the ground plane at the mask's centre
    /// pixel; once the fit has moved the centre in the image, re-placing it at the ground height
    /// along its new ray ([`fit`], mono depth from the ground) beats keeping the seed's distance:
    /// on the paper preset (80 no-tags images, learned seeds, `--ground auto`) perpendicular
    /// error 35.8 / 58.5 -> 30.2 / 51.5 mm (median / p90; seeds 32.1 / 54.4).
    pub mask_seed_relief_sigma_m: f64,
    /// [`Refiner::refine`], mask and box seeds: `mono_length_depth` used. Off: on the paper
    /// preset (learned seeds, `--ground auto`, 80 no-tags images, 337 seeds within 100 mm of a
    /// truth) the distance error went 39 -> 35 mm at the median (fully visible tubes 38 -> 23)
    /// but its p90 64 -> 172 mm (ends hidden by rocks or sand, end outlines on wrong edges).
    pub mask_seed_length_depth: bool,
    /// [`Refiner::refine`], seeds with a mask and no template pose: a converged fit whose
    /// silhouette agrees with the mask at a lower IoU than this keeps the seed's centre and axis
    /// ([`TubeAxisPose::seed_kept`]); 0 disables. Chosen on a generated validation set (val21,
    /// learned seeds, `--ground auto`): axis 0.63 / 4.06 -> 0.61 / 3.23 degrees (median / p90),
    /// perpendicular 11.2 -> 9.6 mm (median); 0.5: 0.63 / 3.70 degrees.
    pub mask_seed_min_agreement: f64,
    /// [`Refiner::refine`], detections with a mask and its axis and no template pose: the mask's
    /// axis line is a prior on the fitted axis's direction in the image
    /// ([`priors::ImageAxisPrior`]) with the line's ends known to this many pixels, with a ground
    /// plane, in the fits without stereo points (mono, and the stereo edge polish that keeps the
    /// stereo distance; on the calibration stereo set, seed 11, learned seeds, stereo + ground:
    /// axis p90 2.85 -> 2.19 deg, perpendicular p90 4.12 -> 4.29 mm; also in the stereo fit
    /// itself: 2.68 deg, 4.54 mm; stereo without the ground: 11.2 -> 12.9 deg); 0 disables.
    /// The fit's edges and the mask's shape err independently: without the prior the fit left
    /// 207 of 1582 no-tags test axes more than 0.5 deg further from their truth than the mask's
    /// axis, and brought 440 that much closer. 0.4 px was chosen on the generated validation
    /// sets (val9, val21; both cross-split models, learned seeds, `--ground auto`) among 0.25,
    /// 0.3, 0.4, 0.5, 0.6 and 1 by the mean axis p90: mono axis median / p90 from 0.52-0.55 /
    /// 2.48-3.35 deg to 0.41-0.52 / 1.87-2.08 deg (`docs/design/0015-mask-axis-prior.md`).
    /// Once mask seeds start at their seal end ([`RefineConfig::mask_seed_end_colour_corr`]):
    /// 0.5 px, chosen the same way among 0.3, 0.4, 0.5, 0.6, 0.8 and 1 on the seed-21 set and
    /// val9 (no-tags model, mono + ground): mean axis p90 1.31 -> 1.16 deg.
    pub mask_axis_sigma_px: f64,
    /// [`Refiner::refine`], mask seeds without stereo points: contour points more than this
    /// many pixels outside the detection's mask are hidden ([`fit::Scene::shown`]), so that
    /// the fit of a tube partly hidden by a rock or sand does not take the occluder's outline
    /// for the tube's; 0 disables.
    pub mask_visibility_px: usize,
    /// [`Refiner::refine`] with a ground plane (`RefineInput::ground`) and no stereo points: a
    /// Line2D template pose seeds the fit by its image axis ([`seed::template_image_axis`]),
    /// placed on the ground like a learned mask's axis and refined with the mask seeds'
    /// settings ([`seed_policy::SeedKind::MaskOrBox`]; the template's silhouette is its mask),
    /// instead of by the template's own distance and tilt, which are those of the nearest
    /// template view. Line2D detections on two generated validation sets (seed-21
    /// no-tags half, val9), mono + `--ground auto`: tubes matched within 50 mm 338 -> 836 of
    /// 1425 and 117 -> 351 of 363, axis median / p90 2.04 / 17.4 -> 0.73 / 5.7 deg and 3.05 /
    /// 29.6 -> 0.69 / 8.7 deg, perpendicular median 16.7 -> 5.2 mm and 17.2 -> 5.4 mm
    /// (`docs/design/0019-line2d-seeds-by-image-axis.md`). Off: the template pose is the seed.
    pub template_seed_as_image_axis: bool,
    /// [`Refiner::refine_with_colour`], mask seeds in a colour (or grey) image: the mask's image
    /// axis is turned end to end before the fit when its colours put the gold seal section
    /// behind it, `ρ ≤ −mask_seed_end_colour_corr` ([`seal_end::seal_end_along_axis`], a
    /// correlation in [−1, 1]); a value above 1 disables. A mask axis has no end of its own,
    /// and a fit started with the ends swapped lays the wider seal and foot sections over the
    /// wrong parts of the tube and settles turned and displaced along the axis before the end
    /// decision ([`Refiner::refine_seed`]) can swap them back. See
    /// `docs/design/0016-seal-end-from-colour.md` for the choice.
    pub mask_seed_end_colour_corr: f64,
}

impl Default for RefineConfig {
    fn default() -> Self {
        RefineConfig {
            search_radius_px: 8,
            fine_search_radius_px: 5,
            fine_polish: true,
            blur_full_resolution: false,
            sample_spacing_px: 3.0,
            max_samples: 200,
            min_gradient: 0.004,
            rel_edge_strength: 0.25,
            max_step_px: 2.0,
            reassociate_px: 1.0,
            converged_px: 0.02,
            max_iterations: 16,
            min_body_width_px: 14.0,
            seed_search: true,
            seed_search_radius_px: 16,
            seed_search_rotation_deg: 7.5,
            max_hypotheses: 3,
            stereo_edge_polish: true,
            end_limb_weight: 0.0,
            seed_score_margin: 0.0,
            max_levels: 4,
            edge_sigma_px: 0.5,
            stereo_sigma_m: 0.0015,
            stereo_points_per_measurement: 63.0,
            inlier_px: 2.0,
            min_inlier_fraction: 0.5,
            min_in_image_fraction: 0.7,
            min_samples: 12,
            max_centre_shift_frac: 0.3,
            max_axis_change_deg: 50.0,
            decide_end: true,
            end_score_scale: 0.02,
            end_override_confidence: 0.9,
            limb_polarity: true,
            outermost_limb_edge: false,
            ground_sigma_m: 0.003,
            ground_height_known: true,
            seed_distance_sigma_frac: 0.0,
            ground_tilt_sigma_deg: 3.0,
            mono_keep_depth: true,
            mono_width_sigma_px: 0.3,
            mono_depth_sigma_frac: 0.01,
            detection_depth_sigma_frac: 0.03,
            detection_end_limb_weight: 1.0,
            mono_tilt_sigma_deg: 0.0,
            mono_tilt_min_deg: 0.0,
            ground_relief_sigma_m: 0.0,
            mask_seed_keep_depth: true,
            mask_seed_tilt_sigma_deg: 0.1,
            mask_seed_end_limb_weight: 0.0,
            mono_length_depth: false,
            mask_seed_length_depth: false,
            mask_seed_relief_sigma_m: 0.001,
            mask_seed_min_agreement: 0.6,
            mask_axis_sigma_px: 0.5,
            mask_visibility_px: 8,
            mask_seed_end_colour_corr: 0.3,
            template_seed_as_image_axis: true,
        }
    }
}

impl RefineConfig {
    /// Checks ranges.
    pub fn validate(&self) -> Result<(), RefineError> {
        let ok = self.search_radius_px >= 1
            && self.search_radius_px <= 64
            && self.fine_search_radius_px >= 1
            && self.sample_spacing_px > 0.0
            && self.max_samples >= 16
            && self.min_gradient >= 0.0
            && self.max_levels >= 1
            && self.reassociate_px >= 0.0
            && self.converged_px >= 0.0
            && self.edge_sigma_px > 0.0
            && self.stereo_sigma_m > 0.0
            && self.stereo_points_per_measurement >= 1.0
            && self.inlier_px > 0.0
            && (0.0..=1.0).contains(&self.min_inlier_fraction)
            && (0.0..=1.0).contains(&self.min_in_image_fraction)
            && self.end_score_scale > 0.0
            && (0.5..=1.0).contains(&self.end_override_confidence)
            && self.ground_sigma_m > 0.0
            && self.seed_distance_sigma_frac >= 0.0
            && self.ground_tilt_sigma_deg > 0.0
            && self.mono_depth_sigma_frac > 0.0
            && self.detection_depth_sigma_frac > 0.0
            && self.detection_end_limb_weight >= 0.0
            && self.end_limb_weight >= 0.0
            && self.mono_tilt_sigma_deg >= 0.0
            && (0.0..=90.0).contains(&self.mono_tilt_min_deg)
            && self.mono_width_sigma_px >= 0.0
            && self.ground_relief_sigma_m >= 0.0
            && self.mask_seed_tilt_sigma_deg > 0.0
            && self.mask_seed_end_limb_weight >= 0.0
            && self.mask_seed_relief_sigma_m >= 0.0
            && (0.0..=1.0).contains(&self.mask_seed_min_agreement)
            && self.mask_axis_sigma_px >= 0.0
            && self.mask_seed_end_colour_corr >= 0.0;
        if ok {
            Ok(())
        } else {
            Err(RefineError::Config(format!("{self:?}")))
        }
    }
}

/// One image (grayscale, intensities in [0, 1]) with its camera and optional scene data.
#[derive(Clone, Copy, Debug)]
pub struct RefineInput<'a> {
    /// Grayscale image, row-major, `camera.width x camera.height`.
    pub image: &'a Plane<f32>,
    /// Camera of the image.
    pub camera: &'a CameraModel,
    /// Optional ground plane (camera frame): places mask/box seeds on it and adds the resting
    /// priors to the fit (see [`fit`]).
    pub ground: Option<GroundPlane>,
    /// Optional depth map and stereo points.
    pub scene: Scene<'a>,
}

/// The colour image and the detection's mask for the colour end decision ([`seal_end`]).
#[derive(Clone, Copy)]
struct EndColour<'a> {
    image: &'a ColourImage<'a>,
    visible: Option<&'a BinaryMask>,
}

/// The pose refiner: a tube model and a configuration.
#[derive(Clone, Debug)]
pub struct Refiner {
    /// The cylinder model of the tube.
    pub model: CylinderModel,
    /// Tuning.
    pub config: RefineConfig,
}

/// Stereo points within the robust threshold that make a fit's stereo distance trusted
/// whatever the region's point count ([`stereo_supports_fit`]).
pub const MIN_STEREO_INLIERS: usize = 20;

/// Whether a fit's stereo points support it: at least [`MIN_STEREO_INLIERS`] of them, or at
/// least half of the `points`, lie within the robust threshold (`inliers`,
/// [`tubeloc_core::ResidualStats::stereo_points`]). Without that support (mismatched disparities, e.g. beside
/// the left border) a detection is refined again without its points ([`Refiner::refine`]) and
/// the edge polish does not keep their distance ([`RefineConfig::stereo_edge_polish`]).
pub fn stereo_supports_fit(inliers: usize, points: usize) -> bool {
    inliers >= MIN_STEREO_INLIERS || 2 * inliers >= points
}

impl Refiner {
    /// A refiner for `tube` with `config`.
    pub fn new(tube: &TubeModel, config: RefineConfig) -> Result<Self, RefineError> {
        config.validate()?;
        Ok(Refiner { model: CylinderModel::new(tube)?, config })
    }

    /// Refines one detection, with the settings of its seed's kind ([`SeedKind::of`],
    /// [`SeedSettings`]: template pose or mask/box seed). Never returns NaN: failures come back with `converged = false`
    /// and a [`tubeloc_core::RefineFailure`]; the pose is then the last finite estimate (or the
    /// seed).
    pub fn refine(&self, input: &RefineInput, det: &TubeDetection) -> TubeAxisPose {
        self.refine_with_colour(input, det, None)
    }

    /// [`Refiner::refine`] with the image's colours: where the fit shows enough of the seal
    /// section and the body (kept to the detection's mask), their colours decide which end is
    /// the seal end ([`seal_end`]) instead of the edges, and set `end_confidence`.
    pub fn refine_with_colour(&self, input: &RefineInput, det: &TubeDetection, colour: Option<&ColourImage>) -> TubeAxisPose {
        let axis = self.template_as_image_axis(input, det);
        let det = axis.as_ref().unwrap_or(det);
        let mask = det.mask.as_ref().and_then(|m| m.to_mask().ok());
        let turned = self.seed_turned_by_colour(det, mask.as_ref(), colour);
        let det = turned.as_ref().unwrap_or(det);
        match seed_from_detection(det, input.camera, &self.model, input.ground.as_ref(), input.scene.stereo_points) {
            Ok(seed) => {
                // Detector seeds are worse than explicit ones in kind-specific ways
                // ([`seed_policy`]).
                let has_ground = input.ground.is_some() || input.scene.ground.is_some();
                let cfg = SeedSettings::new(&self.config, SeedKind::of(det), has_ground).config(&self.config);
                let r = Refiner { model: self.model.clone(), config: cfg };
                let ends = colour.map(|image| EndColour { image, visible: mask.as_ref() });
                // The mask's axis line as a prior on the image direction, with a ground plane
                // (used by the fits without stereo points: mono, and the stereo edge polish).
                let image_axis = match (&det.axis_seed, &mask, det.t_cam_tube.is_none() && has_ground) {
                    (Some(ax), Some(_), true) => priors::ImageAxisPrior::from_image_line(input.camera, ax.centre_px, ax.direction_px, self.config.mask_axis_sigma_px, self.model.length, seed.state.c.norm()),
                    _ => None,
                };
                // The mask shows which part of the tube is visible (mono: no depth map).
                let mono_mask = det.t_cam_tube.is_none() && input.scene.stereo_points.is_empty() && self.config.mask_visibility_px > 0;
                let of_image = |m: &&BinaryMask| m.width == input.camera.width as usize && m.height == input.camera.height as usize;
                let shown = mask.as_ref().filter(|_| mono_mask).filter(of_image).map(|m| m.dilated_window(self.config.mask_visibility_px));
                let with_prior = RefineInput { scene: Scene { image_axis, shown: shown.as_ref().map(|m| (m, input.camera)), ..input.scene }, ..*input };
                let pose = r.refine_seed_inner(&with_prior, &seed, det.image_id, det.score, Some(det.bbox), ends);
                // Stereo points that do not support the fit also gave the seed its distance;
                // the detection is refined again without them (mono, with the ground plane if any).
                let n_st = input.scene.stereo_points.len();
                if n_st > 0 && pose.failure.is_none() && !stereo_supports_fit(pose.residuals.stereo_points, n_st) {
                    let mono = RefineInput { scene: Scene { stereo_points: &[], ..input.scene }, ..*input };
                    return self.refine_with_colour(&mono, det, colour);
                }
                match (&mask, det.t_cam_tube.is_none()) {
                    (Some(m), true) => self.checked_against_mask(pose, &seed, m, input.camera),
                    _ => pose,
                }
            }
            Err(e) => failed(det.image_id, det.score, None, FailureReason::BadSeed, e.to_string()),
        }
    }

    /// The seed [`Refiner::refine_with_colour`] starts from: the detection's
    /// ([`seed_from_detection`]), a mask seed's image axis first turned to the seal end by its
    /// mask's colours when `colour` is given ([`RefineConfig::mask_seed_end_colour_corr`]).
    pub fn seed_with_colour(&self, input: &RefineInput, det: &TubeDetection, colour: Option<&ColourImage>) -> Result<Seed, RefineError> {
        let axis = self.template_as_image_axis(input, det);
        let det = axis.as_ref().unwrap_or(det);
        let mask = colour.and(det.mask.as_ref()).and_then(|m| m.to_mask().ok());
        let turned = self.seed_turned_by_colour(det, mask.as_ref(), colour);
        seed_from_detection(turned.as_ref().unwrap_or(det), input.camera, &self.model, input.ground.as_ref(), input.scene.stereo_points)
    }

    /// `det` with its mask axis turned end to end when the colours of `image` under `mask` (the
    /// detection's, decoded) put the seal end behind it
    /// ([`RefineConfig::mask_seed_end_colour_corr`]); `None` keeps `det` (no colour image or
    /// mask, a template pose, no axis seed, too little colour evidence, or the axis already
    /// points to the seal end).
    fn seed_turned_by_colour(&self, det: &TubeDetection, mask: Option<&BinaryMask>, image: Option<&ColourImage>) -> Option<TubeDetection> {
        let (mask, image) = (mask?, image?);
        if det.t_cam_tube.is_some() {
            return None;
        }
        let ax = det.axis_seed?;
        let rho = seal_end::seal_end_along_axis(mask, &ax, image)?;
        (rho <= -self.config.mask_seed_end_colour_corr).then(|| {
            let [dx, dy] = ax.direction_px;
            TubeDetection { axis_seed: Some(tubeloc_core::AxisSeed { direction_px: [-dx, -dy], ..ax }), ..det.clone() }
        })
    }

    /// The detection with its template pose replaced by the pose's image axis
    /// ([`seed::template_image_axis`]) where [`RefineConfig::template_seed_as_image_axis`]
    /// applies: a template pose, a ground plane in `input`, no stereo points.
    fn template_as_image_axis(&self, input: &RefineInput, det: &TubeDetection) -> Option<TubeDetection> {
        let applies = self.config.template_seed_as_image_axis && input.ground.is_some() && input.scene.stereo_points.is_empty();
        applies.then(|| seed::template_image_axis(det, input.camera, &self.model)).flatten()
    }

    /// A converged fit of a mask seed whose silhouette disagrees with the detector's mask
    /// (`IoU(silhouette ∩ dilate(mask, 4 px), mask) < mask_seed_min_agreement`, see
    /// [`silhouette::snap_mask`]) went to the wrong edges: the seed's centre and axis are
    /// returned instead, with the fit's end decision, the covariance widened by the squared
    /// fit-to-seed differences, and [`TubeAxisPose::seed_kept`] saying why.
    fn checked_against_mask(&self, mut pose: TubeAxisPose, seed: &Seed, mask: &BinaryMask, camera: &CameraModel) -> TubeAxisPose {
        let tau = self.config.mask_seed_min_agreement;
        if !(pose.converged && tau > 0.0) {
            return pose;
        }
        let Some(iou) = silhouette::mask_agreement(mask, &self.model, &pose, camera, silhouette::MaskSnap::default().dilate_px) else { return pose };
        if iou >= tau {
            return pose;
        }
        let a = if seed.state.a.dot(&pose.end_direction) >= 0.0 { seed.state.a } else { -seed.state.a };
        let Ok(kept) = TubeAxisPose::new(pose.image_id, pose.score, seed.state.c, a, pose.end_confidence) else { return pose };
        let dc = pose.centre - kept.centre;
        let angle = tubeloc_core::tube_pose::axis_angle(&pose.axis, &kept.axis);
        for i in 0..3 {
            pose.covariance[i][i] += dc[i] * dc[i];
        }
        for i in 3..5 {
            pose.covariance[i][i] += angle * angle;
        }
        pose.centre = kept.centre;
        pose.axis = kept.axis;
        pose.end_direction = kept.end_direction;
        pose.seed_kept = Some(format!("the fitted silhouette agrees with the detector's mask at IoU {iou:.2} < {tau}"));
        pose
    }

    /// Refines from an explicit seed. `bbox` (COCO `[x, y, w, h]`) widens the region of
    /// interest when given.
    pub fn refine_seed(&self, input: &RefineInput, seed: &Seed, image_id: u64, score: f64, bbox: Option<[f64; 4]>) -> TubeAxisPose {
        self.refine_seed_inner(input, seed, image_id, score, bbox, None)
    }

    /// [`Refiner::refine_seed`], with the colour end decision when `ends` is given.
    fn refine_seed_inner(&self, input: &RefineInput, seed: &Seed, image_id: u64, score: f64, bbox: Option<[f64; 4]>, ends: Option<EndColour>) -> TubeAxisPose {
        let cam = input.camera;
        if input.image.width != cam.width as usize || input.image.height != cam.height as usize {
            let msg = format!("image is {}x{} but the camera is {}x{}", input.image.width, input.image.height, cam.width, cam.height);
            return failed(image_id, score, Some(&seed.state), FailureReason::BadSeed, msg);
        }
        let st = seed.state;
        if !(st.c.iter().all(|v| v.is_finite()) && st.a.iter().all(|v| v.is_finite())) || st.a.norm() < 1e-9 || st.c.z <= 0.0 {
            return failed(image_id, score, None, FailureReason::BadSeed, "seed is not finite or is behind the camera".into());
        }
        let st = AxisState { c: st.c, a: st.a.normalize() };
        let Some((rect, top)) = self.region(cam, &st, bbox) else {
            return failed(image_id, score, Some(&st), FailureReason::OutOfImage, "the seed projects outside the image".into());
        };
        // Unsmoothed full-resolution gradients only for narrow tubes (fitted at full resolution
        // alone), where smoothing merges a limb's shading ramp with its step.
        let pyr = edges::build_pyramid_with(input.image, cam, rect, top + 1, self.config.blur_full_resolution || top > 0);
        let scene = Scene { ground: input.scene.ground.or(input.ground), ..input.scene };
        let top = top.min(pyr.len() - 1);
        let mut a = self.fit_candidates(&pyr, top, &scene, &st);
        if a.failure.is_some() && self.config.decide_end {
            // A template flipped end to end misplaces the sections; retry the other end.
            let b = fit::fit(&self.model, &self.config, &pyr, top, &scene, AxisState { c: st.c, a: -st.a });
            if b.failure.is_none() {
                a = b;
            }
        }
        let colour_evidence = ends.and_then(|e| {
            let pose = to_pose(image_id, score, &a, 0.5);
            (a.failure.is_none()).then(|| seal_end::seal_end_evidence(&self.model, &pose, cam, e.image, e.visible)).flatten()
        });
        let (best, conf) = if let (true, Some(ev)) = (self.config.decide_end, colour_evidence) {
            // The colours decide; the flipped hypothesis is fitted (its sections placed) when
            // they favour it, else `a` is simply turned end to end.
            let p = seal_end::end_confidence(&ev);
            if ev.contrast >= 0.0 {
                (a, p)
            } else {
                let b = fit::fit(&self.model, &self.config, &pyr, top.min(1), &scene, AxisState { c: a.state.c, a: -a.state.a });
                if b.failure.is_none() {
                    (b, p)
                } else {
                    (FitResult { state: AxisState { c: a.state.c, a: -a.state.a }, ..a }, p)
                }
            }
        } else if self.config.decide_end && a.failure.is_none() {
            let flipped = AxisState { c: a.state.c, a: -a.state.a };
            let b = fit::fit(&self.model, &self.config, &pyr, top.min(1), &scene, flipped);
            let dscore = if b.failure.is_none() { b.score - a.score } else { 1.0 };
            let p = 1.0 / (1.0 + (-dscore.abs() / self.config.end_score_scale).exp());
            // A detector that claims the end (template pose) is overruled only by clear image
            // evidence; small tubes often cannot tell the ends apart in grey levels.
            let keeps_claim = seed.end_known && a.state.a.dot(&st.a) > 0.0;
            if dscore < 0.0 && (!keeps_claim || p >= self.config.end_override_confidence) {
                (b, p)
            } else if dscore < 0.0 {
                (a, 0.5)
            } else {
                (a, p)
            }
        } else {
            (a, if seed.end_known { 0.6 } else { 0.5 })
        };
        let mut best = best;
        if self.config.stereo_edge_polish && !scene.stereo_points.is_empty() && scene.mask.is_none() && best.failure.is_none() {
            // Stereo points fix the distance and tilt but, biased at the tube's outline, also
            // pull it across the image; the edges alone then place it in the image with the
            // distance and tilt kept (the mono keep-depth mode, forced). Where the stereo points
            // support the fit ([`stereo_supports_fit`]) the stereo distance stands: no
            // re-placement at the ground's height, which mask seeds' settings ask for in mono,
            // and no distance from the ends' length. Without that support the mono settings
            // apply, and the ground may place the tube.
            let mut cfg = RefineConfig { mono_width_sigma_px: f64::INFINITY, seed_search: false, decide_end: false, fine_polish: false, ..self.config.clone() };
            if stereo_supports_fit(best.stats.stereo_points, scene.stereo_points.len()) {
                cfg.ground_relief_sigma_m = 0.0;
                cfg.mono_length_depth = false;
            }
            let mono_scene = Scene { stereo_points: &[], ..scene };
            let polished = fit::fit(&self.model, &cfg, &pyr, 0, &mono_scene, best.state);
            if polished.failure.is_none() {
                best.state = polished.state;
            }
        }
        to_pose(image_id, score, &best, conf)
    }

    /// Fits from the coarse-search hypotheses ([`search::coarse_search`]) and the seed itself,
    /// best scored first, up to `max_hypotheses` fits: the best hypothesis and the seed are both
    /// fitted and the better final score ([`FitResult::score`]) wins; further hypotheses are
    /// tried only while none succeeded. Returns the first failure when all fail.
    fn fit_candidates(&self, pyr: &[edges::GradientLevel], top: usize, scene: &Scene, st: &AxisState) -> FitResult {
        let cfg = &self.config;
        let mut cands: Vec<AxisState> = Vec::new();
        if cfg.seed_search {
            let spec = search::SearchSpec { radius_px: cfg.seed_search_radius_px as i32, step_px: 2, max_rotation_deg: cfg.seed_search_rotation_deg, rotation_step_deg: 2.5, max_samples: 120 };
            let hyps = search::coarse_search(&self.model, &pyr[top], st, scene.ground.as_ref(), cfg.ground_height_known, &spec);
            cands.extend(hyps.iter().map(|h| h.state));
        }
        // The seed itself goes second (or first without the search).
        cands.insert(cands.len().min(1), *st);
        let mut first_fail = None;
        let mut best: Option<FitResult> = None;
        let seed_index = cands.len().min(1);
        for (k, c) in cands.iter().take(cfg.max_hypotheses.max(1)).enumerate() {
            let mut r = fit::fit(&self.model, cfg, pyr, top, scene, *c);
            if r.failure.is_none() {
                // The seed's own fit wins unless a search hypothesis scores clearly better (the
                // search can prefer a neighbouring edge structure, e.g. a limb shaded into the
                // tube's own cast shadow, whose shadow edge and terminator pair up).
                let adjusted = if k == seed_index { r.score - cfg.seed_score_margin } else { r.score };
                if best.as_ref().is_none_or(|b| adjusted < b.score) {
                    r.score = adjusted;
                    best = Some(r);
                }
                if k >= 1 {
                    break;
                }
                continue;
            }
            first_fail.get_or_insert(r);
        }
        if let Some(b) = best {
            return b;
        }
        first_fail.expect("at least the seed is fitted")
    }

    /// Region of interest (crop rectangle) and coarsest pyramid level for a state.
    fn region(&self, cam: &CameraModel, st: &AxisState, bbox: Option<[f64; 4]>) -> Option<((usize, usize, usize, usize), usize)> {
        let (mut x0, mut y0, mut x1, mut y1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
        for p in st.bounding_points(&self.model)? {
            if let Some(u) = cam.project(&Point3::from(p)) {
                (x0, y0, x1, y1) = (x0.min(u.x), y0.min(u.y), x1.max(u.x), y1.max(u.y));
            }
        }
        if x0 > x1 {
            return None;
        }
        if let Some(b) = bbox {
            x0 = x0.min(b[0]);
            y0 = y0.min(b[1]);
            x1 = x1.max(b[0] + b[2]);
            y1 = y1.max(b[1] + b[3]);
        }
        let fpx = 0.5 * (cam.fx + cam.fy);
        let body_px = 2.0 * self.model.body_radius() * fpx / st.c.norm();
        let top = ((body_px / self.config.min_body_width_px).max(1.0).log2().floor() as usize).min(self.config.max_levels - 1);
        let extra = if self.config.seed_search { self.config.seed_search_radius_px as f64 } else { 0.0 };
        let margin = (self.config.search_radius_px as f64 + 4.0 + extra) * (1u64 << top) as f64 + 0.1 * (x1 - x0).max(y1 - y0);
        let rect = edges::roi([x0, y0, x1 - x0, y1 - y0], margin, cam.width as usize, cam.height as usize)?;
        Some((rect, top))
    }

    /// Points of the fitted occluding contour in pixels (for overlays), sampled every
    /// `spacing_px`; only silhouette points not hidden by the tube itself.
    pub fn contour_pixels(&self, camera: &CameraModel, pose: &TubeAxisPose, spacing_px: f64) -> Vec<Point2<f64>> {
        let st = AxisState { c: pose.centre, a: pose.end_direction };
        let Some(f) = st.frame() else { return Vec::new() };
        contour::build_samples(&self.model, &st, camera, spacing_px)
            .iter()
            .filter_map(|s| {
                let p = s.eval(&self.model, &f)?;
                if !s.on_silhouette(&self.model, &f, &p) || self.model.occludes(&st.c, &st.a, &(p.x + p.out * 1e-4)) {
                    return None;
                }
                camera.project(&p.x)
            })
            .collect()
    }
}

fn failed(image_id: u64, score: f64, st: Option<&AxisState>, reason: FailureReason, msg: String) -> TubeAxisPose {
    let (c, a) = match st {
        Some(s) if s.c.iter().chain(s.a.iter()).all(|v| v.is_finite()) && s.a.norm() > 1e-9 => (s.c, s.a),
        _ => (Vector3::zeros(), Vector3::z()),
    };
    TubeAxisPose::new(image_id, score, c, a, 0.5).expect("finite centre and unit axis").fail(reason, msg)
}

fn to_pose(image_id: u64, score: f64, r: &FitResult, end_confidence: f64) -> TubeAxisPose {
    let mut p = match TubeAxisPose::new(image_id, score, r.state.c, r.state.a, end_confidence) {
        Ok(p) => p,
        Err(e) => return failed(image_id, score, None, FailureReason::Diverged, e.to_string()),
    };
    p.covariance = r.covariance;
    p.residuals = r.stats;
    match &r.failure {
        Some((reason, msg)) => p.fail(*reason, msg.clone()),
        None => p,
    }
}
