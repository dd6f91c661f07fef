//! Which end is the seal end, from the tube's colours.
//!
//! The sample tube's seal section is gold (TiN coated), its body white alumina
//! (`data/tube.toml`). Edges tell the ends apart only through the sections' small radius
//! differences, which a 15-20 px wide tube barely shows (the edge fit picks the right end for
//! ~74 % of learned detections on a generated validation set); the colours differ strongly.
//!
//! For a pose, the pixels of its silhouette ([`crate::silhouette::silhouette_mask`]), kept to
//! the detector's mask dilated by 2 px when there is one (parts hidden by rocks or sand are not
//! the tube's colour), are split by their axial coordinate: the point of the axis line
//! `c + z a` closest to the pixel's viewing ray `t r`,
//!
//! `z = ((r·a)(r·c) − (r·r)(c·a)) / ((r·r) − (r·a)²)`.
//!
//! Seal pixels have `z` in the last section (the seal end, +z), body pixels `z` in the longest
//! section short of its upper 5 mm. The evidence is the difference of mean yellowness
//! `Y = (R + G)/2 − B` (0-255 units), seal minus body: positive when `a` points to the seal
//! end. In a monochrome image (R = G = B on every pixel used) the gold section is the darker
//! one and the difference of mean grey levels, body minus seal, is used instead.

use crate::model::CylinderModel;
use crate::silhouette::{silhouette_mask, PixelRays};
use nalgebra::Point2;
use tubeloc_core::{AxisSeed, BoundedMask, CameraModel, TubeAxisPose};

/// An interleaved 8-bit RGB image, row-major, `width x height x 3` bytes.
#[derive(Clone, Copy, Debug)]
pub struct ColourImage<'a> {
    /// Width, pixels.
    pub width: usize,
    /// Height, pixels.
    pub height: usize,
    /// `R, G, B` per pixel.
    pub rgb: &'a [u8],
}

/// The colour evidence for which end is the seal end ([`seal_end_evidence`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SealEndEvidence {
    /// Mean yellowness of the seal pixels minus the body pixels' (monochrome: mean grey of the
    /// body minus the seal's), 0-255 units; positive when the pose's `end_direction` points to
    /// the seal end.
    pub contrast: f64,
    /// Pixels counted in the seal section.
    pub seal_pixels: usize,
    /// Pixels counted in the body.
    pub body_pixels: usize,
    /// The image had R = G = B on every pixel used.
    pub monochrome: bool,
}

/// Fewest pixels per section for evidence.
const MIN_PIXELS: usize = 10;

/// Scale of the end confidence `1 / (1 + exp(−|contrast| / s))`, 0-255 units. On the
/// generated validation set val21 (582 learned detections refined), the colour decision was
/// right for 58 % of the tubes with |contrast| < 10, 81 % at 15-25 and 99.4 % above 25.
pub const CONFIDENCE_SCALE: f64 = 8.0;

