//! Settings of a [`crate::Locator`] run: the refiner's, the stereo matcher's and those of the
//! stages after the fit.

use tubeloc_core::{PoseEvidence, ScoreCalibration, TubeModel};
use tubeloc_grasp::{GripperModel, PlannerSettings};
use tubeloc_refine::silhouette::MaskSnap;
use tubeloc_refine::two_view::TwoViewConfig;
use tubeloc_refine::RefineConfig;

/// Everything a [`crate::Locator`] is tuned by. `Default` gives the shipped defaults (those of
/// `tubeloc locate` and `tubeloc refine`). New settings (e.g. a working scale for detection, or
/// a tube-probability threshold) are added as fields with defaults; the struct is
/// `#[non_exhaustive]`, so build it with `LocatorSettings::default()` and assign fields.
#[derive(Clone, Debug)]
#[non_exhaustive]
pub struct LocatorSettings {
    /// The refiner's configuration (the cylinder fit).
    pub refine: RefineConfig,
    /// The tube model (default: the built-in model of `data/tube.toml`).
    pub tube: TubeModel,
    /// Decide which end is the seal end from the image's colours where the fitted pose shows
    /// enough of both sections (`tubeloc_refine::seal_end`); `false`: from the edges only.
    pub colour_ends: bool,
    /// Stereo matching and the stages after the fit.
    pub stages: StageSettings,
    /// Merge converged poses of the same physical tube ([`tubeloc_refine::duplicates`]) in
    /// [`crate::Locator::locate`] (Line2D fires several times on one tube).
    pub merge_duplicates: bool,
    /// Score calibration: each tube's probability of being a tube, and the threshold below
    /// which a converged tube is rejected (`low_probability`) instead of handed to the planner.
    /// Default: the identity with threshold 0 (every converged tube accepted); `tubeloc
    /// locate` loads the one fitted for its model.
    pub calibration: ScoreCalibration,
    /// The gripper whose grasps are checked for collisions (default: the built-in model of
    /// `data/gripper.toml`).
    pub gripper: GripperModel,
    /// How grasp candidates are sampled, checked and ranked, and the tube-tube overlap
    /// tolerance ([`tubeloc_grasp::PlannerSettings`]).
    pub grasp: PlannerSettings,
    /// The least highlight level ([`crate::highlight_level`], the 99th percentile of the
    /// frame's 8-bit grey levels) a frame's tubes are handed to the planner from: in a darker
    /// (underexposed) frame, converged tubes are rejected as `underexposed`. Default 48; 0
    /// disables.
    pub min_highlight_level: f64,
    /// The pose evidence of the detector's model ([`PoseEvidence`]: the probability that a
    /// refined pose is a tube from the detector's score and the fit's evidence). With it, a
    /// converged tube that passes the calibration's threshold is handed over only where its
    /// pose evidence reaches [`LocatorSettings::min_pose_evidence`] (else `weak_pose_evidence`).
    /// Default `None` (no such check); `tubeloc locate` loads the one fitted for the learned
    /// model ([`crate::shipped::locator_pose_evidence`]).
    pub pose_evidence: Option<PoseEvidence>,
    /// The least pose evidence of a handed-over tube, with [`LocatorSettings::pose_evidence`].
    /// Default [`DEFAULT_MIN_POSE_EVIDENCE`]; 0 disables.
    pub min_pose_evidence: f64,
    /// The largest limb continuation of a handed-over tube
    /// ([`tubeloc_refine::limb_continuation`]: how strongly the edges along a converged tube's
    /// limbs go on past its ends, against along its body; a slab rim or a layer of bedrock goes
    /// on, a tube ends). A converged tube that passes the calibration's threshold and the pose
    /// evidence but continues more is listed as `limbs_continue`. Default
    /// [`DEFAULT_MAX_LIMB_CONTINUATION`]; `None` disables.
    pub max_limb_continuation: Option<f64>,
}

/// Default [`LocatorSettings::min_pose_evidence`]: the largest floor in steps of 0.1 that drops
/// no true tube `locate` hands over on the real validation composites (lowest true tube 0.31;
/// 5 of 12 false ones and 1 of the 3 false tubes on 101 tube-free validation frames lie below
/// it; `docs/design/0078-pose-evidence-floor.md`).
pub const DEFAULT_MIN_POSE_EVIDENCE: f64 = 0.3;

