//! Range checks of [`RefineConfig`]: every numeric field must be finite and within a range
//! that a fit can use; the first field out of range is named with its value.

use crate::error::RefineError;
use crate::settings::{Acceptance, EdgeSearch, EndDecision, MaskUse, MonoDepth, Priors, RefineConfig, SeedProfile, SeedSearch, Solver};
use tubeloc_core::field_range::{check_count, check_real, Bound};

/// [`check_count`] as a [`RefineError::Config`].
fn count<T: PartialOrd + std::fmt::Display + Copy>(field: &str, v: T, lo: T, hi: T) -> Result<(), RefineError> {
    check_count(field, v, lo, hi).map_err(RefineError::Config)
}

/// [`check_real`] as a [`RefineError::Config`].
fn real(field: &str, v: f64, lo: Bound, hi: Bound) -> Result<(), RefineError> {
    check_real(field, v, lo, hi).map_err(RefineError::Config)
}

use Bound::{Closed, Open};

impl EdgeSearch {
    fn validate(&self) -> Result<(), RefineError> {
        count("edge_search.radius_px", self.radius_px, 1, 64)?;
        count("edge_search.fine_radius_px", self.fine_radius_px, 1, 64)?;
        real("edge_search.sample_spacing_px", self.sample_spacing_px, Open(0.0), Closed(100.0))?;
        count("edge_search.max_samples", self.max_samples, 16, 100_000)?;
        real("edge_search.min_gradient", self.min_gradient as f64, Closed(0.0), Closed(1.0))?;
        real("edge_search.rel_edge_strength", self.rel_edge_strength as f64, Closed(0.0), Closed(1.0))
    }
}

impl SeedSearch {
    fn validate(&self) -> Result<(), RefineError> {
        count("seed_search.radius_px", self.radius_px, 0, 256)?;
        count("seed_search.step_px", self.step_px, 1, 64)?;
        real("seed_search.rotation_deg", self.rotation_deg, Closed(0.0), Closed(90.0))?;
        real("seed_search.rotation_step_deg", self.rotation_step_deg, Open(0.0), Closed(90.0))?;
        count("seed_search.max_samples", self.max_samples, 8, 100_000)?;
        count("seed_search.max_hypotheses", self.max_hypotheses, 1, 100)
    }
}

impl Solver {
    fn validate(&self) -> Result<(), RefineError> {
        count("solver.max_levels", self.max_levels, 1, 12)?;
        real("solver.min_body_width_px", self.min_body_width_px, Open(0.0), Closed(1000.0))?;
        count("solver.max_iterations", self.max_iterations, 1, 1000)?;
        real("solver.max_step_px", self.max_step_px, Open(0.0), Closed(100.0))?;
        real("solver.reassociate_px", self.reassociate_px, Closed(0.0), Closed(100.0))?;
        real("solver.converged_px", self.converged_px, Closed(0.0), Closed(10.0))?;
        real("solver.edge_sigma_px", self.edge_sigma_px, Open(0.0), Closed(100.0))?;
        real("solver.stereo_sigma_m", self.stereo_sigma_m, Open(0.0), Closed(1.0))?;
        real("solver.stereo_points_per_measurement", self.stereo_points_per_measurement, Closed(1.0), Closed(1e4))?;
        real("solver.axis_sigma_scale", self.axis_sigma_scale, Closed(1.0), Closed(100.0))
    }
}

impl Acceptance {
    fn validate(&self) -> Result<(), RefineError> {
        real("acceptance.inlier_px", self.inlier_px, Open(0.0), Closed(100.0))?;
        real("acceptance.min_inlier_fraction", self.min_inlier_fraction, Closed(0.0), Closed(1.0))?;
        real("acceptance.min_in_image_fraction", self.min_in_image_fraction, Closed(0.0), Closed(1.0))?;
        count("acceptance.min_samples", self.min_samples, 1, 10_000)?;
        real("acceptance.max_centre_shift_frac", self.max_centre_shift_frac, Open(0.0), Closed(10.0))?;
        real("acceptance.max_axis_change_deg", self.max_axis_change_deg, Open(0.0), Closed(180.0))
    }
}

impl EndDecision {
    fn validate(&self) -> Result<(), RefineError> {
        real("end_decision.score_scale", self.score_scale, Open(0.0), Closed(10.0))?;
        real("end_decision.override_confidence", self.override_confidence, Closed(0.5), Closed(1.0))
    }
}

impl Priors {
    fn validate(&self) -> Result<(), RefineError> {
        real("priors.ground_sigma_m", self.ground_sigma_m, Open(0.0), Closed(10.0))
    }
}

impl MonoDepth {
    fn validate(&self) -> Result<(), RefineError> {
        real("mono_depth.width_sigma_px", self.width_sigma_px, Closed(0.0), Closed(100.0))
    }
}

impl SeedProfile {
    fn validate(&self, group: &str) -> Result<(), RefineError> {
        real(&format!("{group}.depth_sigma_frac"), self.depth_sigma_frac, Open(0.0), Closed(1.0))?;
        real(&format!("{group}.end_limb_weight"), self.end_limb_weight, Closed(0.0), Closed(100.0))?;
        real(&format!("{group}.ground_tilt_sigma_deg"), self.ground_tilt_sigma_deg, Open(0.0), Closed(90.0))?;
        real(&format!("{group}.ground_relief_sigma_m"), self.ground_relief_sigma_m, Closed(0.0), Closed(10.0))
    }
}