/// The colour evidence of `image` (same size as the camera) for `pose`'s end direction, or
/// `None` when the seal section or the body covers fewer than 10 pixels (tube cut by the
/// border, hidden, end-on) or the sizes differ. `visible`: the detector's mask of the tube.
pub fn seal_end_evidence(model: &CylinderModel, pose: &TubeAxisPose, camera: &CameraModel, image: &ColourImage, visible: Option<&BoundedMask>) -> Option<SealEndEvidence> {
    let (w, h) = (camera.width as usize, camera.height as usize);
    if image.width != w || image.height != h || image.rgb.len() != w * h * 3 {
        return None;
    }
    let seal = *model.sections.last()?;
    let body = *model.sections.iter().max_by(|a, b| (a.z1 - a.z0).total_cmp(&(b.z1 - b.z0)))?;
    if seal == body {
        return None;
    }
    let (c, a) = (pose.centre, pose.end_direction);
    let ca = c.dot(&a);
    // Sums of yellowness and grey per section, and whether any pixel had colour.
    let (mut ys, mut gs, mut ns) = (0.0, 0.0, 0usize);
    let (mut yb, mut gb, mut nb) = (0.0, 0.0, 0usize);
    let mut coloured = false;
    let mut add = |i: usize| {
        let (x, y) = (i % w, i / w);
        let r = camera.unproject(&Point2::new(x as f64, y as f64));
        let (rr, ra, rc) = (r.dot(&r), r.dot(&a), r.dot(&c));
        let den = rr - ra * ra;
        if den.abs() < 1e-12 {
            return;
        }
        let z = (ra * rc - rr * ca) / den;
        let px = &image.rgb[3 * i..3 * i + 3];
        let (red, green, blue) = (px[0] as f64, px[1] as f64, px[2] as f64);
        coloured |= px[0] != px[1] || px[1] != px[2];
        let yellow = 0.5 * (red + green) - blue;
        let grey = (red + green + blue) / 3.0;
        if z >= seal.z0 && z <= seal.z1 {
            (ys, gs, ns) = (ys + yellow, gs + grey, ns + 1);
        } else if z >= body.z0 && z <= body.z1 - 0.005 {
            (yb, gb, nb) = (yb + yellow, gb + grey, nb + 1);
        }
    };
    match visible {
        // The silhouette's pixels within 2 px of the mask, in image order: only the grown
        // mask's pixels are tested (the same test as the silhouette's, [`PixelRays`]).
        Some(m) if m.width == w && m.height == h => {
            let near = m.dilated_window(2);
            if let Some(rays) = PixelRays::new(model, pose, camera) {
                for y in 0..near.mask.height {
                    for x in (0..near.mask.width).filter(|&x| near.mask.data[y * near.mask.width + x] != 0) {
                        let (ix, iy) = (near.x0 + x, near.y0 + y);
                        if rays.hit(ix, iy) {
                            add(iy * w + ix);
                        }
                    }
                }
            }
        }
        _ => {
            let sil = silhouette_mask(model, pose, camera);
            for (i, _) in sil.data.iter().enumerate().filter(|(_, &v)| v != 0) {
                add(i);
            }
        }
    }
    if ns < MIN_PIXELS || nb < MIN_PIXELS {
        return None;
    }
    let (ns_f, nb_f) = (ns as f64, nb as f64);
    let contrast = if coloured { ys / ns_f - yb / nb_f } else { gb / nb_f - gs / ns_f };
    Some(SealEndEvidence { contrast, seal_pixels: ns, body_pixels: nb, monochrome: !coloured })
}

/// Decides `pose`'s seal end from `evidence` (computed for this pose): flips `end_direction`
/// when the contrast is negative and sets `end_confidence` ([`end_confidence`]). The flip-free
/// axis and the centre do not change ([`crate::Refiner::refine`] re-fits the flipped
/// end instead).
pub fn apply_seal_end(pose: &mut TubeAxisPose, evidence: &SealEndEvidence) {
    if evidence.contrast < 0.0 {
        pose.end_direction = -pose.end_direction;
    }
    pose.end_confidence = end_confidence(evidence);
}

/// Most confidence monochrome evidence gives ([`end_confidence`]). In grey, a darker section
/// beyond the tube's bright body is the gold seal or the ground past the foot; on the real grey
/// validation composites (`val_grey11`, `val_grey0`: 104 matched mono poses) the end was right
/// for 90 % of the poses whose colour-scale confidence was 0.99 or more, and for 82 % in all.
/// Fitted there by maximum likelihood with [`MONOCHROME_CONFIDENCE_SCALE`] (record 0067).
pub const MONOCHROME_MAX_CONFIDENCE: f64 = 0.89;

/// Scale of the monochrome end confidence, grey levels (0-255); see [`end_confidence`].
pub const MONOCHROME_CONFIDENCE_SCALE: f64 = 16.0;

/// Confidence in the end the evidence favours. Colour evidence: `σ(|c| / s)`, `σ(x) = 1 / (1 +
/// e^-x)`, `s` = [`CONFIDENCE_SCALE`]. Monochrome evidence: `0.5 + (m − 0.5) (2 σ(|c| / s_m) −
/// 1)`, `m` = [`MONOCHROME_MAX_CONFIDENCE`], `s_m` = [`MONOCHROME_CONFIDENCE_SCALE`] (the colour
/// form is the case `m = 1`).
pub fn end_confidence(evidence: &SealEndEvidence) -> f64 {
    let sigma = |x: f64| 1.0 / (1.0 + (-x).exp());
    let c = evidence.contrast.abs();
    if evidence.monochrome {
        0.5 + (MONOCHROME_MAX_CONFIDENCE - 0.5) * (2.0 * sigma(c / MONOCHROME_CONFIDENCE_SCALE) - 1.0)
    } else {
        sigma(c / CONFIDENCE_SCALE)
    }
}