/// Default [`LocatorSettings::max_limb_continuation`]: the smallest cut in steps of 0.1 that
/// drops at most 1 % of the true tubes `locate` hands over on the real validation composites
/// (4 of 462; 4 of the 7 false ones and 1 of the 2 false tubes on 101 tube-free validation
/// frames lie above it; `docs/design/0080-limb-continuation.md`).
pub const DEFAULT_MAX_LIMB_CONTINUATION: f64 = 0.6;

/// Default [`LocatorSettings::min_highlight_level`]: near the geometric mean of the darkest
/// well-exposed real frame of the shared data as tubeloc reads it (81) and the underexposed
/// rear Hazcam frame (25; `docs/design/0062-underexposed-frames.md`).
pub const DEFAULT_MIN_HIGHLIGHT_LEVEL: f64 = 48.0;

impl LocatorSettings {
    /// Checks the cuts `locate` applies after the fit: the pose-evidence floor a probability,
    /// the limb cut a positive number, the highlight level a grey level in `[0, 255]`. The error
    /// names the field and its value ([`crate::Locator::new`] refuses such settings).
    pub fn validate_cuts(&self) -> Result<(), String> {
        if !(0.0..=1.0).contains(&self.min_pose_evidence) {
            return Err(format!("min_pose_evidence = {}: expected a probability in [0, 1]", self.min_pose_evidence));
        }
        if let Some(c) = self.max_limb_continuation.filter(|c| !(c.is_finite() && *c > 0.0)) {
            return Err(format!("max_limb_continuation = {c}: expected a positive number (None for no such check)"));
        }
        if !(0.0..=255.0).contains(&self.min_highlight_level) {
            return Err(format!("min_highlight_level = {}: expected a grey level in [0, 255]", self.min_highlight_level));
        }
        Ok(())
    }
}

impl Default for LocatorSettings {
    fn default() -> Self {
        LocatorSettings {
            refine: RefineConfig::default(),
            tube: TubeModel::default(),
            colour_ends: true,
            stages: StageSettings::default(),
            merge_duplicates: true,
            calibration: ScoreCalibration { threshold: 0.0, ..ScoreCalibration::identity() },
            gripper: GripperModel::default(),
            grasp: PlannerSettings::default(),
            min_highlight_level: DEFAULT_MIN_HIGHLIGHT_LEVEL,
            pose_evidence: None,
            min_pose_evidence: DEFAULT_MIN_POSE_EVIDENCE,
            max_limb_continuation: Some(DEFAULT_MAX_LIMB_CONTINUATION),
        }
    }
}

/// Settings of stereo matching and of the stages after the fit (see
/// [`crate::stages::after_fit`] for their order). In a settings file (`tubeloc refine
/// --config`, [`load_settings_file`]) they are the `[stages]` table, with `[stages.two_view]`
/// and `[stages.snap]`; missing fields keep their defaults, unknown ones are refused.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
#[non_exhaustive]
pub struct StageSettings {
    /// Number of disparities searched by SGM (multiple of 16); the window starts at the
    /// disparity of the farthest seed + 0.5 m.
    pub disparities: usize,
    /// Erode each detection mask by this many pixels before keeping its stereo points.
    pub stereo_erode_px: usize,
    /// With stereo and a ground plane, move each tube's plane to the matched terrain beside it
    /// ([`tubeloc_refine::local_ground`]).
    pub local_ground: bool,
    /// Stereo: leave out contour points (and photometric pixels) whose SGM scene depth lies in
    /// front of the cylinder (rocks or sand over the tube).
    pub scene_occlusion: bool,
    /// Stereo: anchor tubes of mask seeds with one end hidden at their visible end
    /// ([`tubeloc_refine::hidden_end`]).
    pub hidden_end: bool,
    /// Stereo photometric stage: search range along the viewing rays, millimetres (0 disables
    /// the photometric / rims / two-view stage).
    pub photo_range_mm: f64,
    /// Photometric stage: least ZNCC for its depth to be applied.
    pub photo_min_zncc: f64,
    /// Photometric stage: move only the centre along its ray (otherwise each end moves along
    /// its own ray when there is no ground plane).
    pub photo_centre_only: bool,
    /// Rims stage: only for axes whose image direction lies within this angle of the epipolar
    /// lines, degrees (90: all; 0: never).
    pub rim_max_epipolar_deg: f64,
    /// The last stereo stage, the fit of the whole contour in both rectified views; `None`
    /// turns it off.
    pub two_view: Option<TwoViewConfig>,
    /// Uncertainty (pixels along the axis) of a visible end that anchors a tube, in the
    /// centre's along-axis widening over the unseen part of the tube
    /// ([`tubeloc_refine::hidden_end::unseen_length_variance`]).
    pub unseen_anchor_px: f64,
    /// How masks are snapped to their fitted silhouettes ([`crate::stages::snapped_detection`]).
    pub snap: MaskSnap,
}

