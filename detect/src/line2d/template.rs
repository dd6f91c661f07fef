//! Templates: contour features of rendered silhouettes on a 2-level pyramid, and the library.
//!
//! Features of a silhouette mask `M` (one pyramid level): the contour is `M AND NOT erode₃ₓ₃(M)`;
//! each contour pixel gets the quantized orientation (8 bins modulo 180 degrees, the same
//! quantizer as the image side) of the Sobel gradient of `M`. From those, `n` features are
//! chosen spread out by farthest-point sampling: start at the contour pixel farthest from the
//! contour's centroid, then repeatedly add the pixel whose distance to the chosen set is
//! largest. Level 1 uses the mask downsampled 2x2 (a pixel is on when at least 2 of its 4
//! children are), in the same local frame halved.

use crate::line2d::gradient::orientation_bin;
use crate::line2d::mesh::{render_mesh_silhouette, MeshShape};
use crate::line2d::render::{render_silhouette, Pinhole, Silhouette};
use crate::line2d::viewpoints::{estimate_views, generate_views, ViewEstimate, ViewParams, ViewSpec};
use crate::line2d::Line2dError;
use rayon::prelude::*;
use tubeloc_core::{CameraModel, Pose, TubeModel};

/// One feature: position in template-local pixels (level coordinates) and orientation bin 0..8.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Feature {
    /// Column relative to the template's top-left pixel.
    pub x: u16,
    /// Row relative to the template's top-left pixel.
    pub y: u16,
    /// Quantized orientation bin (0..8), 22.5 degrees each, modulo 180 degrees.
    pub ori: u8,
}

/// Features of one pyramid level (level `l` has pixels `2^l` times larger than level 0).
#[derive(Clone, Debug, PartialEq)]
pub struct TemplateLevel {
    /// Template width at this level, pixels.
    pub width: u16,
    /// Template height at this level, pixels.
    pub height: u16,
    /// The selected features.
    pub features: Vec<Feature>,
}

/// A template: pose, silhouette and features on levels 0 (full resolution) and 1 (half).
#[derive(Clone, Debug, PartialEq)]
pub struct Template {
    /// Index in its library.
    pub id: u32,
    /// Angle between tube axis and line of sight, degrees.
    pub alpha_deg: f32,
    /// Image direction of the projected tube `+z` axis, degrees.
    pub psi_deg: f32,
    /// Distance of the tube centre from the camera, metres.
    pub distance: f32,
    /// `T_cam_tube` of the view: the tube centre on the optical axis.
    pub t_cam_tube: Pose,
    /// Projection of the tube centre in level-0 template-local pixels.
    pub centre: [f32; 2],
    /// Pyramid levels: `[0]` full resolution, `[1]` half resolution.
    pub levels: Vec<TemplateLevel>,
    /// Level-0 silhouette, `levels[0].width x levels[0].height`, 1 = tube.
    pub mask: Vec<u8>,
    /// Number of silhouette pixels (`Σ mask`).
    pub area: u32,
}

/// How a library was built (stored in the file).
#[derive(Clone, Debug, PartialEq)]
pub struct LibraryParams {
    /// Intrinsics the templates were rendered with (pixels; distortion ignored).
    pub camera: Pinhole,
    /// View sampling.
    pub views: ViewParams,
    /// Requested features per template and level.
    pub features: u32,
}

impl LibraryParams {
    /// The paper's camera at half resolution (5472x3648 at 77 degrees HFOV, halved), as the
    /// benchmark images are half-resolution crops: `fx = fy ≈ 1720 px`.
    pub fn default_camera() -> CameraModel {
        CameraModel::from_hfov(5472, 3648, 77.0).scaled(0.5)
    }
}

/// The estimated size of a library, from its parameters alone ([`LibraryParams::estimate`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LibraryEstimate {
    /// The view counts.
    pub views: ViewEstimate,
    /// Upper bound of the templates (views whose silhouette is empty are dropped).
    pub templates: f64,
    /// Estimated in-memory size of one template, bytes: the structure, two levels of features
    /// and the level-0 mask, taken as half the square of the tube's longest projected extent
    /// (a tube lying diagonally) averaged over the distance grid (an over-estimate: most views
    /// are foreshortened or closer to an image axis).
    pub bytes_per_template: f64,
    /// Estimated peak memory of a build, bytes: the templates twice (the library and its
    /// serialized file in memory when it is saved).
    pub peak_bytes: f64,
}

