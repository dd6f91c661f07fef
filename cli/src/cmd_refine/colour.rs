//! Images for `tubeloc refine` read once as RGB: the grey levels feed the edge fit, the
//! colours the seal-end decision ([`tubeloc_refine::seal_end`],
//! [`tubeloc_refine::Refiner::refine_with_colour`]).

use anyhow::{Context, Result};
use std::path::Path;
use tubeloc_core::Plane;
use tubeloc_refine::seal_end::ColourImage;

/// An image file read as RGB, with its grey levels (the refiner's input).
pub(crate) struct LoadedImage {
    /// The image as interleaved RGB.
    pub rgb: image::RgbImage,
    /// Its grey levels (`image`'s luma conversion, as `cmd_stereo::load_gray`).
    pub gray: Plane<u8>,
}

impl LoadedImage {
    /// The colours for the seal-end decision, or `None` when `wanted` is false.
    pub fn colour(&self, wanted: bool) -> Option<ColourImage<'_>> {
        wanted.then(|| ColourImage { width: self.rgb.width() as usize, height: self.rgb.height() as usize, rgb: self.rgb.as_raw() })
    }
}

/// Reads an image file once, as RGB and as grey levels.
pub(crate) fn load(path: &Path) -> Result<LoadedImage> {
    let img = image::open(path).with_context(|| format!("cannot read image {}", path.display()))?;
    let luma = img.to_luma8();
    let gray = Plane::from_vec(luma.width() as usize, luma.height() as usize, luma.into_raw());
    Ok(LoadedImage { rgb: img.to_rgb8(), gray })
}
