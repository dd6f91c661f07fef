//! The fitted tube's silhouette as a mask, and masks snapped to it.
//!
//! A segmenter's mask is only as sharp as its output stride: the learned one's limbs wander by
//! ±3 px on 15-20 px wide tubes, which caps its mask IoU near 0.7. A refined pose projects to
//! a silhouette whose limbs sit on the image edges, so the mask can take its outline from the
//! pose and only its visibility (which parts of the tube the scene hides) from the segmenter:
//!
//! `snapped = silhouette ∩ dilate(segmenter mask, r)`, kept when `IoU(snapped, mask) ≥ τ`.
//!
//! The silhouette is the set of pixel centres whose viewing ray meets the solid cylinder
//! stack ([`CylinderModel::occludes`], exact), so it follows the camera's distortion and the
//! wider foot and seal sections.

use crate::model::CylinderModel;
use nalgebra::{Point2, Point3};
use tubeloc_core::{BinaryMask, BoundedMask, CameraModel, TubeAxisPose};

/// Settings of [`snap_mask`].
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MaskSnap {
    /// The silhouette is kept only within this many pixels (L1, 4-neighbour steps,
    /// [`BinaryMask::dilated`]) of the
    /// segmenter's mask: the segmenter decides which parts of the tube are visible.
    pub dilate_px: usize,
    /// Least IoU between the snapped mask and the segmenter's for the snap to be used; below
    /// it the pose is taken to disagree with the mask (a wrong fit) and the mask is kept.
    pub min_agreement: f64,
    /// Masks that are not snapped (no converged pose, or one that disagrees) are eroded by this
    /// many pixels (4-neighbour steps, [`BinaryMask::eroded_within_image`]: the image border
    /// does not erode), since the segmenter's stride-4 masks are wider than the tube; see
    /// [`trim_kept_mask`].
    pub kept_erode_px: usize,
    /// Masks of fewer pixels than this are not snapped (they are trimmed like the masks that
    /// disagree): a tube that shows this little (cut by the image border, mostly buried, or far)
    /// constrains its fit too weakly for the silhouette to beat the segmenter's outline.
    pub min_area_px: u64,
    /// A pose that kept its detector seed ([`TubeAxisPose::seed_kept`]) is snapped, to the
    /// seed's silhouette, only when the tube's body is narrower than this in the image,
    /// pixels (`2 r f_x / z`): two cells of the segmenter's stride-4 output, below which its
    /// masks are too narrow for the fitted silhouette to agree with them and the seed was kept
    /// for that reason (`docs/design/0051-verifier-features-and-seed-keeping-on-real-grey.md`).
    /// 0: kept seeds are never snapped.
    pub kept_seed_max_width_px: f64,
}

impl Default for MaskSnap {
    /// `r = 8 px`, `τ = 0.3`, no erosion of the masks that are not snapped, no least area:
    /// chosen on the real validation composites (`docs/design/0048-mask-snapping-on-real-frames.md`),
    /// the shipped model's masks snapped to mono-refined poses, by the mean of segm AP50 and AR
    /// over the grey (`val_grey11`, Navcam frames with their PDS geometry, tubes 4-7 px wide) and
    /// colour (`val_colour12`) sets, over `r` in 2-20 px, `τ` in 0.2-0.6, erosion 0 / 1 px and
    /// least areas 0 / 150 / 300 px: 0.6505 at the former defaults' `r` and `τ` with no erosion
    /// and no least area, 0.6635 at `r` 8, `τ` 0.4 (a plateau from `r` = 6 to 14 px and for `τ`
    /// up to 0.45); the network's own masks score 0.5395. The former defaults (`r` 4, `τ` 0.6,
    /// 1 px erosion, 500 px least area), chosen on rendered validation scenes, left the real
    /// composites' small masks unsnapped and eroded them: 0.4448. Once kept seeds were snapped
    /// too (`docs/design/0051-verifier-features-and-seed-keeping-on-real-grey.md`), `τ` was
    /// chosen again over 0.2-0.5 with `r` in 6-12 px: 0.689 at `τ` 0.4, **0.698** at 0.3 (0.2-0.3
    /// within 0.002). Kept seeds are snapped for tubes narrower than 8 px (see
    /// [`MaskSnap::kept_seed_max_width_px`]).
    fn default() -> Self {
        MaskSnap { dilate_px: 8, min_agreement: 0.3, kept_erode_px: 0, min_area_px: 0, kept_seed_max_width_px: 8.0 }
    }
}

/// Least area (pixels) that [`trim_kept_mask`] leaves; a smaller erosion is not used.
pub const MIN_TRIMMED_AREA_PX: u64 = 10;