impl MaskUse {
    fn validate(&self) -> Result<(), RefineError> {
        real("mask.axis_sigma_px", self.axis_sigma_px, Closed(0.0), Closed(100.0))?;
        count("mask.visibility_px", self.visibility_px, 0, 1000)?;
        real("mask.min_agreement", self.min_agreement, Closed(0.0), Closed(1.0))?;
        real("mask.end_colour_corr", self.end_colour_corr, Closed(0.0), Closed(10.0))
    }
}

impl RefineConfig {
    /// Checks that every numeric field is finite and in range; the error names the first field
    /// that is not (`group.field = value is out of range RANGE`).
    pub fn validate(&self) -> Result<(), RefineError> {
        self.edge_search.validate()?;
        self.seed_search.validate()?;
        self.solver.validate()?;
        self.acceptance.validate()?;
        self.end_decision.validate()?;
        self.priors.validate()?;
        self.mono_depth.validate()?;
        self.seeds.explicit.validate("seeds.explicit")?;
        self.seeds.template_pose.validate("seeds.template_pose")?;
        self.seeds.mask_or_box.validate("seeds.mask_or_box")?;
        self.mask.validate()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The message of `config`'s validation error.
    fn error(config: RefineConfig) -> String {
        config.validate().expect_err("out of range").to_string()
    }

    #[test]
    fn the_defaults_are_valid() {
        RefineConfig::default().validate().unwrap();
    }

    #[test]
    fn edge_search_errors_name_the_field_and_value() {
        let c = RefineConfig { edge_search: EdgeSearch { radius_px: 0, ..Default::default() }, ..Default::default() };
        assert_eq!(error(c), "refine config: edge_search.radius_px = 0 is out of range 1..=64");
        let c = RefineConfig { edge_search: EdgeSearch { min_gradient: f32::NAN, ..Default::default() }, ..Default::default() };
        assert_eq!(error(c), "refine config: edge_search.min_gradient = NaN is out of range [0, 1]");
    }

    #[test]
    fn seed_search_errors_name_the_field_and_value() {
        let c = RefineConfig { seed_search: SeedSearch { max_hypotheses: 0, ..Default::default() }, ..Default::default() };
        assert_eq!(error(c), "refine config: seed_search.max_hypotheses = 0 is out of range 1..=100");
        let c = RefineConfig { seed_search: SeedSearch { rotation_step_deg: 0.0, ..Default::default() }, ..Default::default() };
        assert_eq!(error(c), "refine config: seed_search.rotation_step_deg = 0 is out of range (0, 90]");
    }

    #[test]
    fn solver_errors_name_the_field_and_value() {
        let c = RefineConfig { solver: Solver { max_levels: 40, ..Default::default() }, ..Default::default() };
        assert_eq!(error(c), "refine config: solver.max_levels = 40 is out of range 1..=12");
        let c = RefineConfig { solver: Solver { stereo_sigma_m: f64::INFINITY, ..Default::default() }, ..Default::default() };
        assert_eq!(error(c), "refine config: solver.stereo_sigma_m = inf is out of range (0, 1]");
    }

    #[test]
    fn acceptance_errors_name_the_field_and_value() {
        let c = RefineConfig { acceptance: Acceptance { min_inlier_fraction: 1.5, ..Default::default() }, ..Default::default() };
        assert_eq!(error(c), "refine config: acceptance.min_inlier_fraction = 1.5 is out of range [0, 1]");
    }

    #[test]
    fn end_decision_errors_name_the_field_and_value() {
        let c = RefineConfig { end_decision: EndDecision { override_confidence: 0.4, ..Default::default() }, ..Default::default() };
        assert_eq!(error(c), "refine config: end_decision.override_confidence = 0.4 is out of range [0.5, 1]");
    }

    #[test]
    fn prior_errors_name_the_field_and_value() {
        let c = RefineConfig { priors: Priors { ground_sigma_m: 0.0, ..Default::default() }, ..Default::default() };
        assert_eq!(error(c), "refine config: priors.ground_sigma_m = 0 is out of range (0, 10]");
    }

    #[test]
    fn mono_depth_errors_name_the_field_and_value() {
        let c = RefineConfig { mono_depth: MonoDepth { width_sigma_px: -0.1, ..Default::default() }, ..Default::default() };
        assert_eq!(error(c), "refine config: mono_depth.width_sigma_px = -0.1 is out of range [0, 100]");
    }

    #[test]
    fn seed_profile_errors_name_the_profile_field_and_value() {
        let mut c = RefineConfig::default();
        c.seeds.mask_or_box.ground_tilt_sigma_deg = 0.0;
        assert_eq!(error(c), "refine config: seeds.mask_or_box.ground_tilt_sigma_deg = 0 is out of range (0, 90]");
        let mut c = RefineConfig::default();
        c.seeds.template_pose.depth_sigma_frac = f64::NAN;
        assert_eq!(error(c), "refine config: seeds.template_pose.depth_sigma_frac = NaN is out of range (0, 1]");
    }

    #[test]
    fn mask_errors_name_the_field_and_value() {
        let c = RefineConfig { mask: MaskUse { min_agreement: -1.0, ..Default::default() }, ..Default::default() };
        assert_eq!(error(c), "refine config: mask.min_agreement = -1 is out of range [0, 1]");
    }
}
