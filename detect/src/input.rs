//! Rover camera images of any format (PNG, JPEG, TIFF, PGM / PPM / PNM, BMP, WebP, PDS3
//! products) as the detectors' input: 8-bit sRGB, interleaved RGB.
//!
//! Every detector and the training loader go through [`rgb8_of`], so training and inference
//! see the same conversion:
//! - 8-bit grey, grey + alpha, RGB and RGBA (alpha dropped; grey replicated to three channels);
//! - 16-bit containers hold data of some real bit depth (12-bit for rover EDRs), mapped by
//!   [`tubeloc_core::bit_depth`]: `v · 255 / (2^b - 1)` with `b` the bits of the largest value
//!   (at least 8), so 12-bit data fill the 8-bit range instead of being divided by 257;
//! - 32-bit float images are taken as `[0, 1]`.
//!
//! [`InputInfo`] says what was found, and [`InputInfo::warning`] flags inputs that cannot give
//! detections (a flat image), so that an empty result is never silent.

use std::path::Path;

/// What an input image was, before conversion.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct InputInfo {
    /// Channels in the file (1 grey, 2 grey + alpha, 3 RGB, 4 RGBA).
    pub channels: u8,
    /// Bits per channel of the container (8, 16 or 32).
    pub container_bits: u8,
    /// Bits of the data found in the container (the largest value's), used for the mapping.
    pub data_bits: u8,
    /// Whether the image is grey (one channel, or three equal channels).
    pub grey: bool,
    /// Standard deviation of the 8-bit luminance, DN.
    pub luminance_std: f64,
}

impl InputInfo {
    /// A warning for inputs on which no detector can find anything, or `None`.
    pub fn warning(&self) -> Option<String> {
        (self.luminance_std < 0.5).then(|| format!("the image is flat (luminance standard deviation {:.2} DN after conversion to 8 bits): nothing can be detected in it", self.luminance_std))
    }
}

/// An image converted for the detectors.
#[derive(Clone, Debug)]
pub struct DetectorInput {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Interleaved sRGB bytes, `width * height * 3`.
    pub rgb: Vec<u8>,
    /// What the source was.
    pub info: InputInfo,
}

pub use tubeloc_core::monochrome::is_grey_rgb8;

/// Converts a decoded image (see the module doc).
pub fn rgb8_of(img: &image::DynamicImage) -> DetectorInput {
    use image::DynamicImage as D;
    let (w, h) = (img.width() as usize, img.height() as usize);
    let channels = img.color().channel_count();
    let (rgb, container_bits, bits): (Vec<u8>, u8, u8) = match img {
        D::ImageLuma16(_) | D::ImageLumaA16(_) | D::ImageRgb16(_) | D::ImageRgba16(_) => {
            let (levels, b) = tubeloc_core::bit_depth::eight_bit_levels(img.to_rgb16().as_raw());
            (levels, 16, b)
        }
        D::ImageRgb32F(_) | D::ImageRgba32F(_) => {
            let f = img.to_rgb32f();
            (f.as_raw().iter().map(|&v| (v.clamp(0.0, 1.0) * 255.0).round() as u8).collect(), 32, 8)
        }
        _ => (img.to_rgb8().into_raw(), 8, 8),
    };
    let grey = channels <= 2 || is_grey_rgb8(&rgb);
    let n = (w * h).max(1) as f64;
    let (mut s, mut s2) = (0.0f64, 0.0f64);
    for p in rgb.chunks_exact(3) {
        let l = 0.299 * p[0] as f64 + 0.587 * p[1] as f64 + 0.114 * p[2] as f64;
        s += l;
        s2 += l * l;
    }
    let var = (s2 / n - (s / n) * (s / n)).max(0.0);
    let info = InputInfo { channels, container_bits, data_bits: bits, grey, luminance_std: var.sqrt() };
    DetectorInput { width: w, height: h, rgb, info }
}

/// The interleaved RGB8 pixels of `img` as the detectors read them: an RGB8 image's own bytes,
/// borrowed; any other format converted by [`rgb8_of`] (16-bit data at their real bit depth).
pub fn rgb8_pixels(img: &image::DynamicImage) -> std::borrow::Cow<'_, [u8]> {
    match img {
        image::DynamicImage::ImageRgb8(rgb) => std::borrow::Cow::Borrowed(rgb.as_raw().as_slice()),
        _ => std::borrow::Cow::Owned(rgb8_of(img).rgb),
    }
}

