//! [`Refiner`]: a tube model and its resolved settings, with the two ways in: a detection
//! ([`Refiner::refine`]) or an explicit seed ([`Refiner::refine_seed`]).

use crate::contour::{self, AxisState};
use crate::detection_seed::{self, EndColour};
use crate::error::RefineError;
use crate::model::CylinderModel;
use crate::scene::Scene;
use crate::seal_end::ColourImage;
use crate::seed::{GroundPlane, Seed};
use crate::seed_fit::{failed, SeedToFit};
use crate::seed_policy::{FitSettings, SeedKind};
use crate::settings::RefineConfig;
use nalgebra::Point2;
use tubeloc_core::{BoundedMask, CameraModel, FailureReason, Plane, TubeAxisPose, TubeDetection, TubeModel};

/// One image (grayscale, intensities in [0, 1]) with its camera and optional scene data.
#[derive(Clone, Copy, Debug)]
pub struct RefineInput<'a> {
    /// Grayscale image, row-major, `camera.width x camera.height`.
    pub image: &'a Plane<f32>,
    /// Camera of the image.
    pub camera: &'a CameraModel,
    /// Optional ground plane (camera frame): places mask/box seeds on it and adds the resting
    /// priors to the fit (see [`crate::settings::Priors`]).
    pub ground: Option<GroundPlane>,
    /// Optional depth map and stereo points.
    pub scene: Scene<'a>,
}

/// The pose refiner: a tube model and its settings, resolved once per seed kind.
#[derive(Clone, Debug)]
pub struct Refiner {
    /// The cylinder model of the tube.
    pub model: CylinderModel,
    config: RefineConfig,
    /// `config` resolved for each seed kind, in the order of [`SeedKind::ALL`].
    resolved: [FitSettings; 3],
}

/// Stereo points within the robust threshold that make a fit's stereo distance trusted
/// whatever the region's point count ([`stereo_supports_fit`]).
pub const MIN_STEREO_INLIERS: usize = 20;

/// Whether a fit's stereo points support it: at least [`MIN_STEREO_INLIERS`] of them, or at
/// least half of the `points`, lie within the robust threshold (`inliers`,
/// [`tubeloc_core::ResidualStats::stereo_points`]). Without that support (mismatched
/// disparities, e.g. beside the left border) a detection is refined again without its points
/// ([`Refiner::refine`]) and the edge polish does not keep their distance
/// ([`crate::settings::Solver::stereo_edge_polish`]).
pub fn stereo_supports_fit(inliers: usize, points: usize) -> bool {
    inliers >= MIN_STEREO_INLIERS || 2 * inliers >= points
}

impl Refiner {
    /// A refiner for `tube` with `config` (validated, then resolved for every seed kind).
    pub fn new(tube: &TubeModel, config: RefineConfig) -> Result<Self, RefineError> {
        config.validate()?;
        let resolved = SeedKind::ALL.map(|k| config.resolve(k));
        Ok(Refiner { model: CylinderModel::new(tube)?, config, resolved })
    }

    /// The settings the refiner was built with.
    pub fn config(&self) -> &RefineConfig {
        &self.config
    }

    /// The settings a fit of a seed of `kind` uses.
    pub fn settings(&self, kind: SeedKind) -> &FitSettings {
        &self.resolved[kind.index()]
    }