/// Fewest mask pixels for [`seal_end_along_axis`].
const MIN_MASK_PIXELS: usize = 20;

/// Which way along a mask's image axis the seal end lies, from the colours under the mask and
/// no pose: the correlation, over the mask's pixels `u`, between the coordinate along the axis
/// seed, `t = (u − centre_px) · direction_px`, and the yellowness `Y = (R + G)/2 − B`,
///
/// `ρ = cov(t, Y) / sqrt(var(t) var(Y))`,
///
/// in [−1, 1], positive when `direction_px` points toward the gold seal end. In a monochrome
/// image (R = G = B on every mask pixel) the darkness `−(R + G + B)/3` replaces `Y` (the gold
/// section is the darker). It orients a mask seed before the fit
/// ([`crate::settings::MaskUse::end_colour_corr`]), whose image axis has no end of its
/// own. `None` when the sizes differ, the mask has fewer than 20 pixels, or `t` or the colour
/// is constant over it.
pub fn seal_end_along_axis(mask: &BoundedMask, axis: &AxisSeed, image: &ColourImage) -> Option<f64> {
    let (w, h) = (image.width, image.height);
    if mask.width != w || mask.height != h || image.rgb.len() != w * h * 3 {
        return None;
    }
    let [bx, by, bw, bh] = mask.bbox();
    let (x0, y0) = (bx as usize, by as usize);
    let (x1, y1) = (x0 + bw as usize, y0 + bh as usize);
    let [cx, cy] = axis.centre_px;
    let [dx, dy] = axis.direction_px;
    // Sums of t, t², and of the yellowness and grey with their squares and products with t.
    let (mut n, mut st, mut stt) = (0usize, 0.0, 0.0);
    let (mut sy, mut syy, mut sty) = (0.0, 0.0, 0.0);
    let (mut sg, mut sgg, mut stg) = (0.0, 0.0, 0.0);
    let mut coloured = false;
    for y in y0..y1 {
        let row = &mask.data[y * w..(y + 1) * w];
        for x in (x0..x1).filter(|&x| row[x] != 0) {
            let px = &image.rgb[3 * (y * w + x)..3 * (y * w + x) + 3];
            coloured |= px[0] != px[1] || px[1] != px[2];
            let (r, g, b) = (px[0] as f64, px[1] as f64, px[2] as f64);
            let t = (x as f64 - cx) * dx + (y as f64 - cy) * dy;
            let (yel, grey) = (0.5 * (r + g) - b, (r + g + b) / 3.0);
            n += 1;
            (st, stt) = (st + t, stt + t * t);
            (sy, syy, sty) = (sy + yel, syy + yel * yel, sty + t * yel);
            (sg, sgg, stg) = (sg + grey, sgg + grey * grey, stg + t * grey);
        }
    }
    if n < MIN_MASK_PIXELS {
        return None;
    }
    let nf = n as f64;
    let vt = stt - st * st / nf;
    // Darkness −grey: its covariance with t is minus grey's, its variance grey's.
    let (cov, vc) = if coloured { (sty - st * sy / nf, syy - sy * sy / nf) } else { (-(stg - st * sg / nf), sgg - sg * sg / nf) };
    let den = (vt * vc).sqrt();
    (den > 1e-9 * nf).then(|| (cov / den).clamp(-1.0, 1.0))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Point3, Vector3};
    use tubeloc_core::BinaryMask;
    use tubeloc_core::TubeModel;

    /// A tube across the view at 1 m painted as the real one: the seal section gold
    /// (200, 160, 60), the body white (220, 220, 215); background sand (150, 120, 95).
    fn painted(model: &CylinderModel, truth: &TubeAxisPose, cam: &CameraModel) -> Vec<u8> {
        let sil = silhouette_mask(model, truth, cam);
        let seal_z0 = model.sections.last().unwrap().z0;
        let mut rgb = Vec::with_capacity(sil.data.len() * 3);
        for (i, &v) in sil.data.iter().enumerate() {
            let (x, y) = ((i % sil.width) as f64, (i / sil.width) as f64);
            let r = cam.unproject(&Point2::new(x, y));
            let (c, a) = (truth.centre, truth.end_direction);
            let z = (r.dot(&a) * r.dot(&c) - r.dot(&r) * c.dot(&a)) / (r.dot(&r) - r.dot(&a).powi(2));
            rgb.extend_from_slice(match (v != 0, z >= seal_z0) {
                (false, _) => &[150, 120, 95],
                (true, true) => &[200, 160, 60],
                (true, false) => &[220, 220, 215],
            });
        }
        rgb
    }

    /// A 640 x 480 camera and a tube at 1 m, turned across the view ([`painted`]), in colour and
    /// in grey (each pixel's mean).
    struct PaintedScene {
        cam: CameraModel,
        model: CylinderModel,
        axis: Vector3<f64>,
        truth: TubeAxisPose,
        rgb: Vec<u8>,
        grey: Vec<u8>,
    }

    fn painted_scene() -> PaintedScene {
        let cam = CameraModel::from_hfov(640, 480, 40.0);
        let model = CylinderModel::new(&TubeModel::default()).unwrap();
        let axis = Vector3::new(1.0, 0.2, 0.1).normalize();
        let truth = TubeAxisPose::new(0, 1.0, Vector3::new(0.0, 0.0, 1.0), axis, 0.5).unwrap();
        let rgb = painted(&model, &truth, &cam);
        let grey = rgb.chunks(3).flat_map(|p| [((p[0] as u32 + p[1] as u32 + p[2] as u32) / 3) as u8; 3]).collect();
        PaintedScene { cam, model, axis, truth, rgb, grey }
    }

    #[test]
    fn the_gold_section_marks_the_seal_end_in_colour_and_in_grey() {
        let PaintedScene { cam, model, axis, truth, rgb, grey } = painted_scene();
        let image = ColourImage { width: 640, height: 480, rgb: &rgb };
        let grey_image = ColourImage { width: 640, height: 480, rgb: &grey };
        for (img, mono) in [(&image, false), (&grey_image, true)] {
            // A pose pointing the wrong way is flipped, with high confidence.
            let mut flipped = TubeAxisPose::new(0, 1.0, truth.centre, -axis, 0.9).unwrap();
            let ev = seal_end_evidence(&model, &flipped, &cam, img, None).expect("evidence");
            assert_eq!(ev.monochrome, mono);
            assert!(ev.contrast < -20.0, "{ev:?}");
            apply_seal_end(&mut flipped, &ev);
            assert!(flipped.end_direction.dot(&axis) > 0.999);
            // Grey evidence is trusted less: at most MONOCHROME_MAX_CONFIDENCE.
            let (least, most) = if mono { (0.7, MONOCHROME_MAX_CONFIDENCE) } else { (0.9, 1.0) };
            assert!(flipped.end_confidence > least && flipped.end_confidence <= most, "{}", flipped.end_confidence);
            assert!((flipped.axis - truth.axis).norm() < 1e-12 && flipped.centre == truth.centre);
            // The right way round stays.
            let mut right = truth.clone();
            let ev = seal_end_evidence(&model, &right, &cam, img, None).unwrap();
            apply_seal_end(&mut right, &ev);
            assert!(right.end_direction.dot(&axis) > 0.999 && ev.contrast > 20.0, "{ev:?}");
        }
    }

    #[test]
    fn end_confidence_follows_its_formulas() {
        let ev = |contrast: f64, monochrome: bool| SealEndEvidence { contrast, seal_pixels: 50, body_pixels: 50, monochrome };
        let sigma = |x: f64| 1.0 / (1.0 + (-x).exp());
        for c in [-40.0, -5.0, 0.0, 3.0, 30.0] {
            assert!((end_confidence(&ev(c, false)) - sigma(c.abs() / CONFIDENCE_SCALE)).abs() < 1e-12);
            let mono = end_confidence(&ev(c, true));
            assert!((mono - (0.5 + (MONOCHROME_MAX_CONFIDENCE - 0.5) * (2.0 * sigma(c.abs() / MONOCHROME_CONFIDENCE_SCALE) - 1.0))).abs() < 1e-12);
            assert!((0.5..MONOCHROME_MAX_CONFIDENCE).contains(&mono) || c == 0.0 && mono == 0.5);
        }
        // No contrast: no evidence either way; a large one: the most each kind allows.
        assert_eq!(end_confidence(&ev(0.0, true)), 0.5);
        assert!((end_confidence(&ev(1e4, true)) - MONOCHROME_MAX_CONFIDENCE).abs() < 1e-12);
        assert!((end_confidence(&ev(1e4, false)) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn no_evidence_without_enough_pixels_of_both_sections() {
        let cam = CameraModel::from_hfov(640, 480, 40.0);
        let model = CylinderModel::new(&TubeModel::default()).unwrap();
        let pose = TubeAxisPose::new(0, 1.0, Vector3::new(0.0, 0.0, 1.0), Vector3::x(), 0.5).unwrap();
        let rgb = painted(&model, &pose, &cam);
        let image = ColourImage { width: 640, height: 480, rgb: &rgb };
        // The mask shows only the seal half: no body pixels.
        let sil = silhouette_mask(&model, &pose, &cam);
        let seal_only = BoundedMask::new(BinaryMask::from_fn(640, 480, |x, y| sil.get(x, y) && x as f64 > cam.cx + 0.03 * cam.fx));
        assert!(seal_end_evidence(&model, &pose, &cam, &image, Some(&seal_only)).is_none());
        // A wrongly sized image gives no evidence rather than a panic.
        let small = ColourImage { width: 10, height: 10, rgb: &rgb[..300] };
        assert!(seal_end_evidence(&model, &pose, &cam, &small, None).is_none());
    }

    #[test]
    fn the_mask_axis_correlates_with_the_gold_end_in_colour_and_in_grey() {
        let PaintedScene { cam, model, axis, truth, rgb, grey } = painted_scene();
        let mask = BoundedMask::new(silhouette_mask(&model, &truth, &cam));
        let pixels = (0..480).flat_map(|y| (0..640).map(move |x| (x, y))).filter(|&(x, y)| mask.get(x, y)).map(|(x, y)| (x as f64, y as f64));
        let ax = AxisSeed::from_pixels(pixels).unwrap();
        // Orient the seed toward the projected seal end.
        let p0 = cam.project(&Point3::from(truth.centre)).unwrap();
        let p1 = cam.project(&Point3::from(truth.centre + axis * 0.05)).unwrap();
        let s = if (p1 - p0).dot(&nalgebra::Vector2::from(ax.direction_px)) >= 0.0 { 1.0 } else { -1.0 };
        let toward = AxisSeed { direction_px: [s * ax.direction_px[0], s * ax.direction_px[1]], ..ax };
        let away = AxisSeed { direction_px: [-toward.direction_px[0], -toward.direction_px[1]], ..ax };
        for rgb in [&rgb, &grey] {
            let image = ColourImage { width: 640, height: 480, rgb };
            let rho = seal_end_along_axis(&mask, &toward, &image).expect("evidence");
            assert!(rho > 0.5, "{rho}");
            let back = seal_end_along_axis(&mask, &away, &image).unwrap();
            assert!((back + rho).abs() < 1e-9, "{back} {rho}");
        }
        // Too few pixels, or an image of another size: no evidence.
        let tiny = BoundedMask::new(BinaryMask::from_fn(640, 480, |x, y| mask.get(x, y) && (x + y) % 97 == 0 && y % 13 == 0));
        assert!(tiny.area() < 20);
        assert!(seal_end_along_axis(&tiny, &toward, &ColourImage { width: 640, height: 480, rgb: &rgb }).is_none());
        assert!(seal_end_along_axis(&mask, &toward, &ColourImage { width: 10, height: 10, rgb: &rgb[..300] }).is_none());
    }

    #[test]
    fn a_mask_covering_the_silhouette_gives_the_evidence_of_no_mask() {
        // Only the grown mask's pixels are tested when a mask is given; the silhouette within
        // it is the whole silhouette here, so the sums (same pixels, same order) are identical.
        let PaintedScene { cam, model, truth, rgb, .. } = painted_scene();
        let image = ColourImage { width: 640, height: 480, rgb: &rgb };
        let sil = BoundedMask::new(silhouette_mask(&model, &truth, &cam));
        let bare = seal_end_evidence(&model, &truth, &cam, &image, None).unwrap();
        assert_eq!(seal_end_evidence(&model, &truth, &cam, &image, Some(&sil)), Some(bare));
        assert!(bare.seal_pixels > 100 && bare.body_pixels > 100, "{bare:?}");
    }
}
