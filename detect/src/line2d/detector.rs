//! `Line2dDetector`: a template library with its matching parameters, run end to end on an
//! image: matching ([`crate::line2d::matching`]), the ground-consistency check where the
//! ground is known ([`crate::line2d::ground`]), radiometric verification
//! ([`crate::line2d::verify`]), non-maximum suppression, re-ranking within each cluster, and
//! the detections with their coarse poses ([`crate::line2d::detection`]).

use crate::line2d::classify::features;
use crate::line2d::detection::Line2dDetection;
use crate::line2d::ground::GroundRange;
use crate::line2d::matching::{match_all_within, prepare_image, RawMatch};
use crate::line2d::nms::{nms_clusters, rerank_with, MAX_NMS_INPUT};
use crate::line2d::params::MatchParams;
use crate::line2d::template::TemplateLibrary;
use crate::line2d::verify::{contrast, luminance, verified_score, SampleCache};
use crate::line2d::Line2dError;
use rayon::prelude::*;
use tubeloc_core::{CameraModel, GroundPlane};

/// A ready-to-run detector: a library and matching parameters.
pub struct Line2dDetector {
    /// The template library.
    pub library: TemplateLibrary,
    /// Matching parameters.
    pub params: MatchParams,
    /// Verification samples per template, computed on first use.
    samples: SampleCache,
}

impl Line2dDetector {
    /// A detector over `library`.
    pub fn new(library: TemplateLibrary, params: MatchParams) -> Result<Self, Line2dError> {
        if !(0.0..=100.0).contains(&params.threshold) || params.coarse_threshold.is_some_and(|c| !(0.0..=100.0).contains(&c)) {
            return Err(Line2dError::invalid("threshold", "must be a percentage in 0..=100"));
        }
        if params.t0 == 0 || params.t1 == 0 || params.t1 > 64 || params.t0 > 64 {
            return Err(Line2dError::invalid("T", "spreading steps must be in 1..=64"));
        }
        let samples = SampleCache::new(library.len());
        Ok(Line2dDetector { library, params, samples })
    }

    /// Detects tubes in an interleaved RGB8 image. `camera` gives the intrinsics of this image
    /// (for the coarse pose); without it the library's focal lengths and the image centre are
    /// used. When the camera's focal lengths differ from the library's by more than 2 percent
    /// the image is first resampled to the library's pixel scale (factor
    /// [`Line2dDetector::scale_for`] per axis: a tube at range `r` then looks like the
    /// library's templates at range `r`), matched there, and the detections are mapped back to
    /// this image (masks and boxes at its size, centres by [`crate::scale::point_back`], coarse
    /// poses in `camera`; see [`Line2dDetection::from_match_scaled`]). An image that would have
    /// to be enlarged by more than [`MatchParams::max_upsample`] is not searched (no detection;
    /// see [`Line2dDetector::resolvable`]), nor is one (as matched) narrower or shorter than two
    /// level-1 tiles (`2 t1` px): no template fits in it.
    pub fn detect(&self, rgb: &[u8], width: usize, height: usize, camera: Option<&CameraModel>) -> Result<Vec<Line2dDetection>, Line2dError> {
        self.detect_on_ground(rgb, width, height, camera, None)
    }

    /// [`Line2dDetector::detect`] with the image's ground plane (camera frame, `n · X = d`, `n`
    /// up) when it is known: with [`MatchParams::ground_range`] set, every raw match whose
    /// template distance disagrees with the ground's distance along its centre's ray is
    /// dropped before verification and NMS ([`crate::line2d::ground`]): a tube lies on the
    /// ground, so a match in the sky or at a scale the ground does not allow there is not one.
    /// The ground needs the image's own `camera` (the rays); without either this is
    /// [`Line2dDetector::detect`].
    pub fn detect_on_ground(&self, rgb: &[u8], width: usize, height: usize, camera: Option<&CameraModel>, ground: Option<&GroundPlane>) -> Result<Vec<Line2dDetection>, Line2dError> {
        let ground = ground.filter(|_| camera.is_some());
        let cam = self.camera_for(width, height, camera)?;
        if rgb.len() != width * height * 3 {
            return Err(Line2dError::invalid("image", format!("RGB buffer has {} bytes, expected {}", rgb.len(), width * height * 3)));
        }
        let (sx, sy) = self.scale_for(camera);
        if !self.resolvable(camera) {
            return Ok(Vec::new());
        }
        // Whether the image is grey decides the far search and the verifier's cut: read once.
        let (colour_k, grey_k) = (self.params.far_scale, self.params.far_scale_grey);
        let grey = (self.params.verifier.is_some() || colour_k != grey_k) && crate::input::is_grey_rgb8(rgb);
        let k = self.far_scale_for(grey, sx, sy);
        let two = self.searched_twice(grey, camera);
        let cut = self.params.verifier.as_ref().map(|v| v.threshold_for_search(grey, two));
        let mut dets = self.detect_at(rgb, width, height, &cam, sx, sy, ground, 1.0, cut)?;
        if two {
            let far = self.detect_at(rgb, width, height, &cam, sx * k, sy * k, ground, k, cut)?;
            dets.extend(far.into_iter().map(|mut d| {
                d.t_cam_tube.0.translation.vector *= k;
                d
            }));
            dets.sort_by(|a, b| b.score.total_cmp(&a.score));
            dets = suppress_overlapping(dets, self.params.verified_overlap);
            dets.truncate(self.params.max_detections);
        }
        Ok(dets)
    }