/// A mask that is not snapped, eroded by `snap.kept_erode_px` pixels within the image; `None`
/// when that changes nothing or leaves fewer than [`MIN_TRIMMED_AREA_PX`] pixels (the mask is
/// then kept as it is).
pub fn trim_kept_mask(mask: &BinaryMask, snap: &MaskSnap) -> Option<BinaryMask> {
    if snap.kept_erode_px == 0 {
        return None;
    }
    let eroded = mask.eroded_within_image(snap.kept_erode_px);
    (eroded.area() >= MIN_TRIMMED_AREA_PX).then_some(eroded)
}

/// The silhouette of the tube at `pose` (centre and seal-end direction, camera frame, metres)
/// in an image of `camera`: pixel `(x, y)` is set when the ray through its centre meets the
/// solid tube. Only the pixels inside the projection's bounding box (plus 2 px) are tested;
/// an empty mask when the tube is behind the camera or outside the image.
pub fn silhouette_mask(model: &CylinderModel, pose: &TubeAxisPose, camera: &CameraModel) -> BinaryMask {
    silhouette_mask_in(model, pose, camera, PixelWindow { x0: 0, y0: 0, width: camera.width as usize, height: camera.height as usize })
}

/// A window of image pixels: columns `x0..x0 + width`, rows `y0..y0 + height`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PixelWindow {
    /// First column.
    pub x0: usize,
    /// First row.
    pub y0: usize,
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
}

impl PixelWindow {
    /// The set pixels' bounding box of `mask` grown by `margin` pixels on every side, within
    /// the mask's image; `None` for an empty mask.
    pub fn around(mask: &BinaryMask, margin: usize) -> Option<PixelWindow> {
        PixelWindow::around_box(mask.bbox(), mask.width, mask.height, margin)
    }

    /// [`PixelWindow::around`] of a mask of `width x height` whose set pixels' box is `bbox`
    /// (COCO `[x, y, w, h]`).
    pub fn around_box(bbox: [f64; 4], width: usize, height: usize, margin: usize) -> Option<PixelWindow> {
        let [x, y, w, h] = bbox;
        if w == 0.0 {
            return None;
        }
        let (x0, y0) = ((x as usize).saturating_sub(margin), (y as usize).saturating_sub(margin));
        let (x1, y1) = (((x + w) as usize + margin).min(width), ((y + h) as usize + margin).min(height));
        Some(PixelWindow { x0, y0, width: x1 - x0, height: y1 - y0 })
    }
}

/// How [`silhouette_mask_raster`] decides its pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Raster {
    /// Every pixel's ray is tested (exact).
    EveryPixel,
    /// The rays of the pixels with even `x` on the even rows are tested. A pixel between two
    /// tested neighbours (left and right on an even row, above and below on an odd row) that
    /// agree takes their value; elsewhere its ray is tested. About a third of the rays for a
    /// 400 px tube; it differs from [`Raster::EveryPixel`] only where the silhouette is under
    /// 2 px thick between samples (a handful of corner pixels of a tube).
    Adaptive,
}

/// [`silhouette_mask`] within `window` only: pixel `(x, y)` of the `window.width x
/// window.height` result is image pixel `(window.x0 + x, window.y0 + y)`. Identical to
/// cropping the whole image's silhouette, at the cost of the window's pixels only.
pub fn silhouette_mask_in(model: &CylinderModel, pose: &TubeAxisPose, camera: &CameraModel, window: PixelWindow) -> BinaryMask {
    silhouette_mask_raster(model, pose, camera, window, Raster::EveryPixel)
}

