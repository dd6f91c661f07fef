//! AprilTag detection: a thin, typed wrapper around the `apriltag` crate (AprilTag 3 C library).
//!
//! Pixel convention: the C library puts pixel centres at `(i + 0.5, j + 0.5)`; tubeloc (and
//! OpenCV) put them at integers. Corners, centres and homographies returned here are shifted by
//! `-0.5` px into the tubeloc/OpenCV convention.
//!
//! Corner order (the detector's): in the tag frame (x right, y down as printed, z into the
//! tag, `s` = edge of the black square) corner `k` is
//! `(-s/2, s/2), (s/2, s/2), (s/2, -s/2), (-s/2, -s/2)` for `k = 0..3`.

use crate::error::CalibError;
use apriltag::{families, DetectorBuilder, Family, Image};
use serde::{Deserialize, Serialize};
use tubeloc_core::Plane;

/// Shift from the C detector's pixel convention to tubeloc's, pixels.
pub const C_TO_OPENCV_PX: f64 = -0.5;

/// Largest image side the C detector takes, pixels (it asserts `w, h < 32768` and indexes
/// pixels with 32-bit ints). Larger images are refused with an error.
pub const MAX_IMAGE_SIDE: usize = 32767;

/// Smallest side of the image the C detector searches for quads (the input after
/// decimation), pixels. Below it the C code reads outside its buffers (its 4 px threshold
/// tiles do not fit: 1 or 2 px tall images crashed it), and no tag fits anyway (a tag36h11
/// needs 8 cells across): such images give no detection.
pub const MIN_QUAD_SIDE: usize = 8;

/// Largest decimation factor accepted.
pub const MAX_DECIMATION: f32 = 64.0;

/// Largest Gaussian blur sigma accepted, pixels.
pub const MAX_SIGMA: f32 = 16.0;

/// Checks a decimation factor: 1, 1.5, or a whole number from 2 to [`MAX_DECIMATION`]. The C
/// library decimates by the integer part of the factor but scales the quads back by the factor
/// itself, so other fractions would misplace every corner.
pub fn check_decimation(decimation: f32) -> Result<(), String> {
    let ok = decimation.is_finite() && (1.0..=MAX_DECIMATION).contains(&decimation) && (decimation == 1.5 || decimation.fract() == 0.0);
    if ok {
        Ok(())
    } else {
        Err(format!("must be 1, 1.5 or a whole number from 2 to {MAX_DECIMATION}, got {decimation}"))
    }
}

/// Size of the image the C detector searches for quads: `width x height` decimated by
/// `decimation` as `image_u8_decimate` does it.
pub fn quad_image_size(width: usize, height: usize, decimation: f32) -> (usize, usize) {
    if decimation == 1.5 {
        (width / 3 * 2, height / 3 * 2)
    } else if decimation > 1.0 {
        let f = decimation as usize;
        (1 + (width.max(1) - 1) / f, 1 + (height.max(1) - 1) / f)
    } else {
        (width, height)
    }
}

/// Kernel size of the C detector's quad blur for `sigma` (`4 sigma`, made odd; 1 = no blur).
fn blur_kernel(sigma: f32) -> usize {
    let k = (4.0 * sigma) as usize;
    if k % 2 == 0 {
        k + 1
    } else {
        k
    }
}

/// Supported tag families.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum TagFamily {
    /// tag36h11 (default; 587 ids).
    #[default]
    #[serde(rename = "tag36h11")]
    Tag36h11,
    /// tag25h9.
    #[serde(rename = "tag25h9")]
    Tag25h9,
    /// tag16h5.
    #[serde(rename = "tag16h5")]
    Tag16h5,
    /// tagStandard41h12.
    #[serde(rename = "tagStandard41h12")]
    TagStandard41h12,
}

