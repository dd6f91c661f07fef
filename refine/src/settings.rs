//! The refiner's settings ([`RefineConfig`]), in the groups a reader reviews one at a time.
//!
//! Pixel values are in pixels of the pyramid level they apply to unless a field says
//! full-resolution pixels. A settings file (`tubeloc refine --config`, TOML or JSON) holds any
//! subset of the groups and fields; missing ones keep their defaults, unknown ones are refused.
//! [`RefineConfig::validate`] names the first field out of range; [`RefineConfig::resolve`]
//! turns the groups and one seed kind's profile into the [`FitSettings`] a fit uses.
//!
//! The figures behind the defaults are in `docs/design/` (the record is named in each field).

use crate::error::RefineError;
use crate::seed_policy::{FitSettings, SeedKind};
use serde::{Deserialize, Serialize};
use tubeloc_core::CoreError;

/// Every setting of the refiner, by group. `Default` is the shipped tuning.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RefineConfig {
    /// Where contour samples are placed and how edges are searched along their normals.
    pub edge_search: EdgeSearch,
    /// The coarse alignment of the seed's contour before the fit.
    pub seed_search: SeedSearch,
    /// The coarse-to-fine Levenberg-Marquardt loop and its noise model.
    pub solver: Solver,
    /// When a finished fit counts as converged.
    pub acceptance: Acceptance,
    /// Which end of the fitted axis is the seal end (grey-level edges; colours when given).
    pub end_decision: EndDecision,
    /// The ground plane's priors.
    pub priors: Priors,
    /// Mono fits of narrow tubes that keep the seed's distance.
    pub mono_depth: MonoDepth,
    /// One profile per kind of seed, and how Line2D template poses are seeded.
    pub seeds: SeedProfiles,
    /// What a detector's mask adds to the fit of its seed.
    pub mask: MaskUse,
}

/// Contour sampling and the 1D edge search along each sample's image normal.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EdgeSearch {
    /// Half length of the search along contour normals at the coarsest level, pixels.
    pub radius_px: usize,
    /// Half length of the search at the finer levels, pixels (at most `radius_px`).
    pub fine_radius_px: usize,
    /// Spacing of contour samples along the projected contour, pixels.
    pub sample_spacing_px: f64,
    /// Most contour samples per level: the spacing widens for large tubes so that the cost per
    /// iteration stays bounded.
    pub max_samples: usize,
    /// Least `|∇I · n|` of an edge (intensity per pixel, images in [0, 1]).
    pub min_gradient: f32,
    /// Edge hypotheses weaker than this fraction of the strongest along a normal are dropped.
    pub rel_edge_strength: f32,
    /// Fix each limb's edge polarity (tube brighter or darker than the ground) after the first
    /// iteration of each level, so that edges of the other polarity are not associated.
    pub limb_polarity: bool,
}

impl Default for EdgeSearch {
    fn default() -> Self {
        EdgeSearch { radius_px: 8, fine_radius_px: 5, sample_spacing_px: 3.0, max_samples: 200, min_gradient: 0.004, rel_edge_strength: 0.25, limb_polarity: true }
    }
}

/// Coarse seed search ([`crate::search`]): the seed's contour is aligned at the coarsest level
/// over image translations and axis rotations before the fit, widening the basin to ~10 mm /
/// 5 degrees; the best hypothesis and the seed are both fitted and the better score wins.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SeedSearch {
    /// Run the search (otherwise the seed alone is fitted).
    pub enabled: bool,
    /// Half width of the translation grid, pixels of the coarsest level.
    pub radius_px: usize,
    /// Translation grid step, pixels of the coarsest level.
    pub step_px: usize,
    /// Largest axis rotation tried, degrees.
    pub rotation_deg: f64,
    /// Rotation step, degrees.
    pub rotation_step_deg: f64,
    /// Most contour samples scored per hypothesis.
    pub max_samples: usize,
    /// Most fits tried (search hypotheses and the seed) until one succeeds.
    pub max_hypotheses: usize,
}

