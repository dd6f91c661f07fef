//! Per-seed-kind settings: detector seeds are worse than the explicit seeds the defaults of
//! [`RefineConfig`] are tuned for, in different ways per detector, so a few fit settings
//! depend on where the seed came from ([`SeedKind`], [`SeedSettings`]). The values live in
//! [`RefineConfig`] (its `detection_*` and `mask_seed_*` fields, so that config files stay
//! flat); this module says which apply to which kind, and why.

use crate::RefineConfig;
use tubeloc_core::TubeDetection;

/// Where a seed came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SeedKind {
    /// An explicit seed ([`crate::Refiner::refine_seed`]): e.g. a perturbed exact pose; the
    /// configured settings apply unchanged.
    Explicit,
    /// A detector's full pose (Line2D template pose, [`TubeDetection::t_cam_tube`]): a coarse
    /// distance (template scale) and tilt, ends possibly flipped.
    TemplatePose,
    /// A mask or box seed (learned segmenter's mask axis, or a box; no template pose): a good
    /// image axis, a distance off by centimetres (ground plane or mask width), an axis parallel
    /// to the ground.
    MaskOrBox,
}

impl SeedKind {
    /// The kind of a detection's seed: a template pose when it carries `t_cam_tube`.
    pub fn of(det: &TubeDetection) -> Self {
        if det.t_cam_tube.is_some() {
            SeedKind::TemplatePose
        } else {
            SeedKind::MaskOrBox
        }
    }
}

/// The fit settings that differ by [`SeedKind`] (each overrides the [`RefineConfig`] field of
/// the same meaning, see [`SeedSettings::config`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SeedSettings {
    /// `mono_depth_sigma_frac`. Detector seeds: `detection_depth_sigma_frac` (3 %; template
    /// distances are off by ~1 % at the median, and the keep-depth mode would also keep a
    /// template's tilt), so tubes wider than ~10 px get the full fit.
    pub depth_sigma_frac: f64,
    /// `end_limb_weight`. Template poses: `detection_end_limb_weight` (the end sections' limbs
    /// tell a flipped template's ends apart); mask/box seeds: `mask_seed_end_limb_weight` (the
    /// limbs' shading bias outweighs that).
    pub end_limb_weight: f64,
    /// Always fit in the mono keep-depth mode (`mono_width_sigma_px` = ∞). Mask/box seeds:
    /// `mask_seed_keep_depth` (the limbs' separation is biased by shading, and a wrong distance
    /// made the fit tilt the axis to match the foreshortened length).
    pub keep_depth: bool,
    /// `mono_length_depth`. Mask/box seeds: `mask_seed_length_depth` (off: the end outlines are
    /// often hidden by rocks or sand).
    pub length_depth: bool,
    /// `ground_relief_sigma_m`. Mask/box seeds: `mask_seed_relief_sigma_m` when positive (once
    /// the fit moved the centre in the image, re-placing it at the ground height along its new
    /// ray beats keeping the seed's distance, which came from the ground at the mask centre).
    pub relief_sigma_m: f64,
    /// `ground_tilt_sigma_deg`. Mask/box seeds with a ground plane: `mask_seed_tilt_sigma_deg`
    /// (the seed's axis lies parallel to the ground, while its distance is off, so a fitted tilt
    /// would follow the wrong foreshortened length).
    pub ground_tilt_sigma_deg: f64,
}

impl SeedSettings {
    /// The settings of seeds of `kind` under `config`; `has_ground`: a ground plane is given.
    pub fn new(config: &RefineConfig, kind: SeedKind, has_ground: bool) -> Self {
        let c = config;
        let explicit =
            SeedSettings { depth_sigma_frac: c.mono_depth_sigma_frac, end_limb_weight: c.end_limb_weight, keep_depth: false, length_depth: c.mono_length_depth, relief_sigma_m: c.ground_relief_sigma_m, ground_tilt_sigma_deg: c.ground_tilt_sigma_deg };
        match kind {
            SeedKind::Explicit => explicit,
            SeedKind::TemplatePose => SeedSettings { depth_sigma_frac: c.detection_depth_sigma_frac, end_limb_weight: c.detection_end_limb_weight, ..explicit },
            SeedKind::MaskOrBox => SeedSettings {
                depth_sigma_frac: c.detection_depth_sigma_frac,
                end_limb_weight: c.mask_seed_end_limb_weight,
                keep_depth: c.mask_seed_keep_depth,
                length_depth: c.mask_seed_length_depth,
                relief_sigma_m: if c.mask_seed_relief_sigma_m > 0.0 { c.mask_seed_relief_sigma_m } else { c.ground_relief_sigma_m },
                ground_tilt_sigma_deg: if has_ground { c.mask_seed_tilt_sigma_deg } else { c.ground_tilt_sigma_deg },
            },
        }
    }

    /// `base` with these settings in place of its fields.
    pub fn config(&self, base: &RefineConfig) -> RefineConfig {
        RefineConfig {
            mono_depth_sigma_frac: self.depth_sigma_frac,
            end_limb_weight: self.end_limb_weight,
            mono_width_sigma_px: if self.keep_depth { f64::INFINITY } else { base.mono_width_sigma_px },
            mono_length_depth: self.length_depth,
            ground_relief_sigma_m: self.relief_sigma_m,
            ground_tilt_sigma_deg: self.ground_tilt_sigma_deg,
            ..base.clone()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn explicit_seeds_keep_the_configuration() {
        let c = RefineConfig { mono_length_depth: true, ground_relief_sigma_m: 0.02, ..RefineConfig::default() };
        assert_eq!(SeedSettings::new(&c, SeedKind::Explicit, true).config(&c), c);
    }

    #[test]
    fn detector_seeds_take_their_settings() {
        let c = RefineConfig::default();
        let t = SeedSettings::new(&c, SeedKind::TemplatePose, true).config(&c);
        assert_eq!((t.mono_depth_sigma_frac, t.end_limb_weight), (c.detection_depth_sigma_frac, c.detection_end_limb_weight));
        assert_eq!((t.mono_width_sigma_px, t.ground_tilt_sigma_deg), (c.mono_width_sigma_px, c.ground_tilt_sigma_deg));
        let m = SeedSettings::new(&c, SeedKind::MaskOrBox, true).config(&c);
        assert_eq!((m.end_limb_weight, m.ground_tilt_sigma_deg, m.ground_relief_sigma_m), (c.mask_seed_end_limb_weight, c.mask_seed_tilt_sigma_deg, c.mask_seed_relief_sigma_m));
        assert!(m.mono_width_sigma_px.is_infinite());
        // Without a ground plane the tilt prior is the configured one.
        assert_eq!(SeedSettings::new(&c, SeedKind::MaskOrBox, false).ground_tilt_sigma_deg, c.ground_tilt_sigma_deg);
    }
}