    /// Whether an image of `camera` that is `grey` (three equal channels) or colour is also
    /// searched by the far search: its factor ([`Line2dDetector::far_scale_for`]) exceeds 1 and
    /// the image enlarged by it stays within [`MatchParams::max_upsample`]. Such an image's
    /// detections have the verifier's far cut ([`crate::line2d::Verifier::threshold_for_search`]).
    pub fn searched_twice(&self, grey: bool, camera: Option<&CameraModel>) -> bool {
        let (sx, sy) = self.scale_for(camera);
        let k = self.far_scale_for(grey, sx, sy);
        k > 1.0 && sx * k <= self.params.max_upsample && sy * k <= self.params.max_upsample
    }

    /// The far search's factor for an image that is `grey` (three equal channels,
    /// [`crate::input::is_grey_rgb8`]) or colour, resampled by `(sx, sy)` to the library's
    /// scale ([`Line2dDetector::scale_for`]): [`MatchParams::far_scale_grey`] when it is grey
    /// and enlarged (`sx > 1` or `sy > 1`: a mono camera whose pixels are coarser than the
    /// library's, e.g. Navcam), else [`MatchParams::far_scale`].
    pub fn far_scale_for(&self, grey: bool, sx: f64, sy: f64) -> f64 {
        if grey && (sx > 1.0 || sy > 1.0) {
            self.params.far_scale_grey
        } else {
            self.params.far_scale
        }
    }

    /// [`Line2dDetector::detect_native`] on the image resampled by `(sx, sy)` (none at 1).
    /// `far`: 1 for the search at the library's scale, the far search's factor `k` for the far
    /// search (its template distances count `k` times; its candidate budget is that of the
    /// search at the library's scale, whose image is `k²` times smaller). `cut`: the clutter
    /// verifier's cut for this image (its kind, and whether it is searched twice).
    #[allow(clippy::too_many_arguments)]
    fn detect_at(&self, rgb: &[u8], width: usize, height: usize, cam: &CameraModel, sx: f64, sy: f64, ground: Option<&GroundPlane>, far: f64, cut: Option<f32>) -> Result<Vec<Line2dDetection>, Line2dError> {
        if sx == 1.0 && sy == 1.0 {
            return self.detect_native(rgb, width, height, cam, 1.0, 1.0, width, height, ground, far, cut);
        }
        let (nw, nh) = (((width as f64 * sx).round() as usize).max(1), ((height as f64 * sy).round() as usize).max(1));
        let small = crate::scale::resample_rgb8(rgb, width, height, nw, nh);
        self.detect_native(&small, nw, nh, cam, nw as f64 / width as f64, nh as f64 / height as f64, width, height, ground, far, cut)
    }

    /// Whether raw match `m` (resampled pixels, scale `(sx, sy)` of camera `cam`'s image) is
    /// consistent with a tube lying on `ground`, its template distance multiplied by `k`.
    #[allow(clippy::too_many_arguments)]
    fn on_ground(&self, range: &GroundRange, ground: &GroundPlane, k: f64, cam: &CameraModel, m: &RawMatch, sx: f64, sy: f64) -> bool {
        let t = &self.library.templates[m.template as usize];
        let c = crate::scale::point_back([m.x as f64 + t.centre[0] as f64, m.y as f64 + t.centre[1] as f64], sx, sy);
        let ray = cam.unproject(&nalgebra::Point2::new(c[0], c[1]));
        range.admits(ground, &ray, k * t.t_cam_tube.translation().norm())
    }