impl TagFamily {
    /// Parses a family name as the C library spells it (`"tag36h11"`).
    pub fn from_name(name: &str) -> Result<Self, CalibError> {
        match name {
            "tag36h11" => Ok(TagFamily::Tag36h11),
            "tag25h9" => Ok(TagFamily::Tag25h9),
            "tag16h5" => Ok(TagFamily::Tag16h5),
            "tagStandard41h12" => Ok(TagFamily::TagStandard41h12),
            _ => Err(CalibError::invalid("tag family", format!("unknown family {name:?} (tag36h11, tag25h9, tag16h5, tagStandard41h12)"))),
        }
    }

    fn to_family(self) -> Family {
        match self {
            TagFamily::Tag36h11 => families::Tag36h11::default().into(),
            TagFamily::Tag25h9 => families::Tag25h9::default().into(),
            TagFamily::Tag16h5 => families::Tag16h5::default().into(),
            TagFamily::TagStandard41h12 => families::TagStandard41h12::default().into(),
        }
    }
}

/// Detector options: the settings of the C library's reference test program (decimation 1,
/// no edge refinement, 8-bit values used as they are), chosen on real photos
/// (docs/design/0026); elsewhere the C library's defaults.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DetectorConfig {
    /// Families to look for.
    pub families: Vec<TagFamily>,
    /// Maximum number of corrected bits (2 by default; higher costs memory).
    pub max_hamming: usize,
    /// Quad detection on an image decimated by this factor (1 = full resolution).
    pub decimation: f32,
    /// Gaussian blur sigma applied before quad detection, pixels (0 = none).
    pub sigma: f32,
    /// Images detected at once by [`crate::batch::detect_files`] (at least 1). A
    /// [`TagDetector`] always runs the C detector on one thread: its worker pool races
    /// (a worker can read a task list that is being reallocated, AprilTag pull request 339,
    /// and the union-find of its quad clustering is shared unguarded, issue 387), which crashed
    /// `tubeloc calib detect` in 3 of 1600 runs here with 2 threads. Detect several images at
    /// once instead, one detector each (`detect_files`, `tubeloc calib detect --threads`).
    pub threads: u8,
    /// Snap quad edges to strong gradients (improves corners when decimating). Off by default,
    /// unlike `apriltag_detector_create`: the reference corners were made without it, and with
    /// it the corners of real photos move by a median 0.33 px from the reference's.
    pub refine_edges: bool,
    /// Sharpening of the decoded bit image.
    pub sharpening: f64,
    /// Detections with a smaller decision margin are dropped.
    pub min_decision_margin: f32,
    /// Treat the input as sRGB-encoded and convert it to linear intensity before detection.
    ///
    /// Edges are blurred in linear light (optics, pixel area); in an sRGB-encoded image the
    /// transition of a black-on-white edge is skewed toward the dark side, so the detector's
    /// fitted quads shrink: about 0.3 px per corner on the synthetic benchmark's 40 px tags,
    /// i.e. tag-pair ranges 0.5 % too long. Linearizing, `l = ((v + 0.055) / 1.055)^2.4`
    /// (`v / 12.92` below 0.04045), removes the bias. Off by default (the C library's
    /// behaviour, which the reference corner outputs were made with): on real camera JPEGs it
    /// crushes the shadows and finds 26 of 47 tags instead of 46 (docs/design/0026); it is for
    /// images rendered in linear light and encoded as sRGB, like `tubeloc synth` scenes.
    #[serde(default)]
    pub linearize_srgb: bool,
}

impl DetectorConfig {
    /// Checks the settings as [`TagDetector::new`] does, without building the C detector: a
    /// family, a valid decimation, sigma in `[0, MAX_SIGMA]`, threads >= 1, max_hamming <= 3,
    /// a finite sharpening and a number for the least decision margin.
    pub fn validate(&self) -> Result<(), CalibError> {
        if self.families.is_empty() {
            return Err(CalibError::invalid("detector", "no tag family given"));
        }
        check_decimation(self.decimation).map_err(|m| CalibError::invalid("decimation", m))?;
        if !(self.sigma >= 0.0 && self.sigma <= MAX_SIGMA) || self.threads == 0 || self.max_hamming > 3 {
            return Err(CalibError::invalid("detector", format!("sigma must be in [0, {MAX_SIGMA}], threads >= 1, max_hamming <= 3")));
        }
        if !self.sharpening.is_finite() || self.min_decision_margin.is_nan() {
            return Err(CalibError::invalid("detector", "sharpening must be finite and min_decision_margin a number"));
        }
        Ok(())
    }
}

