//! Exact silhouette + depth rendering of the parametric tube by analytic ray casting.
//!
//! Each section of the [`TubeModel`] is a capped cylinder `x² + y² <= r²`, `z0 <= z <= z1` in the
//! tube frame. For every pixel of the tube's projected bounding box, the ray `t (x_n, y_n, 1)`
//! (camera frame, `(x_n, y_n)` undistorted normalized coordinates, so `t` is the depth `Z`) is
//! moved into the tube frame and intersected with each lateral surface (quadratic in `t`) and
//! each cap disc; the smallest positive `t` is the depth.

use nalgebra::{Point3, Vector3};
use tubeloc_core::{Pose, TubeModel};

/// A rendered silhouette: the tube's mask and depth over a pixel box of the image.
#[derive(Clone, Debug, PartialEq)]
pub struct Silhouette {
    /// Image column of the box's first pixel.
    pub x0: i32,
    /// Image row of the box's first pixel.
    pub y0: i32,
    /// Box width, pixels.
    pub width: usize,
    /// Box height, pixels.
    pub height: usize,
    /// 1 where the tube covers the pixel centre, else 0; row-major over the box.
    pub mask: Vec<u8>,
    /// Depth `Z` in the camera frame (metres) where covered, `f32::INFINITY` elsewhere.
    pub depth: Vec<f32>,
}

impl Silhouette {
    /// Number of covered pixels.
    pub fn area(&self) -> usize {
        self.mask.iter().filter(|&&m| m != 0).count()
    }
}

/// Pinhole intrinsics used for rendering (no distortion), pixels; pixel centres at integers.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pinhole {
    /// Focal length x, pixels.
    pub fx: f64,
    /// Focal length y, pixels.
    pub fy: f64,
    /// Principal point x, pixels.
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
}

/// Smallest positive ray parameter `t` where the ray `o + t d` (tube frame) hits the tube.
#[inline]
pub fn intersect_tube(sections: &[(f64, f64, f64)], o: &Vector3<f64>, d: &Vector3<f64>) -> Option<f64> {
    let mut best = f64::INFINITY;
    let a = d.x * d.x + d.y * d.y;
    let b = 2.0 * (o.x * d.x + o.y * d.y);
    let c0 = o.x * o.x + o.y * o.y;
    for &(z0, z1, r) in sections {
        if a > 1e-18 {
            let c = c0 - r * r;
            let disc = b * b - 4.0 * a * c;
            if disc >= 0.0 {
                let sq = disc.sqrt();
                for t in [(-b - sq) / (2.0 * a), (-b + sq) / (2.0 * a)] {
                    if t > 0.0 && t < best {
                        let z = o.z + t * d.z;
                        if z >= z0 && z <= z1 {
                            best = t;
                        }
                    }
                }
            }
        }
        if d.z.abs() > 1e-18 {
            for zc in [z0, z1] {
                let t = (zc - o.z) / d.z;
                if t > 0.0 && t < best {
                    let x = o.x + t * d.x;
                    let y = o.y + t * d.y;
                    if x * x + y * y <= r * r {
                        best = t;
                    }
                }
            }
        }
    }
    best.is_finite().then_some(best)
}

/// The tube's sections as `(z0, z1, radius)` in the tube frame (metres, z along the axis).
fn section_spans(tube: &TubeModel) -> Vec<(f64, f64, f64)> {
    tube.sections
        .iter()
        .map(|s| {
            let (z0, z1) = tube.section_z_in_tube_frame(s);
            (z0, z1, s.radius)
        })
        .collect()
}