/// [`silhouette_mask_in`] with the pixels decided as `raster` says.
pub fn silhouette_mask_raster(model: &CylinderModel, pose: &TubeAxisPose, camera: &CameraModel, window: PixelWindow, raster: Raster) -> BinaryMask {
    let (w, h) = (camera.width as usize, camera.height as usize);
    let mut mask = BinaryMask::new(window.width, window.height);
    let (c, a) = (pose.centre, pose.end_direction);
    let state = crate::AxisState { c, a };
    let Some(bounds) = state.bounding_points(model) else { return mask };
    let (mut x0, mut y0, mut x1, mut y1) = (f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY);
    for p in &bounds {
        let Some(u) = camera.project(&Point3::from(*p)) else { return mask };
        (x0, y0, x1, y1) = (x0.min(u.x), y0.min(u.y), x1.max(u.x), y1.max(u.y));
    }
    let clip = |v: f64, n: usize| v.clamp(0.0, n as f64 - 1.0) as usize;
    if !(x1 >= -2.0 && y1 >= -2.0 && x0 <= w as f64 + 1.0 && y0 <= h as f64 + 1.0) || window.width == 0 || window.height == 0 {
        return mask;
    }
    // The box (plus 2 px) within the image and the window, inclusive.
    let (wx1, wy1) = ((window.x0 + window.width).min(w), (window.y0 + window.height).min(h));
    if window.x0 >= wx1 || window.y0 >= wy1 {
        return mask;
    }
    let (xa, xb) = (clip((x0 - 2.0).floor(), w).max(window.x0), clip((x1 + 2.0).ceil(), w).min(wx1 - 1));
    let (ya, yb) = (clip((y0 - 2.0).floor(), h).max(window.y0), clip((y1 + 2.0).ceil(), h).min(wy1 - 1));
    if xa > xb || ya > yb {
        return mask;
    }
    // Rows are tested only within the convex hull of the projected octagonal prism that
    // circumscribes the tube (octagon radius r_max / cos 22.5°), widened by the same 2 px.
    // Pixels outside a row's span are outside the tube's silhouette.
    let hull = projected_hull(&state, model, camera);
    let span = |y: usize| match hull.as_deref().and_then(|h| hull_row_span(h, y as f64, 2.0)) {
        Some((lo, hi)) => Some((xa.max(clip(lo.floor(), w)), xb.min(clip(hi.ceil(), w)))),
        None if hull.is_some() => None,
        None => Some((xa, xb)),
    };
    let rays = PixelRays { model, camera, c, a, far: PixelRays::far(model, &c) };
    let hit = |x: usize, y: usize| rays.hit(x, y);
    let at = |x: usize, y: usize| (y - window.y0) * window.width + x - window.x0;
    match raster {
        Raster::EveryPixel => {
            for y in ya..=yb {
                let Some((xa, xb)) = span(y) else { continue };
                for x in xa..=xb {
                    mask.data[at(x, y)] = hit(x, y) as u8;
                }
            }
        }
        Raster::Adaptive => {
            // Rows above and below are used only within the window (outside it nothing is known;
            // inside it, pixels off the tested rows and spans are outside the silhouette).
            let inside_y = |y: usize| y > window.y0 && y + 1 < wy1;
            for y in (ya..=yb).filter(|y| y % 2 == 0) {
                let Some((xa, xb)) = span(y) else { continue };
                for x in (xa..=xb).filter(|x| x % 2 == 0) {
                    mask.data[at(x, y)] = hit(x, y) as u8;
                }
                for x in (xa..=xb).filter(|x| x % 2 == 1) {
                    let v = if x > xa && x < xb && mask.data[at(x - 1, y)] == mask.data[at(x + 1, y)] { mask.data[at(x - 1, y)] != 0 } else { hit(x, y) };
                    mask.data[at(x, y)] = v as u8;
                }
            }
            for y in (ya..=yb).filter(|y| y % 2 == 1) {
                let Some((xa, xb)) = span(y) else { continue };
                for x in xa..=xb {
                    let v = if inside_y(y) && mask.data[at(x, y - 1)] == mask.data[at(x, y + 1)] { mask.data[at(x, y - 1)] != 0 } else { hit(x, y) };
                    mask.data[at(x, y)] = v as u8;
                }
            }
        }
    }
    mask
}

/// The test [`silhouette_mask`] makes of each pixel it rasters, for one pose: whether the
/// viewing ray through the pixel's centre meets the solid tube.
pub struct PixelRays<'a> {
    model: &'a CylinderModel,
    camera: &'a CameraModel,
    c: nalgebra::Vector3<f64>,
    a: nalgebra::Vector3<f64>,
    far: f64,
}

impl<'a> PixelRays<'a> {
    /// The rays of `camera` against the tube at `pose`; `None` when a bounding point of the
    /// tube does not project (behind the camera), where [`silhouette_mask`] is empty.
    pub fn new(model: &'a CylinderModel, pose: &TubeAxisPose, camera: &'a CameraModel) -> Option<Self> {
        let (c, a) = (pose.centre, pose.end_direction);
        let bounds = crate::AxisState { c, a }.bounding_points(model)?;
        bounds.iter().all(|p| camera.project(&Point3::from(*p)).is_some()).then_some(PixelRays { model, camera, c, a, far: Self::far(model, &c) })
    }

    /// Distance along a unit ray beyond the whole tube centred at `c`.
    fn far(model: &CylinderModel, c: &nalgebra::Vector3<f64>) -> f64 {
        2.0 * (c.norm() + model.length)
    }