impl Default for SeedSearch {
    fn default() -> Self {
        SeedSearch { enabled: true, radius_px: 16, step_px: 2, rotation_deg: 7.5, rotation_step_deg: 2.5, max_samples: 120, max_hypotheses: 3 }
    }
}

/// The coarse-to-fine loop ([`crate::fit`]) and its residual noise model.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Solver {
    /// Most pyramid levels.
    pub max_levels: usize,
    /// The coarsest level is chosen so that the tube's body is at least this wide, pixels.
    pub min_body_width_px: f64,
    /// Outer iterations at the coarsest level (half of it at the finer levels).
    pub max_iterations: usize,
    /// Most image motion of any contour sample in one step, pixels (trust region).
    pub max_step_px: f64,
    /// Search the edges again once the contour has moved this far since the last search, pixels.
    pub reassociate_px: f64,
    /// A level has converged when a step right after a fresh edge search moves no contour
    /// sample more than this, pixels.
    pub converged_px: f64,
    /// When the coarsest level is full resolution (narrow tubes), run it once more with the
    /// fine search radius, in mono fits (no stereo points, no depth map)
    /// (`docs/design/0018-fine-polish-in-mono.md`).
    pub fine_polish: bool,
    /// With stereo points: after the fit, re-place the tube in the image from the edges alone
    /// with its distance and tilt kept (the stereo points, biased at the tube's outline, pull
    /// it across the image).
    pub stereo_edge_polish: bool,
    /// Nominal edge localization noise, full-resolution pixels (residual normalization).
    pub edge_sigma_px: f64,
    /// Nominal stereo point noise, metres.
    pub stereo_sigma_m: f64,
    /// Stereo points per independent measurement, for the output covariance only: neighbouring
    /// SGM disparities share most of their census bits; 63 is the default census window
    /// (9 x 7 px) (`docs/design/0024-stereo-covariance-census-window.md`).
    pub stereo_points_per_measurement: f64,
    /// Factor on the axis's standard deviations in the output covariance only (its axis block
    /// times the square, the centre-axis terms times the factor, so that the matrix stays
    /// positive semi-definite): the edge residuals do not show the model's own errors (shading
    /// that moves limb edges, the ground's tilt prior), which left the axis σ too small. 1.35 is
    /// the smallest factor on a 0.05 grid that puts 95 % of the mono axis errors within 2σ on
    /// the real validation composites (`docs/design/0053-axis-covariance-on-real-frames.md`).
    pub axis_sigma_scale: f64,
}

impl Default for Solver {
    fn default() -> Self {
        Solver {
            max_levels: 4,
            min_body_width_px: 14.0,
            max_iterations: 16,
            max_step_px: 2.0,
            reassociate_px: 1.0,
            converged_px: 0.02,
            fine_polish: true,
            stereo_edge_polish: true,
            edge_sigma_px: 0.5,
            stereo_sigma_m: 0.0015,
            stereo_points_per_measurement: 63.0,
            axis_sigma_scale: 1.35,
        }
    }
}

/// When a finished fit is accepted; a rejected one carries its
/// [`tubeloc_core::FailureReason`] instead of `converged`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Acceptance {
    /// A sample is an inlier when its edge lies within this many full-resolution pixels.
    pub inlier_px: f64,
    /// Fits with a smaller inlier fraction are rejected (`empty_terrain`).
    pub min_inlier_fraction: f64,
    /// Fits whose visible contour lies less than this fraction inside the image are rejected
    /// (`out_of_image`; not in the mono keep-depth mode, where the seed keeps the distance).
    pub min_in_image_fraction: f64,
    /// Fewer visible (or matched) contour samples than this fail the fit.
    pub min_samples: usize,
    /// A fit moving the centre by more than this fraction of the seed's distance diverged.
    pub max_centre_shift_frac: f64,
    /// A fit turning the axis by more than this (degrees, undirected) diverged.
    pub max_axis_change_deg: f64,
}