impl Default for DetectorConfig {
    fn default() -> Self {
        DetectorConfig { families: vec![TagFamily::Tag36h11], max_hamming: 2, decimation: 1.0, sigma: 0.0, threads: 1, refine_edges: false, sharpening: 0.25, min_decision_margin: 0.0, linearize_srgb: false }
    }
}

/// One detected tag (pixel coordinates in the tubeloc/OpenCV convention).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TagDetection {
    /// Family of the tag.
    pub family: TagFamily,
    /// Tag id.
    pub id: u32,
    /// Bits corrected.
    pub hamming: u32,
    /// Decision margin of the decoder (larger is more confident).
    pub decision_margin: f32,
    /// Tag centre, pixels.
    pub center: [f64; 2],
    /// Corners in detector order (see the module doc), pixels.
    pub corners: [[f64; 2]; 4],
    /// Homography (row-major) from tag coordinates `(x, y) in [-1, 1]^2` (x right, y down as
    /// printed; `±1` at the black square's edge) to pixels: `[u, v, w]^T = H [x, y, 1]^T`.
    pub homography: [[f64; 3]; 3],
}

/// 8-bit sRGB code value to 8-bit linear intensity (rounded): the sRGB decoding curve.
pub fn srgb_to_linear_lut() -> [u8; 256] {
    let mut lut = [0u8; 256];
    for (i, o) in lut.iter_mut().enumerate() {
        let v = i as f64 / 255.0;
        let l = if v <= 0.04045 { v / 12.92 } else { ((v + 0.055) / 1.055).powf(2.4) };
        *o = (l * 255.0).round() as u8;
    }
    lut
}

/// A reusable AprilTag detector.
pub struct TagDetector {
    inner: apriltag::Detector,
    config: DetectorConfig,
    families: Vec<TagFamily>,
}

impl std::fmt::Debug for TagDetector {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TagDetector").field("config", &self.config).finish()
    }
}

impl TagDetector {
    /// Builds a detector; fails for an empty family list or invalid numbers.
    pub fn new(config: DetectorConfig) -> Result<Self, CalibError> {
        config.validate()?;
        let mut b = DetectorBuilder::new();
        for f in &config.families {
            b = b.add_family_bits(f.to_family(), config.max_hamming);
        }
        let mut inner = b.build().map_err(|e| CalibError::Detector(e.to_string()))?;
        inner.set_decimation(config.decimation);
        inner.set_sigma(config.sigma);
        // One thread: the C worker pool is not thread-safe (see `DetectorConfig::threads`).
        inner.set_thread_number(1);
        inner.set_refine_edges(config.refine_edges);
        inner.set_shapening(config.sharpening);
        let families = config.families.clone();
        Ok(TagDetector { inner, config, families })
    }

    /// The options in use.
    pub fn config(&self) -> &DetectorConfig {
        &self.config
    }

    /// The family that decoded a detection (read from the C struct's family name).
    fn family_of(&self, d: apriltag::Detection) -> TagFamily {
        let ptr = d.into_raw();
        // SAFETY: `ptr` is a live detection whose `family` points at one of the detector's
        // families (NUL-terminated name); ownership goes back to a `Detection` that frees it.
        let name = unsafe {
            let fam = ptr.as_ref().family;
            let name = if fam.is_null() || (*fam).name.is_null() { None } else { std::ffi::CStr::from_ptr((*fam).name).to_str().ok().map(str::to_owned) };
            drop(apriltag::Detection::from_raw(ptr.as_ptr()));
            name
        };
        name.and_then(|n| TagFamily::from_name(&n).ok()).unwrap_or(self.families[0])
    }

