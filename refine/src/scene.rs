//! What the fit knows of the scene besides the image: depth map, stereo points, ground plane,
//! the detector's mask and image axis ([`Scene`]).

use crate::priors::ImageAxisPrior;
use crate::seed::GroundPlane;
use nalgebra::Point3;
use tubeloc_core::{BinaryMask, CameraModel, MaskWindow, Plane};

/// Optional scene information for visibility and the stereo term.
#[derive(Clone, Copy, Debug, Default)]
pub struct Scene<'a> {
    /// Depth map (Z in metres along the optical axis, ≤ 0 or non-finite = unknown) of the full
    /// image and its camera; contour points behind the depth surface are occluded.
    pub depth: Option<(&'a Plane<f32>, &'a CameraModel)>,
    /// 3D points (camera frame, metres) triangulated in the detection's region.
    pub stereo_points: &'a [Point3<f64>],
    /// Ground plane the tube rests on (camera frame): adds the centre-height and axis-parallel
    /// priors (`priors.ground_sigma_m`, the seed profile's `ground_tilt_sigma_deg`).
    pub ground: Option<GroundPlane>,
    /// Mask-agreement mode: the detection's mask (full image) and the full-resolution camera.
    /// When given, each silhouette sample is associated with the mask's boundary along its
    /// normal (the last inside → outside transition within the search radius) instead of image
    /// edges: the fit then makes the projected silhouette agree with the mask.
    pub mask: Option<(&'a BinaryMask, &'a CameraModel)>,
    /// The detector's image axis as a prior on the axis's direction in the image
    /// ([`crate::priors::ImageAxisPrior`]; mask seeds, `mask.axis_sigma_px`).
    pub image_axis: Option<ImageAxisPrior>,
    /// The part of the image where the detector's mask shows the tube (the mask grown by
    /// `mask.visibility_px`) and the full-resolution camera: contour points that
    /// project inside the image but outside it are hidden (by rocks or sand) and are not
    /// associated with edges.
    pub shown: Option<(&'a MaskWindow, &'a CameraModel)>,
}

/// The image-axis prior of a fit: `Scene::image_axis`, in fits without stereo points only. In
/// the stereo fit it traded position for axis (calibration stereo set: perpendicular p90 4.12
/// -> 4.54 mm); the stereo edge polish, which keeps the stereo distance, fits without the
/// points and uses it (axis p90 2.85 -> 2.19 deg).
pub(crate) fn image_axis_prior<'s>(scene: &'s Scene) -> Option<&'s ImageAxisPrior> {
    scene.image_axis.as_ref().filter(|_| scene.stereo_points.is_empty())
}
