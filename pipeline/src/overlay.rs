//! The overlay image: fitted contours drawn over the grey image.

use nalgebra::Point3;
use tubeloc_core::{CameraModel, Plane, TubeAxisPose};
use tubeloc_refine::Refiner;

/// An RGB copy of `gray` with each pose's fitted contour (every 0.5 px) and a 7 px cross at its
/// centre drawn, green for converged poses and red for rejected ones, in order.
pub fn draw<'a>(gray: &Plane<u8>, refiner: &Refiner, cam: &CameraModel, poses: impl IntoIterator<Item = &'a TubeAxisPose>) -> image::RgbImage {
    let (w, h) = (gray.width as u32, gray.height as u32);
    let mut img = image::RgbImage::from_fn(w, h, |x, y| {
        let v = gray.get(x as usize, y as usize);
        image::Rgb([v, v, v])
    });
    for p in poses {
        let col = if p.converged { [40, 230, 60] } else { [240, 40, 40] };
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
    // Fast compression: the overlay is for viewing (5.86 MB at 5472x3648, as with the default).
    let mut buf = Vec::new();
    PngEncoder::new_with_quality(&mut buf, CompressionType::Fast, FilterType::Adaptive).write_image(img.as_raw(), img.width(), img.height(), image::ExtendedColorType::Rgb8)?;
    Ok(buf)
}