impl LibraryParams {
    /// Estimates the library these parameters give for a tube of `length_m` and largest
    /// radius `radius_m`, without rendering anything (see [`LibraryEstimate`]): what
    /// `tubeloc templates build` checks against its limits before building.
    pub fn estimate(&self, length_m: f64, radius_m: f64) -> Result<LibraryEstimate, Line2dError> {
        let views = estimate_views(&self.views)?;
        let f = self.camera.fx.abs().max(self.camera.fy.abs());
        let extent = length_m + 2.0 * radius_m;
        let reach = 0.5 * length_m + radius_m;
        let max_side = (u16::MAX / 2) as f64;
        // Mean squared projected extent over (up to 1000 evenly spaced) grid distances.
        let k = views.distances.clamp(1.0, 1000.0) as usize;
        let span = (self.views.dist_max - self.views.dist_min).max(0.0);
        let mean_sq = (0..k)
            .map(|i| {
                let d = if k == 1 { self.views.dist_min } else { self.views.dist_min + span * i as f64 / (k - 1) as f64 };
                let side = if d > reach { (f * extent / (d - reach) + 2.0).min(max_side) } else { max_side };
                // A tube lying diagonally in the image fills at most about half its square box.
                0.5 * side * side
            })
            .sum::<f64>()
            / k as f64;
        let fixed = std::mem::size_of::<Template>() + 2 * std::mem::size_of::<TemplateLevel>();
        let features = 2.0 * self.features as f64 * std::mem::size_of::<Feature>() as f64;
        let bytes_per_template = fixed as f64 + features + mean_sq;
        Ok(LibraryEstimate { views, templates: views.templates, bytes_per_template, peak_bytes: 2.0 * views.templates * bytes_per_template })
    }
}

impl Default for LibraryParams {
    fn default() -> Self {
        let c = Self::default_camera();
        LibraryParams { camera: Pinhole { fx: c.fx, fy: c.fy, cx: c.cx, cy: c.cy }, views: ViewParams::default(), features: 64 }
    }
}

/// A template library: the parameters it was built with and its templates.
#[derive(Clone, Debug, PartialEq)]
pub struct TemplateLibrary {
    /// Build parameters.
    pub params: LibraryParams,
    /// Templates, `templates[i].id == i`.
    pub templates: Vec<Template>,
}

/// Farthest-point selection of up to `n` indices of `pts`.
fn spread_select(pts: &[(i32, i32)], n: usize) -> Vec<usize> {
    if pts.is_empty() || n == 0 {
        return vec![];
    }
    if pts.len() <= n {
        return (0..pts.len()).collect();
    }
    let (sx, sy) = pts.iter().fold((0i64, 0i64), |a, p| (a.0 + p.0 as i64, a.1 + p.1 as i64));
    let (mx, my) = (sx as f64 / pts.len() as f64, sy as f64 / pts.len() as f64);
    let d2c = |p: &(i32, i32)| (p.0 as f64 - mx).powi(2) + (p.1 as f64 - my).powi(2);
    let mut first = 0;
    for (i, p) in pts.iter().enumerate() {
        if d2c(p) > d2c(&pts[first]) {
            first = i;
        }
    }
    let mut dist = vec![i64::MAX; pts.len()];
    let mut out = Vec::with_capacity(n);
    let mut cur = first;
    for _ in 0..n {
        out.push(cur);
        let c = pts[cur];
        let mut best = 0;
        for (i, p) in pts.iter().enumerate() {
            let d = ((p.0 - c.0) as i64).pow(2) + ((p.1 - c.1) as i64).pow(2);
            if d < dist[i] {
                dist[i] = d;
            }
            if dist[i] > dist[best] {
                best = i;
            }
        }
        cur = best;
    }
    out
}

