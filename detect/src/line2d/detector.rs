//! `Line2dDetector`: a template library with its matching parameters, run end to end on an
//! image: matching ([`crate::line2d::matching`]), radiometric verification
//! ([`crate::line2d::verify`]), non-maximum suppression, re-ranking within each cluster, and
//! the detections with their coarse poses ([`crate::line2d::detection`]).

use crate::line2d::detection::Line2dDetection;
use crate::line2d::matching::{match_all, nms_clusters, prepare_image, rerank_with, MatchParams, RawMatch, MAX_NMS_INPUT};
use crate::line2d::template::TemplateLibrary;
use crate::line2d::verify::{contrast, luminance, verified_score, SampleCache};
use crate::line2d::Line2dError;
use rayon::prelude::*;
use tubeloc_core::CameraModel;

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
    /// used. The camera's focal length must match the library's within 2 percent.
    pub fn detect(&self, rgb: &[u8], width: usize, height: usize, camera: Option<&CameraModel>) -> Result<Vec<Line2dDetection>, Line2dError> {
        let cam = self.camera_for(width, height, camera)?;
        let img = prepare_image(rgb, width, height, &self.params)?;
        let raw = match_all(&img, &self.library, &self.params);
        // Verified scores (percent scale, so that NMS and re-ranking margins keep their units);
        // `sims` keeps each match's Line2D similarity and contrast.
        let mut sims = std::collections::HashMap::new();
        let raw = match &self.params.verify {
            None => raw,
            Some(v) => {
                let luma = luminance(rgb);
                let mut scored: Vec<(RawMatch, f32, Option<f32>)> = raw
                    .into_par_iter()
                    .take(MAX_NMS_INPUT * 4)
                    .filter_map(|m| {
                        let t = &self.library.templates[m.template as usize];
                        let c = contrast(&luma, width, height, self.samples.get(t, v), m.x, m.y);
                        verified_score(m.score, c, v).map(|s| (RawMatch { score: 100.0 * s / (1.0 + v.contrast_weight), ..m }, m.score, c))
                    })
                    .collect();
                scored.sort_by(|a, b| b.0.score.total_cmp(&a.0.score).then(a.0.template.cmp(&b.0.template)).then((a.0.y, a.0.x).cmp(&(b.0.y, b.0.x))));
                scored
                    .into_iter()
                    .map(|(m, sim, c)| {
                        sims.insert((m.template, m.x, m.y), (sim, c));
                        m
                    })
                    .collect()
            }
        };
        let clusters = nms_clusters(&raw, &self.library, self.params.nms_iou, self.params.max_detections);
        let luma = self.params.verify.is_some().then(|| luminance(rgb));
        Ok(clusters
            .iter()
            .map(|c| {
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
                let mut d = Line2dDetection::from_match(&m, t, &cam, width, height);
                if let (Some(v), Some(l)) = (&self.params.verify, &luma) {
                    d.score = (c[0].score / 100.0).max(0.0);
                    d.contrast = contrast(l, width, height, self.samples.get(t, v), m.x, m.y);
                }
                d
            })
            .collect())
    }

    /// The camera used for poses: `camera`, checked against the library, or a pinhole with the
    /// library's focal lengths centred on the image.
    pub fn camera_for(&self, width: usize, height: usize, camera: Option<&CameraModel>) -> Result<CameraModel, Line2dError> {
        let k = &self.library.params.camera;
        match camera {
            Some(c) => {
                let rel = ((c.fx - k.fx) / k.fx).abs().max(((c.fy - k.fy) / k.fy).abs());
                if rel > 0.02 {
                    return Err(Line2dError::invalid(
                        "camera",
                        format!("focal length {:.1}x{:.1} px differs from the library's {:.1}x{:.1} px by {:.0}%: rebuild the templates with this camera (tubeloc templates build --camera)", c.fx, c.fy, k.fx, k.fy, rel * 100.0),
                    ));
                }
                Ok(c.clone())
            }
            None => Ok(CameraModel { width: width as u32, height: height as u32, fx: k.fx, fy: k.fy, cx: (width as f64 - 1.0) / 2.0, cy: (height as f64 - 1.0) / 2.0, distortion: Default::default() }),
        }
    }
}
