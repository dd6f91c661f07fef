//! The overlay image: fitted contours and the chosen gripper poses drawn over the grey image.

use nalgebra::Point3;
use rayon::prelude::*;
use tubeloc_core::{CameraModel, Plane, TubeAxisPose};
use tubeloc_refine::Refiner;

/// Contour colour of a located tube.
pub const LOCATED: [u8; 3] = [40, 230, 60];
/// Contour colour of a converged fit that was rejected (probability under the threshold, or
/// interpenetrating a stronger tube): not handed to the planner.
pub const REJECTED_CONVERGED: [u8; 3] = [250, 230, 40];
/// Contour colour of a fit that did not converge.
pub const NOT_CONVERGED: [u8; 3] = [240, 40, 40];
/// Gripper outline colour of a feasible grasp.
pub const GRASP_FEASIBLE: [u8; 3] = [0, 210, 255];
/// Gripper outline colour where no grasp candidate is feasible.
pub const GRASP_INFEASIBLE: [u8; 3] = [255, 150, 0];

/// Tint of the ignored region ([`crate::LocateInput::ignore`]) on an overlay.
pub const IGNORED: [u8; 3] = [120, 80, 255];

/// Tints the grey pixels of `overlay` (those not drawn on: equal channels) that `ignore` covers
/// (non-zero), `p' = 0.65 p + 0.35 IGNORED`, so the region no tube was handed over from shows
/// under the contours. `ignore` must be the overlay's size.
pub fn tint_ignored(overlay: &mut image::RgbImage, ignore: &Plane<u8>) {
    debug_assert_eq!((overlay.width() as usize, overlay.height() as usize), (ignore.width, ignore.height));
    for (px, &m) in overlay.pixels_mut().zip(&ignore.data) {
        let [r, g, b] = px.0;
        if m != 0 && r == g && g == b {
            px.0 = std::array::from_fn(|k| (0.65 * px.0[k] as f32 + 0.35 * IGNORED[k] as f32).round() as u8);
        }
    }
}

/// An RGB copy of `gray` with each pose's fitted contour (every 0.5 px) and a 7 px cross at its
/// centre drawn, [`LOCATED`] green for converged poses and [`NOT_CONVERGED`] red for the
/// others, in order.
pub fn draw<'a>(gray: &Plane<u8>, refiner: &Refiner, cam: &CameraModel, poses: impl IntoIterator<Item = &'a TubeAxisPose>) -> image::RgbImage {
    draw_coloured(gray, refiner, cam, poses.into_iter().map(|p| (p, if p.converged { LOCATED } else { NOT_CONVERGED })))
}

/// [`draw`] with a colour per pose.
fn draw_coloured<'a>(gray: &Plane<u8>, refiner: &Refiner, cam: &CameraModel, poses: impl IntoIterator<Item = (&'a TubeAxisPose, [u8; 3])>) -> image::RgbImage {
    let (w, h) = (gray.width as u32, gray.height as u32);
    let mut rgb = vec![0u8; 3 * gray.data.len()];
    rgb.par_chunks_mut(3 << 14).zip(gray.data.par_chunks(1 << 14)).for_each(|(out, g)| out.chunks_exact_mut(3).zip(g).for_each(|(p, &v)| p.fill(v)));
    let mut img = image::RgbImage::from_raw(w, h, rgb).expect("3 bytes per pixel");
    for (p, col) in poses {
        for u in refiner.contour_pixels(cam, p, 0.5) {
            let (x, y) = (u.x.round(), u.y.round());
            if x >= 0.0 && y >= 0.0 && x < w as f64 && y < h as f64 {
                img.put_pixel(x as u32, y as u32, image::Rgb(col));
            }
        }
        if let Some(c) = cam.project(&Point3::from(p.centre)) {
            for k in -3i64..=3 {
                for (x, y) in [(c.x.round() as i64 + k, c.y.round() as i64), (c.x.round() as i64, c.y.round() as i64 + k)] {
                    if x >= 0 && y >= 0 && x < w as i64 && y < h as i64 {
                        img.put_pixel(x as u32, y as u32, image::Rgb(col));
                    }
                }
            }
        }
    }
    img
}