impl Default for Acceptance {
    fn default() -> Self {
        Acceptance { inlier_px: 2.0, min_inlier_fraction: 0.5, min_in_image_fraction: 0.7, min_samples: 12, max_centre_shift_frac: 0.3, max_axis_change_deg: 50.0 }
    }
}

/// Which end is the seal end: from the colours where the fit shows both sections
/// ([`crate::seal_end`]), else by fitting both end hypotheses and comparing their edge support.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EndDecision {
    /// Decide the end (otherwise the seed's end is kept with confidence 0.5, 0.6 when the
    /// seed claims it).
    pub enabled: bool,
    /// Score difference (mean truncated cost) that gives `end_confidence` ≈ 0.73 (logistic scale).
    pub score_scale: f64,
    /// A seed that claims its end (a template pose) is flipped only when the image favours the
    /// other end with at least this confidence.
    pub override_confidence: f64,
}

impl Default for EndDecision {
    fn default() -> Self {
        EndDecision { enabled: true, score_scale: 0.02, override_confidence: 0.9 }
    }
}

/// The ground plane's priors (with a ground plane in the input): the tube rests on it.
/// The axis tilt's deviation depends on the seed kind ([`SeedProfile::ground_tilt_sigma_deg`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Priors {
    /// Standard deviation of the centre's height above the ground (expected: the largest
    /// radius), metres.
    pub ground_sigma_m: f64,
    /// The tube rests on the given plane itself. False when only the plane's orientation is
    /// trusted (e.g. the world's z = 0 over terrain with relief, `--ground auto`): then the
    /// height prior is left out, seeds keep their height, and the mono depth uses
    /// [`SeedProfile::ground_relief_sigma_m`].
    pub ground_height_known: bool,
}

impl Default for Priors {
    fn default() -> Self {
        Priors { ground_sigma_m: 0.003, ground_height_known: true }
    }
}

/// Mono fits (no stereo points, no mask term) of tubes so narrow that their width fixes the
/// distance worse than the seed: the fit keeps the seed's distance along the centre's viewing
/// ray and fits the centre across the ray, the axis turn about it and, with a ground plane,
/// the tilt (`docs/design/0012-mono-keep-depth-for-narrow-tubes.md`). A tube is that narrow
/// when `width_sigma_px / body_width_px > depth_sigma_frac` of its seed kind's profile.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MonoDepth {
    /// Use the keep-depth mode at all.
    pub keep_depth: bool,
    /// Systematic uncertainty of a limb-to-limb width, full-resolution pixels (shading biases
    /// limb edges by 0.25 px at the median on the paper preset).
    pub width_sigma_px: f64,
}

impl Default for MonoDepth {
    fn default() -> Self {
        MonoDepth { keep_depth: true, width_sigma_px: 0.3 }
    }
}

/// The fit settings that differ by where a seed came from ([`SeedKind`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SeedProfile {
    /// Uncertainty of the seed's distance as a fraction of it: decides which tubes are narrow
    /// enough for the mono keep-depth mode ([`MonoDepth`]) and weighs the seed's distance
    /// against the ground's when a mono fit is finally moved along its ray.
    pub depth_sigma_frac: f64,
    /// Weight of the limb residuals of the sections other than the body (foot flange, seal
    /// section) relative to the body's; shading biases their edges, but they tell a flipped
    /// template's ends apart. 0 leaves them out.
    pub end_limb_weight: f64,
    /// Always fit in the mono keep-depth mode (when it applies at all: mono, no mask term),
    /// whatever the tube's width.
    pub keep_depth: bool,
    /// With a ground plane: standard deviation of the axis's elevation above it, degrees.
    pub ground_tilt_sigma_deg: f64,
    /// Ground of unknown height ([`Priors::ground_height_known`] false): standard deviation of
    /// the tube's height above it, metres, when a mono fit is moved along its ray; 0 keeps the
    /// seed's distance.
    pub ground_relief_sigma_m: f64,
}