/// Contour features of a 0/1 mask of size `w x h` (outside the box counts as 0).
pub fn mask_features(mask: &[u8], w: usize, h: usize, n: usize) -> Vec<Feature> {
    let at = |x: i64, y: i64| -> f32 {
        if x < 0 || y < 0 || x >= w as i64 || y >= h as i64 {
            0.0
        } else {
            mask[y as usize * w + x as usize] as f32
        }
    };
    let mut pts = Vec::new();
    let mut oris = Vec::new();
    for y in 0..h as i64 {
        for x in 0..w as i64 {
            if at(x, y) == 0.0 {
                continue;
            }
            let interior = (-1..=1).all(|dy| (-1..=1).all(|dx| at(x + dx, y + dy) != 0.0));
            if interior {
                continue;
            }
            let gx = at(x + 1, y - 1) + 2.0 * at(x + 1, y) + at(x + 1, y + 1) - at(x - 1, y - 1) - 2.0 * at(x - 1, y) - at(x - 1, y + 1);
            let gy = at(x - 1, y + 1) + 2.0 * at(x, y + 1) + at(x + 1, y + 1) - at(x - 1, y - 1) - 2.0 * at(x, y - 1) - at(x + 1, y - 1);
            if gx == 0.0 && gy == 0.0 {
                continue;
            }
            pts.push((x as i32, y as i32));
            oris.push(orientation_bin(gx, gy));
        }
    }
    spread_select(&pts, n).into_iter().map(|i| Feature { x: pts[i].0 as u16, y: pts[i].1 as u16, ori: oris[i] }).collect()
}

/// Halves a 0/1 mask: a pixel is on when at least 2 of its 4 children are.
pub fn downsample_mask(mask: &[u8], w: usize, h: usize) -> (Vec<u8>, usize, usize) {
    let (w2, h2) = (w.div_ceil(2), h.div_ceil(2));
    let mut out = vec![0u8; w2 * h2];
    for y in 0..h2 {
        for x in 0..w2 {
            let mut s = 0;
            for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let (xx, yy) = (2 * x + dx, 2 * y + dy);
                if xx < w && yy < h {
                    s += mask[yy * w + xx];
                }
            }
            out[y * w2 + x] = (s >= 2) as u8;
        }
    }
    (out, w2, h2)
}

impl Template {
    /// Builds a template from a silhouette rendered with the tube centre at pixel `(cx, cy)`.
    /// Returns `None` when the silhouette is empty or too large for 16-bit coordinates.
    pub fn from_silhouette(id: u32, view: &ViewSpec, sil: &Silhouette, cx: f64, cy: f64, n_features: usize) -> Option<Template> {
        let (w, h) = (sil.width, sil.height);
        let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
        for y in 0..h {
            for x in 0..w {
                if sil.mask[y * w + x] != 0 {
                    x0 = x0.min(x);
                    y0 = y0.min(y);
                    x1 = x1.max(x + 1);
                    y1 = y1.max(y + 1);
                }
            }
        }
        if x0 == usize::MAX || x1 - x0 > u16::MAX as usize / 2 || y1 - y0 > u16::MAX as usize / 2 {
            return None;
        }
        let (tw, th) = (x1 - x0, y1 - y0);
        let mut mask = vec![0u8; tw * th];
        for y in 0..th {
            mask[y * tw..(y + 1) * tw].copy_from_slice(&sil.mask[(y + y0) * w + x0..(y + y0) * w + x1]);
        }
        let f0 = mask_features(&mask, tw, th, n_features);
        let (m1, w1, h1) = downsample_mask(&mask, tw, th);
        let f1 = mask_features(&m1, w1, h1, n_features);
        if f0.is_empty() || f1.is_empty() {
            return None;
        }
        Some(Template {
            id,
            alpha_deg: view.alpha_deg as f32,
            psi_deg: view.psi_deg as f32,
            distance: view.distance as f32,
            t_cam_tube: view.t_cam_tube,
            centre: [(cx - (sil.x0 as f64 + x0 as f64)) as f32, (cy - (sil.y0 as f64 + y0 as f64)) as f32],
            levels: vec![TemplateLevel { width: tw as u16, height: th as u16, features: f0 }, TemplateLevel { width: w1 as u16, height: h1 as u16, features: f1 }],
            area: mask.iter().map(|&m| m as u32).sum(),
            mask,
        })
    }

    /// The tube's axis direction `R_cam_tube e_z` in the template camera frame.
    pub fn axis(&self) -> nalgebra::Vector3<f64> {
        self.t_cam_tube.rotation().column(2).into_owned()
    }
}

