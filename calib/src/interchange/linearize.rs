//! An image taken through a CAHVORE lens ([`super::cahvore`]), resampled into a pinhole camera:
//! each pixel `(u, v)` of the pinhole takes the raw image at the CAHVORE image of a point far
//! along its ray,
//!
//! ```text
//! (x, y) = CAHVORE(C_pin + D R_rig_cam K⁻¹ (u, v, 1)),   D = 1000 m,
//! ```
//!
//! sampled bilinearly; pixels whose rays the lens does not image, or that fall outside the raw
//! frame, are 0. The far point leaves out the entrance pupil's movement with the range: its
//! terms are millimetres, a few hundredths of a pixel at the 0.5 m of the nearest ground a
//! hazard camera sees.

use super::cahvore::Cahvore;
use image::{DynamicImage, ImageBuffer, Luma, LumaA, Rgb, Rgba};
use nalgebra::Point2;
use rayon::prelude::*;
use tubeloc_core::RigCamera;

/// Range (m) of the point each pinhole ray is imaged at.
const FAR_M: f64 = 1000.0;

/// Where each pixel of a pinhole camera lies in the raw image of a CAHVORE camera.
#[derive(Clone, Debug)]
pub struct LinearResampling {
    width: u32,
    height: u32,
    /// Raw-image position (column, row) of each pinhole pixel, row-major; NaN where none.
    source: Vec<[f32; 2]>,
}

impl LinearResampling {
    /// The resampling of images of `raw` (a CAHVORE model in the rig frame) into `pinhole` (a
    /// camera of that rig, its distortion ignored), for a raw image of `raw_size` pixels.
    pub fn new(raw: &Cahvore, pinhole: &RigCamera, raw_size: (u32, u32)) -> Self {
        let m = &pinhole.model;
        let (r, c) = (pinhole.t_rig_cam.rotation(), pinhole.t_rig_cam.translation());
        let (w, h) = (m.width, m.height);
        let (rw, rh) = (raw_size.0 as f64 - 1.0, raw_size.1 as f64 - 1.0);
        let source = (0..h)
            .into_par_iter()
            .flat_map_iter(|v| {
                (0..w).map(move |u| {
                    let dir = r * m.unproject(&Point2::new(u as f64, v as f64)).normalize();
                    match raw.project(&(c + FAR_M * dir)) {
                        Some((x, y)) if (0.0..=rw).contains(&x) && (0.0..=rh).contains(&y) => [x as f32, y as f32],
                        _ => [f32::NAN; 2],
                    }
                })
            })
            .collect();
        LinearResampling { width: w, height: h, source }
    }

    /// The raw-image position (column, row) pinhole pixel `(u, v)` takes, `None` where it
    /// takes none.
    pub fn source_of(&self, u: u32, v: u32) -> Option<Point2<f64>> {
        let [x, y] = *self.source.get((v as usize) * self.width as usize + u as usize)?;
        (u < self.width && !x.is_nan()).then(|| Point2::new(x as f64, y as f64))
    }

    /// Share of the pinhole's pixels that the raw image covers.
    pub fn coverage(&self) -> f64 {
        self.source.iter().filter(|p| !p[0].is_nan()).count() as f64 / self.source.len().max(1) as f64
    }

    /// The pinhole image of the raw image `raw`, in its sample type (grey, grey-alpha, RGB or
    /// RGBA, 8 or 16 bits; other types as 8-bit RGB).
    pub fn apply(&self, raw: &DynamicImage) -> DynamicImage {
        let (w, h) = (self.width, self.height);
        let src = (raw.width() as usize, raw.height() as usize);
        macro_rules! warp {
            ($buf:expr, $px:ident, $t:ty) => {{
                let b = $buf;
                let ch = b.as_raw().len() / (src.0 * src.1).max(1);
                let data = self.warp_samples(b.as_raw(), src, ch, |x| x as $t);
                ImageBuffer::<$px<$t>, Vec<$t>>::from_raw(w, h, data).expect("warped buffer matches its size")
            }};
        }
        match raw {
            DynamicImage::ImageLuma8(b) => warp!(b, Luma, u8).into(),
            DynamicImage::ImageLumaA8(b) => warp!(b, LumaA, u8).into(),
            DynamicImage::ImageRgb8(b) => warp!(b, Rgb, u8).into(),
            DynamicImage::ImageRgba8(b) => warp!(b, Rgba, u8).into(),
            DynamicImage::ImageLuma16(b) => warp!(b, Luma, u16).into(),
            DynamicImage::ImageLumaA16(b) => warp!(b, LumaA, u16).into(),
            DynamicImage::ImageRgb16(b) => warp!(b, Rgb, u16).into(),
            DynamicImage::ImageRgba16(b) => warp!(b, Rgba, u16).into(),
            other => warp!(&other.to_rgb8(), Rgb, u8).into(),
        }
    }