impl SeedProfile {
    /// Explicit seeds (e.g. a perturbed exact pose, [`crate::Refiner::refine_seed`]).
    pub const EXPLICIT: SeedProfile = SeedProfile { depth_sigma_frac: 0.01, end_limb_weight: 0.0, keep_depth: false, ground_tilt_sigma_deg: 3.0, ground_relief_sigma_m: 0.0 };

    /// Line2D template poses: distances off by ~1 % at the median, ends possibly flipped (the
    /// end sections' limbs tell them apart).
    pub const TEMPLATE_POSE: SeedProfile = SeedProfile { depth_sigma_frac: 0.03, end_limb_weight: 1.0, ..SeedProfile::EXPLICIT };

    /// Mask and box seeds (the learned segmenter's mask axis): a good image axis, a distance
    /// off by centimetres, an axis parallel to the ground. The full fit took the distance from
    /// the shading-biased limbs and tilted the axis to match (paper preset, learned seeds:
    /// axis median 1.31 -> 5.06 deg), hence `keep_depth`; a fitted tilt followed the wrong
    /// foreshortened length (3 deg: 1.31 -> 2.99 deg), hence the 0.1 deg tilt prior, which
    /// assumes flat-lying tubes (raise it on sloped terrain;
    /// `docs/design/0013-mask-seeds-lie-flat-on-the-ground.md`); re-placed at the ground's
    /// height once the fit moved the centre (perpendicular median 35.8 -> 30.2 mm).
    pub const MASK_OR_BOX: SeedProfile = SeedProfile { depth_sigma_frac: 0.03, end_limb_weight: 0.0, keep_depth: true, ground_tilt_sigma_deg: 0.1, ground_relief_sigma_m: 0.001 };
}

/// One [`SeedProfile`] per [`SeedKind`], and how template poses are seeded.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SeedProfiles {
    /// [`SeedKind::Explicit`].
    #[serde(deserialize_with = "profile::explicit")]
    pub explicit: SeedProfile,
    /// [`SeedKind::TemplatePose`].
    #[serde(deserialize_with = "profile::template")]
    pub template_pose: SeedProfile,
    /// [`SeedKind::MaskOrBox`].
    #[serde(deserialize_with = "profile::mask")]
    pub mask_or_box: SeedProfile,
    /// With a ground plane and no stereo points, a Line2D template pose seeds the fit by its
    /// image axis placed on the ground, refined as a mask seed ([`seed::template_image_axis`]),
    /// instead of by the nearest template view's distance and tilt: tubes matched within 50
    /// mm 338 -> 836 of 1425 (`docs/design/0019-line2d-seeds-by-image-axis.md`).
    ///
    /// [`seed::template_image_axis`]: crate::seed::template_image_axis
    pub template_as_image_axis: bool,
}

impl Default for SeedProfiles {
    fn default() -> Self {
        SeedProfiles { explicit: SeedProfile::EXPLICIT, template_pose: SeedProfile::TEMPLATE_POSE, mask_or_box: SeedProfile::MASK_OR_BOX, template_as_image_axis: true }
    }
}

/// Partial profile tables: each field missing from a file keeps its kind's default.
mod profile {
    use super::SeedProfile;
    use serde::{Deserialize, Deserializer};

    /// A profile table as written: any subset of the fields.
    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    struct Partial {
        depth_sigma_frac: Option<f64>,
        end_limb_weight: Option<f64>,
        keep_depth: Option<bool>,
        ground_tilt_sigma_deg: Option<f64>,
        ground_relief_sigma_m: Option<f64>,
    }

    fn with<'de, D: Deserializer<'de>>(d: D, base: SeedProfile) -> Result<SeedProfile, D::Error> {
        let p = Partial::deserialize(d)?;
        Ok(SeedProfile {
            depth_sigma_frac: p.depth_sigma_frac.unwrap_or(base.depth_sigma_frac),
            end_limb_weight: p.end_limb_weight.unwrap_or(base.end_limb_weight),
            keep_depth: p.keep_depth.unwrap_or(base.keep_depth),
            ground_tilt_sigma_deg: p.ground_tilt_sigma_deg.unwrap_or(base.ground_tilt_sigma_deg),
            ground_relief_sigma_m: p.ground_relief_sigma_m.unwrap_or(base.ground_relief_sigma_m),
        })
    }