impl TemplateLibrary {
    /// The default library: the default tube model seen through [`LibraryParams::default`] (the
    /// paper's camera at half resolution, 1-4 m, 10-degree views; 8308 templates), what `tubeloc
    /// templates build` writes at its defaults. Line2D searches any camera's image with it by
    /// resampling the image to its pixel scale; building it takes about 1 s on 2 cores. It is
    /// taken through the `.tlt` format, so that it is the library a saved copy loads (template
    /// poses to the bit).
    pub fn default_library() -> Result<TemplateLibrary, Line2dError> {
        let built = Self::build(&TubeModel::default(), &LibraryParams::default(), &|_| {})?;
        TemplateLibrary::from_bytes(&built.to_bytes()).map_err(|e| Line2dError::invalid("default library", e))
    }

    /// Renders and extracts all templates of `params` for `tube` (rayon across views).
    /// `progress` is called with the number of templates done so far (from any thread).
    pub fn build(tube: &TubeModel, params: &LibraryParams, progress: &(dyn Fn(usize) + Sync)) -> Result<TemplateLibrary, Line2dError> {
        Self::build_with(params, progress, |k, pose| render_silhouette(tube, k, pose, None))
    }

    /// Like [`TemplateLibrary::build`], with silhouettes rendered from a triangle mesh
    /// ([`crate::line2d::mesh`]) instead of the parametric model.
    pub fn build_from_mesh(shape: &MeshShape, params: &LibraryParams, progress: &(dyn Fn(usize) + Sync)) -> Result<TemplateLibrary, Line2dError> {
        Self::build_with(params, progress, |k, pose| render_mesh_silhouette(shape, k, pose, None))
    }

    /// Builds a library with `render(intrinsics, T_cam_tube)` giving each view's silhouette.
    pub fn build_with(params: &LibraryParams, progress: &(dyn Fn(usize) + Sync), render: impl Fn(&Pinhole, &Pose) -> Silhouette + Sync) -> Result<TemplateLibrary, Line2dError> {
        if params.features == 0 || params.features > 4096 {
            return Err(Line2dError::invalid("features", format!("must be in 1..=4096, got {}", params.features)));
        }
        let k = params.camera;
        if !(k.fx > 0.0 && k.fy > 0.0 && k.fx.is_finite() && k.fy.is_finite()) {
            return Err(Line2dError::invalid("camera", "focal lengths must be positive"));
        }
        let views = generate_views(&params.views)?;
        let done = std::sync::atomic::AtomicUsize::new(0);
        let built: Vec<Option<Template>> = views
            .par_iter()
            .map(|v| {
                let sil = render(&k, &v.t_cam_tube);
                let t = Template::from_silhouette(0, v, &sil, k.cx, k.cy, params.features as usize);
                progress(done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1);
                t
            })
            .collect();
        let mut templates: Vec<Template> = built.into_iter().flatten().collect();
        for (i, t) in templates.iter_mut().enumerate() {
            t.id = i as u32;
        }
        if templates.is_empty() {
            return Err(Line2dError::invalid("library", "no template could be rendered (tube outside every view?)"));
        }
        Ok(TemplateLibrary { params: params.clone(), templates })
    }

    /// Number of templates.
    pub fn len(&self) -> usize {
        self.templates.len()
    }

    /// True when the library has no templates.
    pub fn is_empty(&self) -> bool {
        self.templates.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rectangle_features_are_on_contour_with_edge_orientations() {
        let (w, h) = (40, 10);
        let mask = vec![1u8; w * h];
        let f = mask_features(&mask, w, h, 200);
        assert_eq!(f.len(), 2 * w + 2 * (h - 2));
        for ft in &f {
            let on_lr = ft.x == 0 || ft.x as usize == w - 1;
            let on_tb = ft.y == 0 || ft.y as usize == h - 1;
            assert!(on_lr || on_tb);
            if on_lr && !on_tb {
                assert_eq!(ft.ori, 0, "left/right edges have horizontal gradients");
            }
            if on_tb && !on_lr {
                assert_eq!(ft.ori, 4, "top/bottom edges have vertical gradients");
            }
        }
        // Spread-out selection: 8 features over the perimeter, pairwise well apart.
        let g = mask_features(&mask, w, h, 8);
        assert_eq!(g.len(), 8);
        for i in 0..8 {
            for j in 0..i {
                let d = ((g[i].x as f64 - g[j].x as f64).powi(2) + (g[i].y as f64 - g[j].y as f64).powi(2)).sqrt();
                assert!(d >= 5.0, "features {i},{j} only {d} px apart");
            }
        }
    }
}