impl StageSettings {
    /// Checks every value: finite, in range. The error names the field and its value.
    pub fn validate(&self) -> Result<(), String> {
        let bad = |field: &str, value: &dyn std::fmt::Display, want: &str| Err(format!("stages.{field} = {value}: {want}"));
        if self.disparities == 0 || self.disparities % 16 != 0 || self.disparities > 4096 {
            return bad("disparities", &self.disparities, "expected a positive multiple of 16, at most 4096");
        }
        if self.stereo_erode_px > 64 {
            return bad("stereo_erode_px", &self.stereo_erode_px, "expected at most 64");
        }
        if !(self.photo_range_mm.is_finite() && (0.0..=1000.0).contains(&self.photo_range_mm)) {
            return bad("photo_range_mm", &self.photo_range_mm, "expected 0..=1000 (0 turns the stage off)");
        }
        if !(self.photo_min_zncc.is_finite() && (-1.0..=1.0).contains(&self.photo_min_zncc)) {
            return bad("photo_min_zncc", &self.photo_min_zncc, "expected a correlation in [-1, 1]");
        }
        if !(self.rim_max_epipolar_deg.is_finite() && (0.0..=90.0).contains(&self.rim_max_epipolar_deg)) {
            return bad("rim_max_epipolar_deg", &self.rim_max_epipolar_deg, "expected degrees in [0, 90]");
        }
        if !(self.unseen_anchor_px.is_finite() && self.unseen_anchor_px > 0.0) {
            return bad("unseen_anchor_px", &self.unseen_anchor_px, "expected a positive number of pixels");
        }
        if !(self.snap.min_agreement.is_finite() && (0.0..=1.0).contains(&self.snap.min_agreement)) {
            return bad("snap.min_agreement", &self.snap.min_agreement, "expected an IoU in [0, 1]");
        }
        if !(self.snap.kept_seed_max_width_px.is_finite() && self.snap.kept_seed_max_width_px >= 0.0) {
            return bad("snap.kept_seed_max_width_px", &self.snap.kept_seed_max_width_px, "expected a width in pixels >= 0");
        }
        if let Some(t) = &self.two_view {
            t.validate().map_err(|e| format!("stages.two_view: {e}"))?;
        }
        Ok(())
    }
}

/// Reads a settings file (`tubeloc refine --config`): TOML (`.toml`) or JSON (any other
/// extension) holding any of the refiner's groups ([`RefineConfig`]: `edge_search`,
/// `seed_search`, `solver`, `acceptance`, `end_decision`, `priors`, `mono_depth`, `seeds`,
/// `mask`) and the `stages` table ([`StageSettings`]). Missing groups and fields keep their
/// defaults; unknown ones are refused; the error names the file and the field.
pub fn load_settings_file(path: &std::path::Path) -> Result<(RefineConfig, StageSettings), tubeloc_core::CoreError> {
    use tubeloc_core::CoreError;
    let mut doc: serde_json::Value = tubeloc_core::files::read_toml_or_json(path, "settings")?;
    let Some(table) = doc.as_object_mut() else { return Err(CoreError::parse(path, "invalid settings: expected a table of groups")) };
    let stages = match table.remove("stages") {
        Some(v) => serde_json::from_value::<StageSettings>(v).map_err(|e| CoreError::parse(path, format!("invalid settings: stages: {e}")))?,
        None => StageSettings::default(),
    };
    let refine: RefineConfig = serde_json::from_value(doc).map_err(|e| CoreError::parse(path, format!("invalid settings: {e}")))?;
    refine.validate().map_err(|e| CoreError::parse(path, e.to_string()))?;
    stages.validate().map_err(|e| CoreError::parse(path, e))?;
    Ok((refine, stages))
}

impl Default for StageSettings {
    fn default() -> Self {
        StageSettings {
            disparities: 256,
            stereo_erode_px: 0,
            local_ground: true,
            scene_occlusion: true,
            hidden_end: true,
            photo_range_mm: 30.0,
            photo_min_zncc: 0.5,
            photo_centre_only: false,
            rim_max_epipolar_deg: 90.0,
            two_view: Some(TwoViewConfig::default()),
            unseen_anchor_px: 3.0,
            snap: MaskSnap::default(),
        }
    }
}