    /// Refines one detection with the settings of its seed's kind ([`SeedKind::of`]). With the
    /// image's colours (`colour`), a mask seed is first turned to its seal end by its mask's
    /// colours, and where the fit shows enough of the seal section and the body their colours
    /// decide which end is the seal end ([`crate::seal_end`]) instead of the edges. Never
    /// returns NaN: failures come back with `converged = false` and a
    /// [`tubeloc_core::RefineFailure`]; the pose is then the last finite estimate (or the seed).
    ///
    /// Steps: the detection's seed ([`Refiner::seed`]); its scene (the mask's image-axis prior
    /// and visible region, [`detection_seed::mask_scene`]); the fit of that seed
    /// ([`crate::seed_fit`]); a refit without stereo points that do not support the fit
    /// ([`stereo_supports_fit`]); the check of a mask seed's silhouette against its mask
    /// ([`crate::mask_check`]).
    pub fn refine(&self, input: &RefineInput, det: &TubeDetection, colour: Option<&ColourImage>) -> TubeAxisPose {
        let axis = detection_seed::template_as_image_axis(self, input, det);
        let det = axis.as_ref().unwrap_or(det);
        let mask = det.mask.as_ref().and_then(|m| m.to_bounded_mask().ok());
        let turned = detection_seed::turned_by_colour(self.config.mask.end_colour_corr, det, mask.as_ref(), colour);
        let det = turned.as_ref().unwrap_or(det);
        let seed = match crate::seed::seed_from_detection(det, input.camera, &self.model, input.ground.as_ref(), input.scene.stereo_points) {
            Ok(seed) => seed,
            Err(e) => return failed(det.image_id, det.score, None, FailureReason::BadSeed, e.to_string()),
        };
        let (image_axis, shown) = detection_seed::mask_scene(self, input, det, mask.as_ref(), &seed);
        let with_mask = RefineInput { scene: Scene { image_axis, shown: shown.as_ref().map(|m| (m, input.camera)), ..input.scene }, ..*input };
        let ends = colour.map(|image| EndColour { image, visible: mask.as_ref() });
        let job = SeedToFit { seed: &seed, image_id: det.image_id, score: det.score, bbox: Some(det.bbox), ends };
        let pose = self.fit_seed(self.settings(SeedKind::of(det)), &with_mask, &job);
        // Stereo points that do not support the fit also gave the seed its distance; the
        // detection is refined again without them (mono, with the ground plane if any).
        let n_st = input.scene.stereo_points.len();
        if n_st > 0 && pose.failure.is_none() && !stereo_supports_fit(pose.residuals.stereo_points, n_st) {
            let mono = RefineInput { scene: Scene { stereo_points: &[], ..input.scene }, ..*input };
            return self.refine(&mono, det, colour);
        }
        match (&mask, det.t_cam_tube.is_none()) {
            (Some(m), true) => crate::mask_check::checked_against_mask(self, pose, &seed, m, input.camera),
            _ => pose,
        }
    }

    /// The seed [`Refiner::refine`] starts from: the detection's
    /// ([`crate::seed::seed_from_detection`]), a template pose taken by its image axis where
    /// [`crate::settings::SeedProfiles::template_as_image_axis`] applies, a mask seed's image
    /// axis first turned to the seal end by its mask's colours when `colour` is given
    /// ([`crate::settings::MaskUse::end_colour_corr`]).
    pub fn seed(&self, input: &RefineInput, det: &TubeDetection, colour: Option<&ColourImage>) -> Result<Seed, RefineError> {
        let axis = detection_seed::template_as_image_axis(self, input, det);
        let det = axis.as_ref().unwrap_or(det);
        let mask: Option<BoundedMask> = colour.and(det.mask.as_ref()).and_then(|m| m.to_bounded_mask().ok());
        let turned = detection_seed::turned_by_colour(self.config.mask.end_colour_corr, det, mask.as_ref(), colour);
        crate::seed::seed_from_detection(turned.as_ref().unwrap_or(det), input.camera, &self.model, input.ground.as_ref(), input.scene.stereo_points)
    }

    /// Refines from an explicit seed with the explicit seeds' profile. `bbox` (COCO
    /// `[x, y, w, h]`) widens the region of interest when given.
    pub fn refine_seed(&self, input: &RefineInput, seed: &Seed, image_id: u64, score: f64, bbox: Option<[f64; 4]>) -> TubeAxisPose {
        let job = SeedToFit { seed, image_id, score, bbox, ends: None };
        self.fit_seed(self.settings(SeedKind::Explicit), input, &job)
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