/// Renders the tube at `t_cam_tube` with pinhole intrinsics `k`.
///
/// The box is the projection of the tube's bounding cylinder box, grown by one pixel, and
/// clipped to `[0, clip.0) x [0, clip.1)` when `clip` is given. Returns an empty silhouette
/// (width or height 0) when the tube is behind the camera or outside the clip region.
pub fn render_silhouette(tube: &TubeModel, k: &Pinhole, t_cam_tube: &Pose, clip: Option<(usize, usize)>) -> Silhouette {
    let sections = section_spans(tube);
    let r = tube.max_radius();
    let h = tube.length / 2.0;
    let (mut umin, mut umax, mut vmin, mut vmax) = (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
    let mut behind = false;
    for i in 0..8 {
        let p = Point3::new(if i & 1 == 0 { -r } else { r }, if i & 2 == 0 { -r } else { r }, if i & 4 == 0 { -h } else { h });
        let pc = t_cam_tube.transform_point(&p);
        if pc.z <= 1e-6 {
            behind = true;
            break;
        }
        let u = k.fx * pc.x / pc.z + k.cx;
        let v = k.fy * pc.y / pc.z + k.cy;
        umin = umin.min(u);
        umax = umax.max(u);
        vmin = vmin.min(v);
        vmax = vmax.max(v);
    }
    let empty = Silhouette { x0: 0, y0: 0, width: 0, height: 0, mask: vec![], depth: vec![] };
    if behind {
        // A tube straddling the camera plane is not a useful view; callers only render tubes in front.
        return empty;
    }
    let (mut x0, mut y0) = (umin.floor() as i64 - 1, vmin.floor() as i64 - 1);
    let (mut x1, mut y1) = (umax.ceil() as i64 + 2, vmax.ceil() as i64 + 2);
    if let Some((w, hh)) = clip {
        x0 = x0.max(0);
        y0 = y0.max(0);
        x1 = x1.min(w as i64);
        y1 = y1.min(hh as i64);
    }
    if x1 <= x0 || y1 <= y0 || (x1 - x0) > 100_000 || (y1 - y0) > 100_000 {
        return empty;
    }
    let (w, hgt) = ((x1 - x0) as usize, (y1 - y0) as usize);
    let t_tube_cam = t_cam_tube.inverse();
    let o = t_tube_cam.translation();
    let rot = t_tube_cam.rotation();
    let mut mask = vec![0u8; w * hgt];
    let mut depth = vec![f32::INFINITY; w * hgt];
    for yy in 0..hgt {
        let yn = ((y0 + yy as i64) as f64 - k.cy) / k.fy;
        for xx in 0..w {
            let xn = ((x0 + xx as i64) as f64 - k.cx) / k.fx;
            let d = rot * Vector3::new(xn, yn, 1.0);
            if let Some(t) = intersect_tube(&sections, &o, &d) {
                mask[yy * w + xx] = 1;
                depth[yy * w + xx] = t as f32;
            }
        }
    }
    Silhouette { x0: x0 as i32, y0: y0 as i32, width: w, height: hgt, mask, depth }
}

/// Paints the tube at `t_cam_tube` over an interleaved RGB8 image (`w x h`): alumina parts
/// light grey-white, the seal section gold, with a simple shading across the tube
/// (`0.75 + 0.25 y/r` of the hit point's tube-frame `y`). For tests, benches and demos.
pub fn draw_tube_rgb(rgb: &mut [u8], w: usize, h: usize, tube: &TubeModel, k: &Pinhole, t_cam_tube: &Pose) {
    let sil = render_silhouette(tube, k, t_cam_tube, Some((w, h)));
    let sections = section_spans(tube);
    let inv = t_cam_tube.inverse();
    let (o, rot) = (inv.translation(), inv.rotation());
    let r = tube.max_radius();
    for yy in 0..sil.height {
        for xx in 0..sil.width {
            if sil.mask[yy * sil.width + xx] == 0 {
                continue;
            }
            let (x, y) = (sil.x0 as usize + xx, sil.y0 as usize + yy);
            let d = rot * Vector3::new((x as f64 - k.cx) / k.fx, (y as f64 - k.cy) / k.fy, 1.0);
            let Some(t) = intersect_tube(&sections, &o, &d) else { continue };
            let p = o + d * t;
            let zf = p.z + tube.length / 2.0;
            let gold = tube.sections.iter().any(|s| s.material == tubeloc_core::TubeMaterial::Gold && zf >= s.z0 && zf <= s.z1);
            let shade = 0.75 + 0.25 * (p.y / r).clamp(-1.0, 1.0);
            let c = if gold { [200.0, 165.0, 80.0] } else { [235.0, 232.0, 225.0] };
            for ch in 0..3 {
                rgb[(y * w + x) * 3 + ch] = (c[ch] * shade) as u8;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Rotation3, Vector3};

    #[test]
    fn side_view_has_expected_size_and_depth() {
        let tube = TubeModel::default();
        let k = Pinhole { fx: 1000.0, fy: 1000.0, cx: 500.0, cy: 500.0 };
        // Tube axis along camera x, 1 m away: length 150 px, body 17.1 px wide.
        let pose = Pose::from_parts(Rotation3::from_axis_angle(&Vector3::y_axis(), std::f64::consts::FRAC_PI_2), Vector3::new(0.0, 0.0, 1.0));
        let s = render_silhouette(&tube, &k, &pose, None);
        let row: usize = (500 - s.y0) as usize;
        let covered: usize = s.mask[row * s.width..(row + 1) * s.width].iter().map(|&m| m as usize).sum();
        assert!((covered as i64 - 150).abs() <= 1, "length {covered}");
        let col = (500 - s.x0) as usize;
        let across: usize = (0..s.height).map(|y| s.mask[y * s.width + col] as usize).sum();
        assert!((across as i64 - 17).abs() <= 1, "width {across}");
        let z = s.depth[row * s.width + col] as f64;
        assert!((z - (1.0 - 0.00855)).abs() < 1e-4, "depth {z}");
    }

    #[test]
    fn end_on_view_is_a_disc_of_the_near_section() {
        let tube = TubeModel::default();
        let k = Pinhole { fx: 1000.0, fy: 1000.0, cx: 100.0, cy: 100.0 };
        // Seal end (+z) toward the camera: looking along -z of the tube.
        let pose = Pose::from_parts(Rotation3::from_axis_angle(&Vector3::y_axis(), std::f64::consts::PI), Vector3::new(0.0, 0.0, 1.0));
        let s = render_silhouette(&tube, &k, &pose, None);
        // Silhouette radius = seal radius 11.5 mm at depth 0.925 m -> 12.43 px.
        let area = s.area() as f64;
        let expect = std::f64::consts::PI * (1000.0 * 0.0115 / 0.925f64).powi(2);
        assert!((area - expect).abs() / expect < 0.05, "area {area} vs {expect}");
        let c = ((100 - s.y0) as usize) * s.width + (100 - s.x0) as usize;
        assert!((s.depth[c] as f64 - 0.925).abs() < 1e-4);
    }
}