    /// The resampling factors `(sx, sy)` that bring an image of `camera` to the library's
    /// pixel scale: `f_library / f_image` per axis, or `(1, 1)` without a camera or when both
    /// focal lengths are within 2 percent of the library's. Factors are clamped to
    /// `[1/8, 8]`.
    pub fn scale_for(&self, camera: Option<&CameraModel>) -> (f64, f64) {
        let k = &self.library.params.camera;
        let Some(c) = camera else { return (1.0, 1.0) };
        let rel = ((c.fx - k.fx) / k.fx).abs().max(((c.fy - k.fy) / k.fy).abs());
        if rel <= 0.02 || !(c.fx > 0.0 && c.fy > 0.0) {
            return (1.0, 1.0);
        }
        ((k.fx / c.fx).clamp(0.125, 8.0), (k.fy / c.fy).clamp(0.125, 8.0))
    }

    /// Whether an image of `camera` is searched: its resampling factors to the library's scale
    /// ([`Line2dDetector::scale_for`]) are at most [`MatchParams::max_upsample`].
    pub fn resolvable(&self, camera: Option<&CameraModel>) -> bool {
        let (sx, sy) = self.scale_for(camera);
        sx <= self.params.max_upsample && sy <= self.params.max_upsample
    }

    /// Matching, verification, NMS, re-ranking and the clutter verifier on an image already at
    /// the library's scale (`w x h`, resampled from the original `ow x oh` image of camera
    /// `cam` by `(sx, sy)`); detections in original pixels. `far` and `cut` as in
    /// [`Line2dDetector::detect_at`].
    #[allow(clippy::too_many_arguments)]
    fn detect_native(&self, rgb: &[u8], width: usize, height: usize, cam: &CameraModel, sx: f64, sy: f64, ow: usize, oh: usize, ground: Option<&GroundPlane>, far: f64, cut: Option<f32>) -> Result<Vec<Line2dDetection>, Line2dError> {
        let t1 = self.params.t1;
        if t1 > 0 && (width < 2 * t1 || height < 2 * t1) {
            return Ok(Vec::new()); // narrower than two level-1 tiles: no template fits in it
        }
        let img = prepare_image(rgb, width, height, &self.params)?;
        let mut raw = match_all_within(&img, &self.library, &self.params, (width * height) as f64 / (far * far));
        if let (Some(range), Some(g)) = (&self.params.ground_range, ground) {
            raw.retain(|m| self.on_ground(range, g, far, cam, m, sx, sy));
        }
        let vp = self.params.verify.unwrap_or_default();
        let need_luma = self.params.verify.is_some() || self.params.verifier.is_some();
        let luma = need_luma.then(|| luminance(rgb));
        // Verified scores (percent scale, so that NMS and re-ranking margins keep their units);
        // `sims` keeps each match's Line2D similarity and contrast.
        let mut sims = std::collections::HashMap::new();
        let raw = match (&self.params.verify, &luma) {
            (Some(v), Some(luma)) => {
                let mut scored: Vec<(RawMatch, f32, Option<f32>)> = raw
                    .into_par_iter()
                    .take(MAX_NMS_INPUT * 4)
                    .filter_map(|m| {
                        let t = &self.library.templates[m.template as usize];
                        let c = contrast(luma, width, height, self.samples.get(t, v), m.x, m.y);
                        verified_score(m.score, c, v).map(|s| (RawMatch { score: 100.0 * s / (1.0 + v.contrast_weight), ..m }, m.score, c))
                    })
                    .collect();
                // Equal keys are equal matches (with equal similarity and contrast): unstable is exact.
                scored.sort_unstable_by(|a, b| b.0.score.total_cmp(&a.0.score).then(a.0.template.cmp(&b.0.template)).then((a.0.y, a.0.x).cmp(&(b.0.y, b.0.x))));
                scored
                    .into_iter()
                    .map(|(m, sim, c)| {
                        sims.insert((m.template, m.x, m.y), (sim, c));
                        m
                    })
                    .collect()
            }
            _ => raw,
        };
        let clusters = nms_clusters(&raw, &self.library, self.params.nms_iou, self.params.max_detections);
        let mut dets: Vec<Line2dDetection> = clusters
            .iter()
            .filter_map(|c| {
                // Verification picks the cluster (where); the Line2D similarity, re-ranked,
                // picks the template (pose) within it.
                let mut by_sim: Vec<RawMatch> = c.iter().map(|m| RawMatch { score: sims.get(&(m.template, m.x, m.y)).map_or(m.score, |s| s.0), ..*m }).collect();
                by_sim.sort_by(|a, b| b.score.total_cmp(&a.score));
                let margin = self.params.rerank_margin;
                let max_area = by_sim.iter().filter(|m| m.score >= by_sim[0].score - margin).map(|m| self.library.templates[m.template as usize].area).max().unwrap_or(1).max(1) as f32;
                let aw = self.params.rerank_area_weight;
                let m = match (&img.resp_rerank, &self.params.verify, &luma) {
                    (Some(rr), Some(v), Some(l)) if v.rerank_weight > 0.0 => {
                        rerank_with(&by_sim, &self.library, rr, margin, |t, x, y| v.rerank_weight * contrast(l, width, height, self.samples.get(t, v), x, y).unwrap_or(-1.0).clamp(-1.0, 1.0) + aw * t.area as f32 / max_area)
                    }
                    (Some(rr), _, _) => rerank_with(&by_sim, &self.library, rr, margin, |t, _, _| aw * t.area as f32 / max_area),
                    _ => by_sim[0],
                };
                let t = &self.library.templates[m.template as usize];
                let mut d = Line2dDetection::from_match_scaled(&m, t, cam, ow, oh, sx, sy);
                if let (Some(v), Some(l)) = (&self.params.verify, &luma) {
                    d.score = (c[0].score / 100.0).max(0.0);
                    d.contrast = contrast(l, width, height, self.samples.get(t, v), m.x, m.y);
                }
                if let (Some(vf), Some(l), Some(cut)) = (&self.params.verifier, &luma, cut) {
                    let f = features(l, width, height, t, self.samples.get(t, &vp), m.x, m.y, m.score);
                    let p = f.as_ref().map_or(0.0, |f| vf.probability(f));
                    if p < cut {
                        return None;
                    }
                    d.score = p;
                    d.probability = Some(p);
                    d.features = f;
                }
                Some(d)
            })
            .collect();
        if self.params.verifier.is_some() {
            dets.sort_by(|a, b| b.score.total_cmp(&a.score));
            dets = suppress_overlapping(dets, self.params.verified_overlap);
        }
        Ok(dets)
    }