    /// Whether the ray through pixel `(x, y)` meets the solid: the segment from the camera to a
    /// point of the ray beyond the whole tube crosses the solid exactly when the ray does
    /// ([`CylinderModel::occludes`]).
    #[inline]
    pub fn hit(&self, x: usize, y: usize) -> bool {
        let d = self.camera.unproject(&Point2::new(x as f64, y as f64));
        self.model.occludes(&self.c, &self.a, &Point3::from(d * (self.far / d.norm())))
    }
}

/// The agreement that [`snap_mask`] tests, `IoU(silhouette ∩ dilate(mask, dilate_px), mask)`
/// for the tube at `pose`, computed within the mask's box grown by `dilate_px` (nothing outside
/// it counts), so it costs the mask's pixels rather than the image's, on the
/// [`Raster::Adaptive`] silhouette (within a few pixels of the exact one). `None` when the mask
/// is not of `camera`'s size; 0 for an empty mask.
pub fn mask_agreement(mask: &BoundedMask, model: &CylinderModel, pose: &TubeAxisPose, camera: &CameraModel, dilate_px: usize) -> Option<f64> {
    mask_agreement_raster(mask, model, pose, camera, dilate_px, Raster::Adaptive)
}

/// [`mask_agreement`] on the silhouette rastered as `raster` says ([`Raster::EveryPixel`]
/// gives exactly [`snap_candidate`]'s agreement with [`silhouette_mask`]).
///
/// With `m` the mask and `s` the silhouette, `s ∩ dilate(m)` meets `m` in `s ∩ m`, and adds
/// to `m` only the pixels of `s` outside `m` within `dilate_px` (L1) of it, so no dilated
/// mask is built: those pixels look for a mask pixel in their diamond.
pub fn mask_agreement_raster(mask: &BoundedMask, model: &CylinderModel, pose: &TubeAxisPose, camera: &CameraModel, dilate_px: usize, raster: Raster) -> Option<f64> {
    if mask.width != camera.width as usize || mask.height != camera.height as usize {
        return None;
    }
    let Some(win) = PixelWindow::around_box(mask.bbox(), mask.width, mask.height, dilate_px) else { return Some(0.0) };
    let sil = silhouette_mask_raster(model, pose, camera, win, raster);
    let r = dilate_px as isize;
    let near = |x: usize, y: usize| {
        (-r..=r).any(|dy| {
            let yy = y as isize + dy;
            let k = r - dy.abs();
            (0..mask.height as isize).contains(&yy) && (-k..=k).any(|dx| (0..mask.width as isize).contains(&(x as isize + dx)) && mask.data[yy as usize * mask.width + (x as isize + dx) as usize] != 0)
        })
    };
    let (mut inter, mut union) = (0u64, 0u64);
    for y in 0..win.height {
        let (mrow, srow) = (&mask.data[(win.y0 + y) * mask.width + win.x0..][..win.width], &sil.data[y * win.width..][..win.width]);
        for (x, (&m, &s)) in mrow.iter().zip(srow).enumerate() {
            if m != 0 {
                union += 1;
                inter += (s != 0) as u64;
            } else if s != 0 && near(win.x0 + x, win.y0 + y) {
                union += 1;
            }
        }
    }
    Some(if union == 0 { 0.0 } else { inter as f64 / union as f64 })
}

/// The convex hull (image pixels, Andrew's monotone chain) of the projected corners of the
/// octagonal prism circumscribing the tube at `state` (circumradius `r_max / cos 22.5°`);
/// `None` when a corner does not project.
fn projected_hull(state: &crate::AxisState, model: &CylinderModel, camera: &CameraModel) -> Option<Vec<Point2<f64>>> {
    let corners = state.prism_points(model, model.max_radius() / std::f64::consts::FRAC_PI_8.cos())?;
    let mut pts = corners.iter().map(|p| camera.project(&Point3::from(*p))).collect::<Option<Vec<_>>>()?;
    pts.sort_by(|p, q| p.x.total_cmp(&q.x).then(p.y.total_cmp(&q.y)));
    let turns_left = |o: &Point2<f64>, a: &Point2<f64>, b: &Point2<f64>| (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x) > 0.0;
    let mut hull: Vec<Point2<f64>> = Vec::with_capacity(2 * pts.len());
    // Lower chain left to right, then upper chain right to left.
    let reversed: Vec<Point2<f64>> = pts.iter().rev().copied().collect();
    for chain in [&pts, &reversed] {
        let base = hull.len();
        for p in chain {
            while hull.len() >= base + 2 && !turns_left(&hull[hull.len() - 2], &hull[hull.len() - 1], p) {
                hull.pop();
            }
            hull.push(*p);
        }
        hull.pop();
    }
    Some(hull)
}

