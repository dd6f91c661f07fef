//! Settings by seed kind: detector seeds are worse than the explicit seeds the defaults are
//! tuned for, in different ways per detector, so a few fit settings depend on where the seed
//! came from ([`SeedKind`]). [`crate::RefineConfig::seeds`] holds one
//! [`crate::settings::SeedProfile`] per kind; [`crate::RefineConfig::resolve`] combines the
//! groups with one profile into the [`FitSettings`] a fit reads. A [`crate::Refiner`] resolves
//! the three kinds once, when it is built.

use crate::settings::{Acceptance, EdgeSearch, EndDecision, MonoDepth, Priors, SeedProfile, SeedSearch, Solver};
use tubeloc_core::TubeDetection;

/// Where a seed came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SeedKind {
    /// An explicit seed ([`crate::Refiner::refine_seed`]): e.g. a perturbed exact pose.
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
    /// Every kind, in the order of [`SeedKind::index`].
    pub const ALL: [SeedKind; 3] = [SeedKind::Explicit, SeedKind::TemplatePose, SeedKind::MaskOrBox];

    /// The kind of a detection's seed: a template pose when it carries `t_cam_tube`.
    pub fn of(det: &TubeDetection) -> Self {
        if det.t_cam_tube.is_some() {
            SeedKind::TemplatePose
        } else {
            SeedKind::MaskOrBox
        }
    }

    /// Position in [`SeedKind::ALL`].
    pub fn index(self) -> usize {
        self as usize
    }
}

/// What one fit reads: the setting groups of [`crate::RefineConfig`] with the profile of the
/// seed's kind in place of the per-kind choices.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FitSettings {
    /// [`crate::RefineConfig::edge_search`].
    pub edge_search: EdgeSearch,
    /// [`crate::RefineConfig::seed_search`].
    pub seed_search: SeedSearch,
    /// [`crate::RefineConfig::solver`].
    pub solver: Solver,
    /// [`crate::RefineConfig::acceptance`].
    pub acceptance: Acceptance,
    /// [`crate::RefineConfig::end_decision`].
    pub end_decision: EndDecision,
    /// [`crate::RefineConfig::priors`].
    pub priors: Priors,
    /// [`crate::RefineConfig::mono_depth`].
    pub mono_depth: MonoDepth,
    /// The seed kind's profile.
    pub seed: SeedProfile,
}

impl FitSettings {
    /// Half length of the edge search at the finer levels, pixels: the fine radius, at most
    /// the coarsest level's.
    pub fn fine_radius_px(&self) -> usize {
        self.edge_search.fine_radius_px.min(self.edge_search.radius_px)
    }
}

#[cfg(test)]
mod tests {
    use crate::settings::SeedProfile;
    use crate::{RefineConfig, SeedKind};

    #[test]
    fn each_kind_resolves_to_its_profile() {
        let mut c = RefineConfig::default();
        c.seeds.explicit.ground_relief_sigma_m = 0.02;
        let r = c.resolve(SeedKind::Explicit);
        assert_eq!((r.seed, r.solver, r.priors), (c.seeds.explicit, c.solver, c.priors));
        assert_eq!(c.resolve(SeedKind::TemplatePose).seed, SeedProfile::TEMPLATE_POSE);
        let m = c.resolve(SeedKind::MaskOrBox).seed;
        assert_eq!((m.keep_depth, m.ground_tilt_sigma_deg, m.ground_relief_sigma_m, m.end_limb_weight), (true, 0.1, 0.001, 0.0));
    }
}
