//! Grey levels of an image file as the tag detector reads them.
//!
//! A colour JPEG stores luma `Y = 0.299 R + 0.587 G + 0.114 B` (JFIF, BT.601) beside two chroma
//! planes. The reference AprilTag detector reads that `Y` plane as it is. Decoding to RGB and
//! weighing the channels again (the `image` crate's `to_luma8` uses BT.709 weights) moves the
//! levels of coloured pixels by up to 14 DN and costs tags on real photos (record 0026), so
//! JPEGs are read as their own `Y` plane here. Every other file is decoded and converted to
//! 8-bit grey (16-bit data at their real bit depth, see [`eight_bit_grey`]).

use crate::CalibError;
use std::path::Path;

/// The luma plane of a JPEG stream (its `Y` component; a grey JPEG's only one), decoded
/// without a colour conversion. The error says why the stream cannot be decoded (a side over
/// [`crate::detect::MAX_IMAGE_SIDE`] is refused before anything is allocated).
pub fn jpeg_luma(bytes: &[u8]) -> Result<image::GrayImage, String> {
    use zune_core::{bytestream::ZCursor, colorspace::ColorSpace, options::DecoderOptions};
    let side = crate::detect::MAX_IMAGE_SIDE;
    let options = DecoderOptions::default().jpeg_set_out_colorspace(ColorSpace::Luma).set_max_width(side).set_max_height(side);
    let mut decoder = zune_jpeg::JpegDecoder::new_with_options(ZCursor::new(bytes), options);
    let levels = decoder.decode().map_err(|e| format!("JPEG decoding failed: {e:?}"))?;
    let (w, h) = decoder.dimensions().ok_or("JPEG decoding gave no size")?;
    image::GrayImage::from_raw(w as u32, h as u32, levels).ok_or_else(|| format!("JPEG decoding gave a buffer that is not {w} x {h} grey levels"))
}

/// An image converted to 8-bit grey: 8-bit images by luminance, 16-bit ones by their real bit
/// depth ([`tubeloc_core::bit_depth`]: 12-bit data fill the 8-bit range), float images taken as
/// `[0, 1]`.
pub fn eight_bit_grey(img: &image::DynamicImage) -> image::GrayImage {
    use image::DynamicImage as D;
    match img {
        D::ImageLuma16(_) | D::ImageLumaA16(_) | D::ImageRgb16(_) | D::ImageRgba16(_) => {
            let (levels, _) = tubeloc_core::bit_depth::eight_bit_levels(img.to_luma16().as_raw());
            image::GrayImage::from_raw(img.width(), img.height(), levels).expect("w x h levels")
        }
        _ => img.to_luma8(),
    }
}

/// Reads an image file as 8-bit grey for tag detection: a JPEG's luma plane
/// ([`jpeg_luma`]), any other format by [`eight_bit_grey`]. The error names the file; a JPEG cut
/// short is one ([`tubeloc_core::image_file::read_whole`]).
pub fn open_grey(path: &Path) -> Result<image::GrayImage, CalibError> {
    let bytes = tubeloc_core::image_file::read_whole(path).map_err(|e| CalibError::parse(path, e.to_string()))?;
    if tubeloc_core::image_file::is_jpeg(&bytes) {
        return jpeg_luma(&bytes).map_err(|e| CalibError::parse(path, e));
    }
    let img = image::load_from_memory(&bytes).map_err(|e| CalibError::parse(path, e.to_string()))?;
    Ok(eight_bit_grey(&img))
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::{codecs::jpeg::JpegEncoder, ImageEncoder};

    fn jpeg_of(img: &image::RgbImage) -> Vec<u8> {
        let mut bytes = Vec::new();
        JpegEncoder::new_with_quality(&mut bytes, 95).write_image(img.as_raw(), img.width(), img.height(), image::ExtendedColorType::Rgb8).unwrap();
        bytes
    }

    /// A saturated colour ramp: BT.601 luma (what a JPEG stores) and BT.709 luminance differ
    /// by tens of levels on it.
    fn colour_ramp() -> image::RgbImage {
        image::RgbImage::from_fn(64, 48, |x, y| image::Rgb([(x * 4) as u8, (255 - y * 5) as u8, if (x / 8 + y / 8) % 2 == 0 { 230 } else { 20 }]))
    }

    #[test]
    fn a_colour_jpeg_gives_its_luma_plane() {
        let rgb = colour_ramp();
        let luma = jpeg_luma(&jpeg_of(&rgb)).unwrap();
        assert_eq!(luma.dimensions(), (64, 48));
        // BT.601 luma of the source within the JPEG's quantization error.
        let errs: Vec<f64> = rgb.pixels().zip(luma.pixels()).map(|(c, l)| (0.299 * c[0] as f64 + 0.587 * c[1] as f64 + 0.114 * c[2] as f64 - l[0] as f64).abs()).collect();
        let mean = errs.iter().sum::<f64>() / errs.len() as f64;
        assert!(mean < 2.0, "mean |luma - BT.601| {mean}");
    }

    #[test]
    fn files_of_every_kind_are_read_as_eight_bit_grey() {
        let dir = tempfile::tempdir().unwrap();
        let jpg = dir.path().join("a.jpg");
        std::fs::write(&jpg, jpeg_of(&colour_ramp())).unwrap();
        assert_eq!(open_grey(&jpg).unwrap(), jpeg_luma(&std::fs::read(&jpg).unwrap()).unwrap());
        // 12-bit data in a 16-bit PNG fill the 8-bit range.
        let png = dir.path().join("b.png");
        image::ImageBuffer::<image::Luma<u16>, _>::from_fn(16, 16, |x, _| image::Luma([(x * 273) as u16])).save(&png).unwrap();
        let g = open_grey(&png).unwrap();
        assert_eq!((g.get_pixel(0, 0)[0], g.get_pixel(15, 0)[0]), (0, 255));
        // Broken files are errors naming the file.
        let bad = dir.path().join("broken.jpg");
        std::fs::write(&bad, &std::fs::read(&jpg).unwrap()[..200]).unwrap();
        let e = open_grey(&bad).unwrap_err().to_string();
        assert!(e.contains("broken.jpg"), "{e}");
        let e = open_grey(&dir.path().join("absent.png")).unwrap_err().to_string();
        assert!(e.contains("absent.png"), "{e}");
    }
}