    /// Bilinear samples of the `ch`-channel image `src` (`size` pixels) at each source
    /// position, rounded to the nearest level by `back` (which truncates: it gets `value + 0.5`).
    fn warp_samples<T: Copy + Into<f32> + Send + Sync + Default>(&self, src: &[T], size: (usize, usize), ch: usize, back: impl Fn(f32) -> T + Sync) -> Vec<T> {
        let (sw, sh) = size;
        let mut out = vec![T::default(); self.source.len() * ch];
        out.par_chunks_mut(self.width as usize * ch).zip(self.source.par_chunks(self.width as usize)).for_each(|(row, from)| {
            for (px, &[x, y]) in row.chunks_exact_mut(ch).zip(from) {
                if x.is_nan() {
                    continue;
                }
                // Sources lie within the raw frame (`new`): 0 <= x <= sw - 1, 0 <= y <= sh - 1.
                let (xf, yf) = (x.floor(), y.floor());
                let (x0, y0) = ((xf as usize).min(sw - 1), (yf as usize).min(sh - 1));
                let (dx, dy) = (usize::from(x0 + 1 < sw) * ch, usize::from(y0 + 1 < sh) * sw * ch);
                let (fx, fy) = (x - xf, y - yf);
                let (w00, w01, w10, w11) = ((1.0 - fx) * (1.0 - fy), fx * (1.0 - fy), (1.0 - fx) * fy, fx * fy);
                let i = (y0 * sw + x0) * ch;
                for (k, s) in px.iter_mut().enumerate() {
                    let v = src[i + k].into() * w00 + src[i + dx + k].into() * w01 + src[i + dy + k].into() * w10 + src[i + dy + dx + k].into() * w11;
                    *s = back(v + 0.5);
                }
            }
        });
        out
    }
}

#[cfg(test)]
mod tests {
    use super::super::cahv::{Cahv, Cahvor};
    use super::*;
    use nalgebra::{Point3, Vector3};
    use tubeloc_core::{CameraModel, Pose};

    /// The pinhole pixel of the rig-frame point `p` and the raw pixel of the same point.
    fn pinhole_and_raw_pixel(raw: &Cahvore, pinhole: &RigCamera, p: &Point3<f64>) -> Option<(Point2<f64>, (f64, f64))> {
        let in_cam = pinhole.t_rig_cam.inverse().transform_point(p);
        Some((pinhole.model.project(&in_cam)?, raw.project(&p.coords)?))
    }

    /// A fisheye looking along the rig's +z with the CAHV part of a 200x160 pinhole, f 90 px.
    fn fisheye() -> (Cahvore, RigCamera) {
        let (f, cx, cy) = (90.0, 99.5, 79.5);
        let cahv = Cahv { c: Vector3::new(0.1, -0.2, 0.3), a: Vector3::z(), h: Vector3::new(f, 0.0, cx), v: Vector3::new(0.0, f, cy) };
        let raw = Cahvore { cahvor: Cahvor { cahv, o: Vector3::z(), r: [0.0, -0.01, 0.0] }, e: [0.001, 0.0, 0.0], linearity: 0.0 };
        let model = CameraModel { width: 200, height: 160, fx: f, fy: f, cx, cy, distortion: Default::default() };
        let pinhole = RigCamera { name: "haz".into(), model, t_rig_cam: Pose::from_parts(Default::default(), cahv.c) };
        (raw, pinhole)
    }

    #[test]
    fn a_resampled_pixel_shows_the_raw_pixel_its_ray_images_at() {
        let (raw, pinhole) = fisheye();
        let map = LinearResampling::new(&raw, &pinhole, (200, 160));
        // A fisheye of the same central scale sees more than the pinhole: every pixel is covered.
        assert_eq!(map.coverage(), 1.0);
        let p = Point3::new(0.5, 0.4, 2.0);
        let (pin, (x, y)) = pinhole_and_raw_pixel(&raw, &pinhole, &p).unwrap();
        let (u, v) = (pin.x.round() as u32, pin.y.round() as u32);
        let src = map.source_of(u, v).unwrap();
        // One pinhole pixel spans at most about a raw pixel here.
        assert!((src.x - x).abs() < 1.0 && (src.y - y).abs() < 1.0, "{src:?} vs ({x}, {y})");
        // A gradient image along x: the resampled value is the raw column it came from.
        let grad = ImageBuffer::from_fn(200, 160, |x, _| Luma([x as u16 * 300]));
        let out = map.apply(&DynamicImage::ImageLuma16(grad));
        let got = out.as_luma16().unwrap().get_pixel(u, v).0[0] as f64;
        assert!((got - 300.0 * src.x).abs() <= 0.5, "{got} vs {}", 300.0 * src.x);
        assert_eq!((out.width(), out.height()), (200, 160));
    }

    #[test]
    fn pixels_the_raw_frame_does_not_cover_are_black() {
        let (raw, pinhole) = fisheye();
        // A raw frame of half the width: the pinhole's right half has no source.
        let map = LinearResampling::new(&raw, &pinhole, (100, 160));
        assert!(map.coverage() > 0.3 && map.coverage() < 0.7, "{}", map.coverage());
        assert!(map.source_of(199, 80).is_none() && map.source_of(0, 80).is_some() && map.source_of(200, 0).is_none());
        let white = DynamicImage::ImageRgb8(ImageBuffer::from_pixel(100, 160, Rgb([255, 255, 255])));
        let out = map.apply(&white).into_rgb8();
        assert_eq!((out.get_pixel(199, 80).0, out.get_pixel(10, 80).0), ([0; 3], [255; 3]));
    }
}