/// A decoded image at 8 bits per channel, as every stage reads it (detectors, refiner,
/// stereo, tags): 8-bit images come back unchanged; 16-bit and float images are mapped by
/// [`rgb8_of`] (their real bit depth, never a fixed division by 257), grey ones to 8-bit grey
/// and the others to RGB8 (alpha dropped).
pub fn eight_bit(img: image::DynamicImage) -> image::DynamicImage {
    to_eight_bit(&img).unwrap_or(img)
}

/// [`eight_bit`] of an image that is not 8-bit; `None` for an 8-bit one (nothing to convert).
pub fn to_eight_bit(img: &image::DynamicImage) -> Option<image::DynamicImage> {
    use image::DynamicImage as D;
    if matches!(img, D::ImageLuma8(_) | D::ImageLumaA8(_) | D::ImageRgb8(_) | D::ImageRgba8(_)) {
        return None;
    }
    let (w, h) = (img.width(), img.height());
    let c = rgb8_of(img);
    Some(if img.color().channel_count() <= 2 {
        D::ImageLuma8(image::GrayImage::from_raw(w, h, c.rgb.chunks_exact(3).map(|p| p[0]).collect()).expect("w x h levels"))
    } else {
        D::ImageRgb8(image::RgbImage::from_raw(w, h, c.rgb).expect("w x h x 3 bytes"))
    })
}

/// File name extensions (any case) of the image files a folder is read for: PNG, JPEG, TIFF,
/// PGM / PPM / PNM (16-bit samples of any `maxval`), BMP, WebP, and PDS3 products (`.img`
/// with an attached label; a detached `.lbl` stands for its `.img`, see
/// [`has_image_extension`]).
pub const IMAGE_EXTENSIONS: [&str; 11] = ["png", "jpg", "jpeg", "tif", "tiff", "pgm", "ppm", "pnm", "bmp", "webp", "img"];

/// Whether `path` has one of [`IMAGE_EXTENSIONS`] (any case). A PDS3 label (`.lbl`) is not
/// one by itself: a folder listing takes it in place of the `.img` of the same stem beside it.
pub fn has_image_extension(path: &Path) -> bool {
    path.extension().and_then(|e| e.to_str()).is_some_and(|e| IMAGE_EXTENSIONS.iter().any(|x| x.eq_ignore_ascii_case(e)))
}

/// The image files of the folder `dir` (not of its subfolders), sorted: those with one of
/// [`IMAGE_EXTENSIONS`], a PDS3 product's detached `.lbl` label in place of the `.img` of the
/// same stem beside it (the `.img` holds no label of its own). An empty list where there are
/// none; an error where the folder cannot be read.
pub fn image_files(dir: &Path) -> std::io::Result<Vec<std::path::PathBuf>> {
    let (mut paths, mut labels) = (Vec::new(), Vec::new());
    for entry in std::fs::read_dir(dir)? {
        let p = entry?.path();
        if !p.is_file() {
            continue;
        }
        if has_image_extension(&p) {
            paths.push(p);
        } else if p.extension().is_some_and(|e| e.eq_ignore_ascii_case("lbl")) {
            labels.push(p);
        }
    }
    let stem = |p: &Path| p.file_stem().map(|s| s.to_ascii_lowercase());
    let is_product = |p: &Path| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("img"));
    let products: std::collections::HashMap<_, usize> = paths.iter().enumerate().filter(|(_, p)| is_product(p)).map(|(k, p)| (stem(p), k)).collect();
    for label in labels {
        if let Some(&k) = products.get(&stem(&label)) {
            paths[k] = label;
        }
    }
    paths.sort();
    Ok(paths)
}

/// Decodes an image file (PNG, JPEG, TIFF, PGM / PPM / PNM, BMP, WebP, or a PDS3 product:
/// [`crate::pds3_image`]), its format told by its bytes; a JPEG cut short is an error
/// ([`tubeloc_core::image_file::read_whole`]), not an image with blank rows.
pub fn open_image(path: impl AsRef<Path>) -> Result<image::DynamicImage, image::ImageError> {
    let path = path.as_ref();
    let bytes = tubeloc_core::image_file::read_whole(path)?;
    if tubeloc_core::odl::looks_like_pds3_label(&bytes) {
        return crate::pds3_image::decode(&bytes, path).map_err(invalid_data);
    }
    if bytes.starts_with(b"LBLSIZE=") {
        return Err(invalid_data(vicar_without_label(path)));
    }
    image::load_from_memory(&bytes).map_err(|e| match e {
        image::ImageError::Unsupported(u) => {
            let hint = match u.kind() {
                image::error::UnsupportedErrorKind::Color(_) => "tubeloc reads 8- and 16-bit integer samples, grey, grey + alpha, RGB or RGBA; convert other sample types, e.g. 32-bit floating point, first",
                _ => "tubeloc reads PNG, JPEG, TIFF, PGM / PPM / PNM, BMP, WebP and PDS3 products",
            };
            invalid_data(format!("{u} ({hint})"))
        }
        e => e,
    })
}