    /// The camera used for poses: `camera` (any focal length: [`Line2dDetector::detect`]
    /// resamples to the library's scale), or a pinhole with the library's focal lengths
    /// centred on the image. A camera with a non-positive or non-finite focal length is refused.
    pub fn camera_for(&self, width: usize, height: usize, camera: Option<&CameraModel>) -> Result<CameraModel, Line2dError> {
        let k = &self.library.params.camera;
        match camera {
            Some(c) => {
                if !(c.fx.is_finite() && c.fy.is_finite() && c.fx > 0.0 && c.fy > 0.0) {
                    return Err(Line2dError::invalid("camera", format!("focal length {}x{} px must be positive and finite", c.fx, c.fy)));
                }
                Ok(c.clone())
            }
            None => Ok(CameraModel { width: width as u32, height: height as u32, fx: k.fx, fy: k.fy, cx: (width as f64 - 1.0) / 2.0, cy: (height as f64 - 1.0) / 2.0, distortion: Default::default() }),
        }
    }
}

/// Greedy suppression over detections sorted by decreasing score: a detection is dropped when
/// the intersection of its mask with a kept detection's mask exceeds `max_overlap` times the
/// smaller mask's area.
fn suppress_overlapping(dets: Vec<Line2dDetection>, max_overlap: f32) -> Vec<Line2dDetection> {
    let mut kept: Vec<Line2dDetection> = Vec::with_capacity(dets.len());
    for d in dets {
        let ad = d.mask.area() as f64;
        let hit = kept.iter().any(|k| {
            let (b, c) = (&d.bbox, &k.bbox);
            if b[0] >= c[0] + c[2] || c[0] >= b[0] + b[2] || b[1] >= c[1] + c[3] || c[1] >= b[1] + b[3] {
                return false;
            }
            let ak = k.mask.area() as f64;
            // With `iscrowd`, the COCO IoU is intersection / area of the first mask.
            let inter = tubeloc_core::Rle::iou(std::slice::from_ref(&d.mask), std::slice::from_ref(&k.mask), &[true])[0] * ad;
            inter > max_overlap as f64 * ad.min(ak).max(1.0)
        });
        if !hit {
            kept.push(d);
        }
    }
    kept
}