/// The x-extent of the convex polygon `hull` within the horizontal band `|Y - y| ≤ m`, widened
/// by `m` on each side; `None` when the band misses the polygon.
fn hull_row_span(hull: &[Point2<f64>], y: f64, m: f64) -> Option<(f64, f64)> {
    let (ylo, yhi) = (y - m, y + m);
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for (i, p) in hull.iter().enumerate() {
        let q = hull[(i + 1) % hull.len()];
        let (a, b) = if p.y <= q.y { (*p, q) } else { (q, *p) };
        let (t0, t1) = (ylo.max(a.y), yhi.min(b.y));
        if t0 > t1 {
            continue;
        }
        // The edge's part within the band: its ends at t0 and t1 (a level edge: both ends).
        let xs = if b.y - a.y > 1e-12 { [t0, t1].map(|t| a.x + (b.x - a.x) * (t - a.y) / (b.y - a.y)) } else { [a.x, b.x] };
        lo = lo.min(xs[0].min(xs[1]));
        hi = hi.max(xs[0].max(xs[1]));
    }
    (lo <= hi).then_some((lo - m, hi + m))
}

/// Intersection over union of two masks of the same size (0 when both are empty).
pub fn mask_iou(a: &BinaryMask, b: &BinaryMask) -> f64 {
    let (mut inter, mut union) = (0u64, 0u64);
    for (&p, &q) in a.data.iter().zip(&b.data) {
        inter += (p != 0 && q != 0) as u64;
        union += (p != 0 || q != 0) as u64;
    }
    if union == 0 {
        0.0
    } else {
        inter as f64 / union as f64
    }
}

/// The segmenter's `mask` snapped to a fitted `silhouette` (same image size):
/// `silhouette ∩ dilate(mask, snap.dilate_px)`, or `None` when that disagrees with the mask
/// (`IoU < snap.min_agreement`), the sizes differ, it is empty, or the mask has fewer than
/// `snap.min_area_px` pixels.
pub fn snap_mask(mask: &BinaryMask, silhouette: &BinaryMask, snap: &MaskSnap) -> Option<BinaryMask> {
    if mask.area() < snap.min_area_px {
        return None;
    }
    let (snapped, agreement) = snap_candidate(mask, silhouette, snap.dilate_px)?;
    (snapped.area() > 0 && agreement >= snap.min_agreement).then_some(snapped)
}

/// `silhouette ∩ dilate(mask, dilate_px)` and its IoU with `mask` (the agreement that
/// [`snap_mask`] tests); `None` when the sizes differ.
pub fn snap_candidate(mask: &BinaryMask, silhouette: &BinaryMask, dilate_px: usize) -> Option<(BinaryMask, f64)> {
    if mask.width != silhouette.width || mask.height != silhouette.height {
        return None;
    }
    // The dilated mask within its own window (no image-sized copy).
    let near = mask.dilated_window(dilate_px);
    let mut snapped = BinaryMask::new(mask.width, mask.height);
    // Only the silhouette's box within the dilated window can be set, and only it and the
    // mask's box hold set pixels.
    let (sx0, sy0, sx1, sy1) = box_corners(silhouette);
    let (wx0, wy0) = (near.x0, near.y0);
    let (wx1, wy1) = (wx0 + near.mask.width, wy0 + near.mask.height);
    for y in sy0.max(wy0)..sy1.min(wy1) {
        for x in sx0.max(wx0)..sx1.min(wx1) {
            let i = y * mask.width + x;
            snapped.data[i] = (silhouette.data[i] != 0 && near.mask.data[(y - wy0) * near.mask.width + x - wx0] != 0) as u8;
        }
    }
    let (mx0, my0, mx1, my1) = box_corners(mask);
    let (x0, y0, x1, y1) = (sx0.min(mx0), sy0.min(my0), sx1.max(mx1), sy1.max(my1));
    let (mut inter, mut union) = (0u64, 0u64);
    for y in y0..y1 {
        let row = y * mask.width;
        for (&p, &q) in snapped.data[row + x0..row + x1].iter().zip(&mask.data[row + x0..row + x1]) {
            inter += (p != 0 && q != 0) as u64;
            union += (p != 0 || q != 0) as u64;
        }
    }
    let agreement = if union == 0 { 0.0 } else { inter as f64 / union as f64 };
    Some((snapped, agreement))
}

