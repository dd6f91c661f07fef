//! From a detection to the seed and scene its fit starts from ([`crate::Refiner::refine`]): a
//! template pose taken by its image axis, a mask axis turned to its seal end by colour, and what
//! the mask adds to the scene (image-axis prior, visible region).

use crate::priors::ImageAxisPrior;
use crate::refiner::{RefineInput, Refiner};
use crate::seal_end::{self, ColourImage};
use crate::seed::{self, Seed};
use tubeloc_core::{AxisSeed, BoundedMask, MaskWindow, TubeDetection};

/// The colour image and the detection's mask for the colour end decision ([`seal_end`]).
#[derive(Clone, Copy)]
pub(crate) struct EndColour<'a> {
    /// The image's colours.
    pub image: &'a ColourImage<'a>,
    /// The detection's mask (pixels where the tube is visible), if any.
    pub visible: Option<&'a BoundedMask>,
}

/// The detection with its template pose replaced by the pose's image axis
/// ([`seed::template_image_axis`]) where
/// [`crate::settings::SeedProfiles::template_as_image_axis`] applies: a template pose, a ground
/// plane in `input`, no stereo points.
pub(crate) fn template_as_image_axis(refiner: &Refiner, input: &RefineInput, det: &TubeDetection) -> Option<TubeDetection> {
    let applies = refiner.config().seeds.template_as_image_axis && input.ground.is_some() && input.scene.stereo_points.is_empty();
    applies.then(|| seed::template_image_axis(det, input.camera, &refiner.model)).flatten()
}

/// `det` with its mask axis turned end to end when the colours of `image` under `mask` (the
/// detection's, decoded) put the seal end behind it: correlation `ρ ≤ −min_corr`
/// ([`crate::settings::MaskUse::end_colour_corr`]); `None` keeps `det` (no colour image or
/// mask, a template pose, no axis seed, too little colour evidence, or the axis already points
/// to the seal end).
pub(crate) fn turned_by_colour(min_corr: f64, det: &TubeDetection, mask: Option<&BoundedMask>, image: Option<&ColourImage>) -> Option<TubeDetection> {
    let (mask, image) = (mask?, image?);
    if det.t_cam_tube.is_some() {
        return None;
    }
    let ax = det.axis_seed?;
    let rho = seal_end::seal_end_along_axis(mask, &ax, image)?;
    (rho <= -min_corr).then(|| {
        let [dx, dy] = ax.direction_px;
        TubeDetection { axis_seed: Some(AxisSeed { direction_px: [-dx, -dy], ..ax }), ..det.clone() }
    })
}

/// What a detection's mask adds to the scene of its fit (mask seeds only, no template pose):
/// with a ground plane, the mask's axis line as a prior on the fitted axis's image direction
/// (used by the fits without stereo points: mono, and the stereo edge polish); in mono, the
/// mask grown by [`crate::settings::MaskUse::visibility_px`] as the visible region.
pub(crate) fn mask_scene(refiner: &Refiner, input: &RefineInput, det: &TubeDetection, mask: Option<&BoundedMask>, seed: &Seed) -> (Option<ImageAxisPrior>, Option<MaskWindow>) {
    let use_mask = &refiner.config().mask;
    let has_ground = input.ground.is_some() || input.scene.ground.is_some();
    let image_axis = match (&det.axis_seed, mask, det.t_cam_tube.is_none() && has_ground) {
        (Some(ax), Some(_), true) => ImageAxisPrior::from_image_line(input.camera, ax.centre_px, ax.direction_px, use_mask.axis_sigma_px, refiner.model.length, seed.state.c.norm()),
        _ => None,
    };
    let mono_mask = det.t_cam_tube.is_none() && input.scene.stereo_points.is_empty() && use_mask.visibility_px > 0;
    let of_image = |m: &&BoundedMask| m.width == input.camera.width as usize && m.height == input.camera.height as usize;
    let shown = mask.filter(|_| mono_mask).filter(of_image).map(|m| m.dilated_window(use_mask.visibility_px));
    (image_axis, shown)
}