/// The error for a VICAR file without a PDS3 label at its head.
fn vicar_without_label(path: &Path) -> String {
    format!("{}: a VICAR image without a PDS3 label at its head; give its detached PDS3 label (.LBL), whose ^IMAGE points into it", path.display())
}

fn invalid_data(message: String) -> image::ImageError {
    image::ImageError::IoError(std::io::Error::new(std::io::ErrorKind::InvalidData, message))
}

/// The width and height of an image file (or PDS3 product) from its header (the pixels are not decoded); an
/// empty file is refused as such ([`tubeloc_core::image_file::check_complete`]).
pub fn image_size(path: impl AsRef<Path>) -> Result<(u32, u32), image::ImageError> {
    let path = path.as_ref();
    if std::fs::metadata(path)?.len() == 0 {
        tubeloc_core::image_file::check_complete(&[]).map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidData, e))?;
    }
    // A PDS3 label (tens of kB) gives the size without the samples.
    let head = tubeloc_core::odl::read_head(path)?;
    if tubeloc_core::odl::looks_like_pds3_label(&head) {
        return crate::pds3_image::size(&head, path).map_err(invalid_data);
    }
    if head.starts_with(b"LBLSIZE=") {
        return Err(invalid_data(vicar_without_label(path)));
    }
    // By the file's content, as `open_image` decodes it, not by its extension (a PNG saved
    // under a `.jpg` name).
    image::ImageReader::open(path)?.with_guessed_format()?.into_dimensions()
}

/// Opens an image file (any format of [`IMAGE_EXTENSIONS`]) by [`open_image`] as [`eight_bit`].
pub fn open_eight_bit(path: impl AsRef<Path>) -> Result<image::DynamicImage, image::ImageError> {
    open_image(path).map(eight_bit)
}