    /// Detects tags in an 8-bit grey plane; detections sorted by (id, centre x).
    pub fn detect(&mut self, plane: &Plane<u8>) -> Result<Vec<TagDetection>, CalibError> {
        self.detect_raw(plane.width, plane.height, plane.width, &plane.data)
    }

    /// Detects tags in an `image` crate grey image.
    pub fn detect_image(&mut self, img: &image::GrayImage) -> Result<Vec<TagDetection>, CalibError> {
        let (w, h) = img.dimensions();
        self.detect_raw(w as usize, h as usize, w as usize, img.as_raw())
    }

    /// Detects tags in a raw buffer with the given row stride (bytes).
    ///
    /// This is the one place that calls the C detector, and it only calls it with inputs it
    /// takes: an image with a side over [`MAX_IMAGE_SIDE`] is an error; one whose decimated
    /// quad image (see [`quad_image_size`]) is under [`MIN_QUAD_SIDE`] px, or narrower than
    /// the blur kernel, holds no tag and gives no detection without calling the C code.
    pub fn detect_raw(&mut self, width: usize, height: usize, stride: usize, data: &[u8]) -> Result<Vec<TagDetection>, CalibError> {
        let fits = stride >= width && height.checked_sub(1).and_then(|h| h.checked_mul(stride)).and_then(|n| n.checked_add(width)).is_some_and(|n| data.len() >= n);
        if width == 0 || height == 0 || !fits {
            return Err(CalibError::invalid("image", format!("{width}x{height} stride {stride} does not fit a buffer of {} bytes", data.len())));
        }
        if width > MAX_IMAGE_SIDE || height > MAX_IMAGE_SIDE {
            return Err(CalibError::invalid("image", format!("{width}x{height} is larger than the AprilTag detector takes ({MAX_IMAGE_SIDE} px a side)")));
        }
        let (qw, qh) = quad_image_size(width, height, self.config.decimation);
        let min_side = MIN_QUAD_SIDE.max(blur_kernel(self.config.sigma));
        if qw < min_side || qh < min_side {
            return Ok(Vec::new());
        }
        let mut im = Image::zeros_with_alignment(width, height, 96).map_err(|e| CalibError::Detector(e.to_string()))?;
        let s = im.stride();
        let buf = im.as_slice_mut();
        if self.config.linearize_srgb {
            let lut = srgb_to_linear_lut();
            for y in 0..height {
                for (o, &v) in buf[y * s..y * s + width].iter_mut().zip(&data[y * stride..y * stride + width]) {
                    *o = lut[v as usize];
                }
            }
        } else {
            for y in 0..height {
                buf[y * s..y * s + width].copy_from_slice(&data[y * stride..y * stride + width]);
            }
        }
        let raw = self.inner.detect(&im);
        let mut out = Vec::with_capacity(raw.len());
        for d in raw {
            if d.decision_margin() < self.config.min_decision_margin {
                continue;
            }
            let hd = d.homography().data().to_vec();
            let mut hm = [[0.0; 3]; 3];
            for (r, row) in hm.iter_mut().enumerate() {
                for (c, v) in row.iter_mut().enumerate() {
                    *v = hd[r * 3 + c];
                }
            }
            // Shift the output pixel frame by -0.5: H' = [1 0 -.5; 0 1 -.5; 0 0 1] H.
            let h2 = hm[2];
            for row in &mut hm[..2] {
                for (v, w) in row.iter_mut().zip(h2) {
                    *v += C_TO_OPENCV_PX * w;
                }
            }
            let shift = |p: [f64; 2]| [p[0] + C_TO_OPENCV_PX, p[1] + C_TO_OPENCV_PX];
            let (id, hamming, margin, center, corners) = (d.id() as u32, d.hamming() as u32, d.decision_margin(), shift(d.center()), d.corners().map(shift));
            let family = self.family_of(d);
            out.push(TagDetection { family, id, hamming, decision_margin: margin, center, corners, homography: hm });
        }
        out.sort_by(|a, b| a.id.cmp(&b.id).then(a.center[0].total_cmp(&b.center[0])));
        Ok(out)
    }
}