/// `img` encoded as PNG bytes.
pub fn png_bytes(img: &image::RgbImage) -> Result<Vec<u8>, image::ImageError> {
    use image::codecs::png::{CompressionType, FilterType, PngEncoder};
    use image::ImageEncoder;
    // Fast compression, Paeth filter: the overlay is for viewing. On a 5472x3648 overlay of
    // a rendered frame: 0.114 s and 13.9 MB, against 0.145 s and 13.9 MB with the adaptive
    // filter choice (no filter: 0.21 s, 60 MB).
    let mut buf = Vec::new();
    PngEncoder::new_with_quality(&mut buf, CompressionType::Fast, FilterType::Paeth).write_image(img.as_raw(), img.width(), img.height(), image::ExtendedColorType::Rgb8)?;
    Ok(buf)
}

/// [`draw`] for what [`crate::Locator::locate`] found: located tubes in [`LOCATED`] green,
/// rejected detections whose fit converged (low probability, interpenetration) in
/// [`REJECTED_CONVERGED`] yellow, failed fits in [`NOT_CONVERGED`] red; rejected ones drawn
/// first, so located tubes stay on top. Each checked tube's chosen gripper pose is drawn too:
/// the outlines of its fingers and palm at `grasp.t_cam_grasp`
/// ([`tubeloc_grasp::GripperModel::parts`]) projected every 1 mm along their edges, cyan for a
/// feasible grasp ([`GRASP_FEASIBLE`]), orange for none feasible ([`GRASP_INFEASIBLE`]; the
/// plain grasp drawn). Rejected tubes are not grasp-checked and get no gripper.
pub fn draw_located(gray: &Plane<u8>, refiner: &Refiner, planner: &tubeloc_grasp::GraspPlanner, cam: &CameraModel, found: &crate::LocateOutput) -> image::RgbImage {
    let rejected = found.rejected.iter().map(|r| (&r.tube.pose, if r.tube.pose.converged { REJECTED_CONVERGED } else { NOT_CONVERGED }));
    let mut img = draw_coloured(gray, refiner, cam, rejected.chain(found.tubes.iter().map(|t| (&t.pose, LOCATED))));
    let (w, h) = (img.width() as f64, img.height() as f64);
    let parts = planner.gripper().parts();
    for t in found.tubes.iter().filter(|t| t.grasp.candidates_tried > 0) {
        let col = if t.grasp.feasible { GRASP_FEASIBLE } else { GRASP_INFEASIBLE };
        for part in &parts {
            let pose = t.grasp.t_cam_grasp.0 * part.pose;
            let e = part.shape.half_extents;
            let corner = |k: usize| Point3::new(if k & 1 == 0 { -e.x } else { e.x }, if k & 2 == 0 { -e.y } else { e.y }, if k & 4 == 0 { -e.z } else { e.z });
            // The 12 edges: corner pairs that differ in one coordinate.
            for a in 0..8usize {
                for bit in [1usize, 2, 4] {
                    if a & bit != 0 {
                        continue;
                    }
                    let (p, q) = (pose * corner(a), pose * corner(a | bit));
                    let steps = ((q - p).norm() / 1e-3).ceil().max(1.0) as usize;
                    for s in 0..=steps {
                        let x = p + (q - p) * (s as f64 / steps as f64);
                        if let Some(u) = cam.project(&x) {
                            let (px, py) = (u.x.round(), u.y.round());
                            if px >= 0.0 && py >= 0.0 && px < w && py < h {
                                img.put_pixel(px as u32, py as u32, image::Rgb(col));
                            }
                        }
                    }
                }
            }
        }
    }
    img
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Grey pixels under the mask take the tint; drawn (coloured) pixels and pixels outside
    /// keep their colour.
    #[test]
    fn the_ignored_region_is_tinted_under_the_drawing() {
        let mut img = image::RgbImage::from_pixel(3, 1, image::Rgb([100, 100, 100]));
        img.put_pixel(1, 0, image::Rgb(LOCATED));
        let mask = Plane { width: 3, height: 1, data: vec![1, 1, 0] };
        tint_ignored(&mut img, &mask);
        assert_eq!(img.get_pixel(0, 0).0, [107, 93, 154]);
        assert_eq!(img.get_pixel(1, 0).0, LOCATED);
        assert_eq!(img.get_pixel(2, 0).0, [100, 100, 100]);
    }
}