/// Reads an image file (any format of [`IMAGE_EXTENSIONS`]) by [`open_image`] and converts it
/// (see the module doc). The error names the file.
pub fn load(path: &Path) -> Result<DetectorInput, String> {
    let img = open_image(path).map_err(|e| format!("{}: {e}", path.display()))?;
    Ok(rgb8_of(&img))
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::{ImageBuffer, Luma, Rgb, Rgba};

    #[test]
    fn a_vicar_file_without_a_pds3_label_is_refused_with_the_way_out() {
        let dir = tempfile::tempdir().unwrap();
        let vic = dir.path().join("n.IMG");
        std::fs::write(&vic, b"LBLSIZE=2048   FORMAT='BYTE'  TYPE='IMAGE'").unwrap();
        for err in [open_image(&vic).unwrap_err().to_string(), image_size(&vic).unwrap_err().to_string()] {
            assert!(err.contains("n.IMG") && err.contains("VICAR") && err.contains(".LBL"), "{err}");
        }
    }

    #[test]
    fn an_unreadable_file_says_which_formats_and_samples_are_read() {
        let dir = tempfile::tempdir().unwrap();
        let text = dir.path().join("notes.png");
        std::fs::write(&text, "not an image").unwrap();
        let e = open_image(&text).unwrap_err().to_string();
        assert!(e.contains("could not be determined") && e.contains("PGM / PPM / PNM, BMP, WebP and PDS3"), "{e}");
        // A TIFF of 32-bit floating-point grey samples (one strip, little-endian).
        let tif = dir.path().join("float.tif");
        let (w, h) = (2u32, 2u32);
        let mut b: Vec<u8> = b"II*\0".to_vec();
        b.extend(8u32.to_le_bytes());
        let entries: [(u16, u16, u32, u32); 9] = [(256, 4, 1, w), (257, 4, 1, h), (258, 3, 1, 32), (259, 3, 1, 1), (262, 3, 1, 1), (273, 4, 1, 8 + 2 + 9 * 12 + 4), (277, 3, 1, 1), (279, 4, 1, w * h * 4), (339, 3, 1, 3)];
        b.extend((entries.len() as u16).to_le_bytes());
        for (tag, ty, n, v) in entries {
            b.extend(tag.to_le_bytes());
            b.extend(ty.to_le_bytes());
            b.extend(n.to_le_bytes());
            b.extend(if ty == 3 { (v as u16 as u32).to_le_bytes() } else { v.to_le_bytes() });
        }
        b.extend(0u32.to_le_bytes());
        b.extend([0.25f32, 0.5, 0.75, 1.0].iter().flat_map(|v| v.to_le_bytes()));
        std::fs::write(&tif, &b).unwrap();
        let e = open_image(&tif).unwrap_err().to_string();
        assert!(e.contains("8- and 16-bit integer samples") && e.contains("floating point"), "{e}");
    }

    #[test]
    fn image_size_reads_the_header_and_refuses_an_empty_file() {
        let dir = tempfile::tempdir().unwrap();
        let png = dir.path().join("a.png");
        image::GrayImage::new(7, 5).save(&png).unwrap();
        assert_eq!(image_size(&png).unwrap(), (7, 5));
        let empty = dir.path().join("empty.png");
        std::fs::write(&empty, []).unwrap();
        assert!(image_size(&empty).unwrap_err().to_string().contains("empty (0 bytes)"));
        assert!(image_size(dir.path().join("missing.png")).is_err());
        // A PNG under a JPEG's name: read by its content, as open_image reads it.
        let misnamed = dir.path().join("a.jpg");
        std::fs::copy(&png, &misnamed).unwrap();
        assert_eq!(image_size(&misnamed).unwrap(), (7, 5));
        assert_eq!((open_image(&misnamed).unwrap().width(), open_image(&misnamed).unwrap().height()), (7, 5));
    }

    #[test]
    fn twelve_bit_data_fill_the_eight_bit_range() {
        let img = ImageBuffer::<Luma<u16>, _>::from_fn(4, 1, |x, _| Luma([[0u16, 1000, 2000, 4095][x as usize]]));
        let c = rgb8_of(&image::DynamicImage::ImageLuma16(img));
        assert_eq!(c.info.data_bits, 12);
        assert_eq!(c.info.container_bits, 16);
        assert!(c.info.grey);
        let grey: Vec<u8> = c.rgb.chunks(3).map(|p| p[0]).collect();
        assert_eq!(grey, vec![0, 62, 125, 255]);
    }

    #[test]
    fn full_sixteen_bit_and_eight_bit_agree() {
        let img8 = ImageBuffer::<Rgb<u8>, _>::from_fn(3, 2, |x, y| Rgb([(x * 80) as u8, (y * 100) as u8, 7]));
        let img16 = ImageBuffer::<Rgb<u16>, _>::from_fn(3, 2, |x, y| Rgb([(x * 80 * 257) as u16, (y * 100 * 257) as u16, 7 * 257]));
        let a = rgb8_of(&image::DynamicImage::ImageRgb8(img8));
        let b = rgb8_of(&image::DynamicImage::ImageRgb16(img16));
        assert_eq!(b.info.data_bits, 16);
        assert_eq!(a.rgb, b.rgb);
        assert!(!a.info.grey);
    }

    /// 16-bit frames become 8-bit frames of the same kind at their real bit depth, and 8-bit
    /// ones are kept as they are.
    #[test]
    fn eight_bit_keeps_the_kind_and_uses_the_real_bit_depth() {
        let grey = ImageBuffer::<Luma<u16>, _>::from_fn(4, 1, |x, _| Luma([[0u16, 1000, 2000, 4095][x as usize]]));
        let g = eight_bit(image::DynamicImage::ImageLuma16(grey));
        assert_eq!(g.as_luma8().expect("grey stays grey").as_raw(), &vec![0, 62, 125, 255]);
        let rgb = ImageBuffer::<Rgb<u16>, _>::from_fn(2, 1, |x, _| Rgb([4095 * x as u16, 2000, 0]));
        let c = eight_bit(image::DynamicImage::ImageRgb16(rgb));
        assert_eq!(c.as_rgb8().expect("colour becomes RGB8").as_raw(), &vec![0, 125, 0, 255, 125, 0]);
        let eight = image::DynamicImage::ImageRgba8(ImageBuffer::from_pixel(2, 2, Rgba([1, 2, 3, 4])));
        assert_eq!(eight_bit(eight.clone()), eight);
        assert_eq!(rgb8_pixels(&c).as_ref(), c.as_rgb8().unwrap().as_raw().as_slice());
        assert_eq!(rgb8_pixels(&g).as_ref(), &[0, 0, 0, 62, 62, 62, 125, 125, 125, 255, 255, 255]);
    }

    #[test]
    fn alpha_is_dropped_and_flat_images_warn() {
        let img = ImageBuffer::<Rgba<u8>, _>::from_pixel(5, 5, Rgba([10, 20, 30, 0]));
        let c = rgb8_of(&image::DynamicImage::ImageRgba8(img));
        assert_eq!(&c.rgb[..3], &[10, 20, 30]);
        assert!(c.info.warning().is_some());
    }
}