    pub(super) fn explicit<'de, D: Deserializer<'de>>(d: D) -> Result<SeedProfile, D::Error> {
        with(d, SeedProfile::EXPLICIT)
    }

    pub(super) fn template<'de, D: Deserializer<'de>>(d: D) -> Result<SeedProfile, D::Error> {
        with(d, SeedProfile::TEMPLATE_POSE)
    }

    pub(super) fn mask<'de, D: Deserializer<'de>>(d: D) -> Result<SeedProfile, D::Error> {
        with(d, SeedProfile::MASK_OR_BOX)
    }
}

/// What a detector's mask adds to the fit of a mask seed (no template pose).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MaskUse {
    /// With a ground plane, in the fits without stereo points: the mask's axis line is a prior
    /// on the fitted axis's image direction, its ends known to this many pixels
    /// ([`crate::priors::ImageAxisPrior`]; `docs/design/0015-mask-axis-prior.md`); 0 disables.
    pub axis_sigma_px: f64,
    /// Mono: contour points more than this many pixels outside the mask are hidden (rocks or
    /// sand over the tube; `docs/design/0017-mask-agreement-and-visibility.md`); 0 disables.
    pub visibility_px: usize,
    /// A converged fit whose silhouette agrees with the mask at a lower IoU than this keeps the
    /// seed's centre and axis ([`tubeloc_core::TubeAxisPose::seed_kept`]); 0 disables.
    pub min_agreement: f64,
    /// With a colour (or grey) image: the mask's axis is turned end to end before the fit when
    /// its colours put the seal section behind it, correlation `ρ ≤ −end_colour_corr`
    /// ([`crate::seal_end::seal_end_along_axis`]; `docs/design/0016-seal-end-from-colour.md`);
    /// above 1 disables.
    pub end_colour_corr: f64,
}

impl Default for MaskUse {
    fn default() -> Self {
        MaskUse { axis_sigma_px: 0.5, visibility_px: 8, min_agreement: 0.6, end_colour_corr: 0.3 }
    }
}

impl RefineConfig {
    /// The profile of seeds of `kind`.
    pub fn profile(&self, kind: SeedKind) -> &SeedProfile {
        match kind {
            SeedKind::Explicit => &self.seeds.explicit,
            SeedKind::TemplatePose => &self.seeds.template_pose,
            SeedKind::MaskOrBox => &self.seeds.mask_or_box,
        }
    }

    /// The settings a fit of a seed of `kind` uses: the groups with that kind's profile.
    pub fn resolve(&self, kind: SeedKind) -> FitSettings {
        FitSettings { edge_search: self.edge_search, seed_search: self.seed_search, solver: self.solver, acceptance: self.acceptance, end_decision: self.end_decision, priors: self.priors, mono_depth: self.mono_depth, seed: *self.profile(kind) }
    }
}

impl RefineConfig {
    /// Reads settings from a TOML (`.toml`) or JSON (any other extension) file: any subset of
    /// the groups and fields, the rest at their defaults; unknown fields are refused. The
    /// error names the file and the field ([`RefineConfig::validate`] for values out of range).
    pub fn load(path: &std::path::Path) -> Result<RefineConfig, RefineError> {
        let config: RefineConfig = tubeloc_core::files::read_toml_or_json(path, "refine config")?;
        config.validate().map_err(|e| CoreError::parse(path, e.to_string()))?;
        Ok(config)
    }

    /// The settings as TOML text, every field written (the format [`RefineConfig::load`] reads).
    pub fn to_toml(&self) -> String {
        toml::to_string(self).expect("settings are plain numbers and flags")
    }
}