/// The set pixels' box as half-open `(x0, y0, x1, y1)`; empty `(0, 0, 0, 0)` for an empty mask.
fn box_corners(m: &BinaryMask) -> (usize, usize, usize, usize) {
    let [x, y, w, h] = m.bbox();
    (x as usize, y as usize, (x + w) as usize, (y + h) as usize)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn camera() -> CameraModel {
        CameraModel::from_hfov(640, 480, 40.0)
    }

    /// A reproducible stream of uniform numbers in [0, 1) (xorshift64 from `state`, nonzero).
    fn uniform_stream(mut state: u64) -> impl FnMut() -> f64 {
        move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    fn pose(c: Vector3<f64>, a: Vector3<f64>) -> TubeAxisPose {
        TubeAxisPose::new(0, 1.0, c, a.normalize(), 1.0).unwrap()
    }

    #[test]
    fn silhouette_of_a_plain_cylinder_across_the_view_has_its_projected_width_and_length() {
        // A 100 mm x 20 mm cylinder 1 m ahead, axis along x: 100 f / 1000 px long and
        // 20 f / 1000 px wide (to within the limb's slight widening at the ends).
        let cam = camera();
        let model = CylinderModel::plain(0.1, 0.01).unwrap();
        let m = silhouette_mask(&model, &pose(Vector3::new(0.0, 0.0, 1.0), Vector3::x()), &cam);
        let [_, _, bw, bh] = m.bbox();
        let f = cam.fx;
        assert!((bw - 0.1 * f).abs() <= 2.0, "length {bw} px, expected {:.1}", 0.1 * f);
        assert!((bh - 0.02 * f).abs() <= 2.0, "width {bh} px, expected {:.1}", 0.02 * f);
        let area = m.area() as f64;
        assert!((area / (0.1 * f * 0.02 * f) - 1.0).abs() < 0.05, "area {area}");
    }

    #[test]
    fn silhouette_behind_the_camera_or_outside_the_image_is_empty() {
        let cam = camera();
        let model = CylinderModel::plain(0.1, 0.01).unwrap();
        assert_eq!(silhouette_mask(&model, &pose(Vector3::new(0.0, 0.0, -1.0), Vector3::x()), &cam).area(), 0);
        assert_eq!(silhouette_mask(&model, &pose(Vector3::new(5.0, 0.0, 1.0), Vector3::x()), &cam).area(), 0);
    }

    #[test]
    fn snapping_a_shifted_coarse_mask_recovers_the_silhouette() {
        let cam = camera();
        let model = CylinderModel::plain(0.1, 0.01).unwrap();
        let sil = silhouette_mask(&model, &pose(Vector3::new(0.0, 0.0, 1.0), Vector3::new(1.0, 0.3, 0.0)), &cam);
        // A segmenter's mask 2 px off across the tube, 2 px too fat.
        let coarse = BinaryMask::from_fn(sil.width, sil.height, |x, y| y >= 2 && sil.get(x, y - 2)).dilated(2);
        let before = mask_iou(&coarse, &sil);
        let snapped = snap_mask(&coarse, &sil, &MaskSnap::default()).expect("agrees");
        assert!(before < 0.8, "coarse IoU {before}");
        assert!(mask_iou(&snapped, &sil) > 0.99, "snapped IoU {}", mask_iou(&snapped, &sil));
    }

    #[test]
    fn snapping_keeps_the_hidden_part_hidden_and_refuses_a_disagreeing_pose() {
        let cam = camera();
        let model = CylinderModel::plain(0.1, 0.01).unwrap();
        let sil = silhouette_mask(&model, &pose(Vector3::new(0.0, 0.0, 1.0), Vector3::x()), &cam);
        // Left half of the tube hidden (by a rock): the snapped mask stays within r of it.
        let cx = cam.cx as usize;
        let visible = BinaryMask::from_fn(sil.width, sil.height, |x, y| x > cx && sil.get(x, y));
        let snapped = snap_mask(&visible, &sil, &MaskSnap::default()).expect("agrees");
        let r = MaskSnap::default().dilate_px;
        let leak = (0..sil.height).flat_map(|y| (0..=cx.saturating_sub(r + 1)).map(move |x| (x, y))).filter(|&(x, y)| snapped.get(x, y)).count();
        assert_eq!(leak, 0, "snapped mask leaked into the hidden half");
        // A pose 30 px off: no agreement, no snap.
        let off = silhouette_mask(&model, &pose(Vector3::new(0.0, 30.0 / cam.fy, 1.0), Vector3::x()), &cam);
        assert!(snap_mask(&visible, &off, &MaskSnap::default()).is_none());
    }

    #[test]
    fn a_mask_under_the_least_area_is_not_snapped() {
        let cam = camera();
        let model = CylinderModel::plain(0.1, 0.01).unwrap();
        let sil = silhouette_mask(&model, &pose(Vector3::new(0.0, 0.0, 1.0), Vector3::new(1.0, 0.3, 0.0)), &cam);
        let coarse = sil.dilated(1);
        let area = coarse.area();
        assert!(snap_mask(&coarse, &sil, &MaskSnap { min_area_px: area, ..MaskSnap::default() }).is_some(), "a mask of exactly the least area snaps");
        assert!(snap_mask(&coarse, &sil, &MaskSnap { min_area_px: area + 1, ..MaskSnap::default() }).is_none(), "a mask one pixel short does not");
    }

    #[test]
    fn an_unsnapped_fat_mask_is_trimmed_toward_the_tube_and_a_speck_is_left_alone() {
        let cam = camera();
        let model = CylinderModel::plain(0.1, 0.01).unwrap();
        let sil = silhouette_mask(&model, &pose(Vector3::new(0.0, 0.0, 1.0), Vector3::new(1.0, 0.3, 0.0)), &cam);
        let fat = sil.dilated(1);
        let erode = MaskSnap { kept_erode_px: 1, ..MaskSnap::default() };
        let trimmed = trim_kept_mask(&fat, &erode).expect("trimmed");
        assert!(mask_iou(&trimmed, &sil) > mask_iou(&fat, &sil) + 0.1, "{} vs {}", mask_iou(&trimmed, &sil), mask_iou(&fat, &sil));
        let speck = BinaryMask::from_fn(20, 20, |x, y| (5..9).contains(&x) && (5..9).contains(&y));
        assert!(trim_kept_mask(&speck, &erode).is_none(), "a 4x4 mask erodes below the least area");
        assert!(trim_kept_mask(&fat, &MaskSnap { kept_erode_px: 0, ..MaskSnap::default() }).is_none());
    }

    /// `snap_candidate` equals its definition on whole images, `silhouette ∩ dilate(mask)`, for
    /// masks on the image border, far from the silhouette, and empty.
    #[test]
    fn snap_candidate_is_the_silhouette_within_the_dilated_mask() {
        let mut u = uniform_stream(0x5eed);
        for case in 0..60 {
            let (w, h) = (40 + (u() * 30.0) as usize, 30 + (u() * 30.0) as usize);
            let rect = |u: &mut dyn FnMut() -> f64| {
                let (x0, y0) = ((u() * w as f64) as usize, (u() * h as f64) as usize);
                let (x1, y1) = (x0 + (u() * 25.0) as usize, y0 + (u() * 12.0) as usize);
                BinaryMask::from_fn(w, h, move |x, y| (x0..x1).contains(&x) && (y0..y1).contains(&y))
            };
            let mask = if case % 10 == 0 { BinaryMask::new(w, h) } else { rect(&mut u) };
            let sil = rect(&mut u);
            for r in [0, 3, 8] {
                let near = mask.dilated(r);
                let expected = BinaryMask::from_fn(w, h, |x, y| sil.get(x, y) && near.get(x, y));
                let (snapped, agreement) = snap_candidate(&mask, &sil, r).unwrap();
                assert_eq!(snapped, expected, "case {case}, r {r}");
                let (inter, union) = (0..w * h).fold((0, 0), |(i, n), k| (i + (snapped.data[k] & mask.data[k]) as u32, n + (snapped.data[k] | mask.data[k]) as u32));
                assert_eq!(agreement, if union == 0 { 0.0 } else { inter as f64 / union as f64 });
            }
        }
    }

    /// The windowed silhouette is the crop of the whole image's, and the windowed agreement is
    /// the whole-image `snap_candidate`'s (within 0.01 on the adaptive raster): random tubes against masks shifted and fattened off
    /// their silhouettes (some cut by the image border), and windows hanging over the border.
    #[test]
    fn windowed_silhouette_and_agreement_match_the_whole_image() {
        let model = CylinderModel::new(&tubeloc_core::TubeModel::default()).unwrap();
        let cam = CameraModel::from_hfov(400, 300, 50.0);
        let mut uniform = uniform_stream(0x2545F4914F6CDD1D);
        let mut compared = 0;
        for _ in 0..40 {
            let z = 0.3 + 1.2 * uniform();
            let p = cam.unproject(&nalgebra::Point2::new((uniform() * 1.2 - 0.1) * 400.0, (uniform() * 1.2 - 0.1) * 300.0));
            let a = Vector3::new(uniform() - 0.5, uniform() - 0.5, uniform() - 0.5);
            let Ok(pose) = TubeAxisPose::new(0, 1.0, p * (z / p.z), a.normalize(), 1.0) else { continue };
            let full = silhouette_mask(&model, &pose, &cam);
            let win = PixelWindow { x0: (uniform() * 380.0) as usize, y0: (uniform() * 280.0) as usize, width: 1 + (uniform() * 150.0) as usize, height: 1 + (uniform() * 150.0) as usize };
            assert_eq!(silhouette_mask_in(&model, &pose, &cam, win), full.crop(win.x0, win.y0, win.width, win.height), "window {win:?}");
            let (dx, dy) = ((uniform() * 8.0) as usize, (uniform() * 8.0) as usize);
            let mask = BoundedMask::new(BinaryMask::from_fn(400, 300, |x, y| x >= dx && y >= dy && full.get(x - dx, y - dy)).dilated((uniform() * 3.0) as usize));
            let whole = snap_candidate(&mask, &full, 4).unwrap().1;
            let windowed = mask_agreement_raster(&mask, &model, &pose, &cam, 4, Raster::EveryPixel).unwrap();
            assert_eq!(windowed, whole, "agreement for the tube at {:?}", pose.centre);
            let adaptive = mask_agreement(&mask, &model, &pose, &cam, 4).unwrap();
            assert!((adaptive - whole).abs() <= 0.01, "adaptive agreement {adaptive} vs {whole} for the tube at {:?}", pose.centre);
            compared += (mask.area() > 0) as usize;
        }
        assert!(compared > 20, "only {compared} tubes in view");
        let small = BoundedMask::new(BinaryMask::new(10, 10));
        let pose = TubeAxisPose::new(0, 1.0, Vector3::new(0.0, 0.0, 1.0), Vector3::x(), 1.0).unwrap();
        assert_eq!(mask_agreement(&small, &model, &pose, &cam, 4), None, "a mask of another size");
        assert_eq!(mask_agreement(&BoundedMask::new(BinaryMask::new(400, 300)), &model, &pose, &cam, 4), Some(0.0), "an empty mask");
    }

    /// The rows' hull culling tests a subset of the bounding box's pixels; no silhouette pixel
    /// lies outside it, and the adaptive raster differs in a few pixels at most: random tubes (0.4-3 m, any direction, some cut by the border) under a
    /// pinhole and a distorted camera against a brute-force test of every pixel of the image.
    #[test]
    fn hull_culled_silhouette_matches_every_pixel_tested() {
        use tubeloc_core::Distortion;
        let model = CylinderModel::new(&tubeloc_core::TubeModel::default()).unwrap();
        let full = CameraModel::from_hfov(5472, 3648, 77.0).cropped(3900, 500, 400, 300);
        let distorted = CameraModel { distortion: Distortion { k1: -0.08, k2: 0.02, p1: 0.0005, p2: -0.0003, k3: 0.0 }, ..full.clone() };
        let mut uniform = uniform_stream(0x9E3779B97F4A7C15);
        let (mut compared, mut worst) = (0, 0);
        for cam in [&full, &distorted] {
            for _ in 0..60 {
                let z = 0.4 + 2.6 * uniform();
                let (u, v) = (uniform() * 1.2 - 0.1, uniform() * 1.2 - 0.1);
                let p = cam.unproject(&nalgebra::Point2::new(u * cam.width as f64, v * cam.height as f64));
                let c = p * (z / p.z);
                let a = Vector3::new(uniform() - 0.5, uniform() - 0.5, uniform() - 0.5);
                let Ok(pose) = TubeAxisPose::new(0, 1.0, c, a.normalize(), 1.0) else { continue };
                let fast = silhouette_mask(&model, &pose, cam);
                let far = 2.0 * (c.norm() + model.length);
                let brute = BinaryMask::from_fn(cam.width as usize, cam.height as usize, |x, y| {
                    let d = cam.unproject(&nalgebra::Point2::new(x as f64, y as f64));
                    model.occludes(&pose.centre, &pose.end_direction, &Point3::from(d * (far / d.norm())))
                });
                if brute.area() > 0 {
                    compared += 1;
                }
                assert_eq!(fast, brute, "tube at {c:?} axis {a:?}");
                let whole = PixelWindow { x0: 0, y0: 0, width: cam.width as usize, height: cam.height as usize };
                let adaptive = silhouette_mask_raster(&model, &pose, cam, whole, Raster::Adaptive);
                let differ = adaptive.data.iter().zip(&brute.data).filter(|(p, q)| p != q).count() as u64;
                worst = worst.max(differ);
                assert!(differ <= 2 + brute.area() / 500, "adaptive raster: {differ} of {} pixels differ, tube at {c:?} axis {a:?}", brute.area());
            }
        }
        assert!(compared > 60, "only {compared} tubes in view");
        eprintln!("adaptive raster: at most {worst} pixels differ");
    }
}
