//! One image's refinement: seeds (detections or explicit seeds) -> (stereo points) -> the
//! cylinder fit -> the stages after the fit. [`crate::Locator`] runs it for `locate`;
//! dataset-wide refinement (`tubeloc refine --dataset`) runs it per image.

use crate::error::{PipelineError, Result};
use crate::settings::LocatorSettings;
use crate::stages::after_fit;
use crate::stereo::{points_per_region, region_of};
use image::DynamicImage;
use nalgebra::Point3;
use rayon::prelude::*;
use tubeloc_core::{BinaryMask, CameraModel, Plane, Pose, TubeAxisPose, TubeDetection};
use tubeloc_refine::seal_end::ColourImage;
use tubeloc_refine::seed::reanchored_pose;
use tubeloc_refine::stereo_stage::StereoRegion;
use tubeloc_refine::{AxisState, GroundPlane, RefineInput, Refiner, Scene, Seed};

/// One image to refine in, with what is known about it.
#[derive(Clone, Copy)]
pub struct Frame<'a> {
    /// The (left) image; its size must be `camera`'s. Colour images give the seal-end colours.
    pub image: &'a DynamicImage,
    /// The camera that took `image`.
    pub camera: &'a CameraModel,
    /// COCO image id given to the poses of explicit seeds and to their seeds.
    pub image_id: u64,
    /// Ground plane in `camera`'s frame (`n · X = d`, n up, metres), if known.
    pub ground: Option<GroundPlane>,
    /// The right image of a stereo pair, if any: adds the stereo term and the stereo stages.
    pub stereo: Option<StereoView<'a>>,
}

/// The right view of a stereo pair.
#[derive(Clone, Copy)]
pub struct StereoView<'a> {
    /// The right image (its grey levels are matched).
    pub right: &'a DynamicImage,
    /// The right camera.
    pub right_camera: &'a CameraModel,
    /// `T_left_right`: maps right-camera points into the left camera's frame, metres.
    pub t_left_right: Pose,
}

/// What to refine: a detection, or an explicit seed (e.g. a perturbed exact pose).
#[derive(Clone, Debug)]
pub enum SeedItem {
    /// A detector's detection (mask / box / template pose seed).
    Detection(TubeDetection),
    /// An explicit seed: centre and axis (camera frame, metres; the axis toward the seal end),
    /// with a box `[x, y, w, h]` (pixels) and an optional mask of the image's size that stand
    /// in for a detector's region (stereo points, mask term).
    Explicit {
        /// Centre and axis.
        state: AxisState,
        /// Region box, pixels.
        bbox: [f64; 4],
        /// Region mask.
        mask: Option<BinaryMask>,
    },
}

impl SeedItem {
    fn detection(&self) -> Option<&TubeDetection> {
        match self {
            SeedItem::Detection(d) => Some(d),
            SeedItem::Explicit { .. } => None,
        }
    }

    fn mask(&self) -> Option<BinaryMask> {
        match self {
            SeedItem::Detection(d) => d.mask.as_ref().and_then(|m| m.to_mask().ok()),
            SeedItem::Explicit { mask, .. } => mask.clone(),
        }
    }
}

/// Per-run options of [`refine_frame`] beyond the settings (dataset evaluation uses them).
#[derive(Clone, Debug, Default)]
pub struct FrameOptions {
    /// Fit the silhouette to each seed's mask boundary instead of the image edges (an upper
    /// bound with exact masks).
    pub mask_term: bool,
    /// Also return the seed each fit started from, as a pose.
    pub seeds: bool,
    /// The camera detections' template poses were computed with, when not the image's own:
    /// they are re-anchored to the image's camera before the fit (same pixel, same distance).
    pub detections_camera: Option<CameraModel>,
}

/// The result of [`refine_frame`].
#[derive(Clone, Debug, Default)]
pub struct FrameRefinement {
    /// One pose per seed item, in order (camera frame, metres).
    pub poses: Vec<TubeAxisPose>,
    /// With [`FrameOptions::seeds`], the seeds the fits started from (camera frame).
    pub seeds: Vec<TubeAxisPose>,
    /// Time of each fit alone (without loading, stereo matching or the stages after it),
    /// milliseconds, one per seed item.
    pub fit_ms: Vec<f64>,
    /// Stereo points (left camera frame, metres) per seed item; empty without stereo.
    pub stereo_points: Vec<Vec<Point3<f64>>>,
    /// The SGM scene depth (metres per left-image pixel, NaN unknown), with stereo.
    pub scene_depth: Option<Plane<f32>>,
    /// The ground plane each seed item was refined with (its local ground in stereo, else the
    /// frame's), camera frame; one per seed item.
    pub grounds: Vec<Option<GroundPlane>>,
}

/// The grey levels (the refiner's input) and the colours (the seal-end decision) of an image.
/// An RGB8 image's colours are read in place; other formats are converted only when the
/// colours are wanted.
pub(crate) struct FramePixels<'a> {
    pub gray: Plane<u8>,
    rgb: Option<std::borrow::Cow<'a, [u8]>>,
}

impl<'a> FramePixels<'a> {
    /// The grey levels of `image`, and its colours when `colour` is set.
    pub fn of(image: &'a DynamicImage, colour: bool) -> Self {
        let rgb = colour.then(|| tubeloc_detect::input::rgb8_pixels(image));
        FramePixels { gray: grey_levels(image), rgb }
    }

    fn colour(&self, wanted: bool) -> Option<ColourImage<'_>> {
        self.rgb.as_deref().filter(|_| wanted).map(|rgb| ColourImage { width: self.gray.width, height: self.gray.height, rgb })
    }
}

/// The grey levels of `image`, as [`DynamicImage::to_luma8`] gives them (the image crate's
/// conversion in the image's colour space). An RGB8 image is converted in bands of rows in
/// parallel; the conversion is per pixel, so the levels are the same.
pub(crate) fn grey_levels(image: &DynamicImage) -> Plane<u8> {
    const BAND_ROWS: usize = 64;
    let (w, h) = (image.width() as usize, image.height() as usize);
    let DynamicImage::ImageRgb8(img) = image else {
        // 16-bit and float frames at their real bit depth, as the detectors read them.
        let levels = match tubeloc_detect::input::to_eight_bit(image) {
            Some(eight) => eight.to_luma8(),
            None => image.to_luma8(),
        };
        return Plane::from_vec(w, h, levels.into_raw());
    };
    let mut gray = vec![0u8; w * h];
    let space = img.color_space();
    gray.par_chunks_mut((w * BAND_ROWS).max(1)).zip(img.as_raw().par_chunks((3 * w * BAND_ROWS).max(1))).for_each(|(out, src)| {
        let rows = out.len() / w.max(1);
        let mut band = image::RgbImage::from_raw(w as u32, rows as u32, src.to_vec()).expect("a band of whole rows");
        // The image's colour space is a valid one, so it is accepted.
        let _ = band.set_color_space(space);
        out.copy_from_slice(DynamicImage::ImageRgb8(band).to_luma8().as_raw());
    });
    Plane::from_vec(w, h, gray)
}

/// Refines every seed item of one frame: stereo points per item (with a right view), the fit,
/// then the stages after the fit ([`after_fit`]). Items are fitted in parallel, at most
/// [`concurrent_fits`] at once, and the results come in item order whatever the threads.
pub fn refine_frame(refiner: &Refiner, settings: &LocatorSettings, frame: &Frame, items: &[SeedItem], opts: &FrameOptions) -> Result<FrameRefinement> {
    refine_pixels(refiner, settings, frame, &FramePixels::of(frame.image, settings.colour_ends), items, opts)
}

/// Memory the fits of one frame that run at once may hold together, bytes.
const FIT_MEMORY_BYTES: u64 = 256 << 20;

/// Memory one fit holds per image pixel, bytes: the detection's mask decoded at full
/// resolution and the masks derived from it (1 byte per pixel each).
const FIT_BYTES_PER_PIXEL: u64 = 4;

/// How many fits may run at once on a frame of `pixels` pixels: `FIT_MEMORY_BYTES /
/// (FIT_BYTES_PER_PIXEL · pixels)`, at least 1. A 20-megapixel frame allows 3; frames above
/// 33.5 megapixels, up to the locator's 100-megapixel bound, are fitted one tube at a time, as
/// its stated memory bound assumes ([`crate::locator::MAX_IMAGE_PIXELS`]).
pub(crate) fn concurrent_fits(pixels: u64) -> usize {
    (FIT_MEMORY_BYTES / (FIT_BYTES_PER_PIXEL * pixels.max(1))).max(1) as usize
}

/// [`refine_frame`] with the frame's pixels already converted.
pub(crate) fn refine_pixels(refiner: &Refiner, settings: &LocatorSettings, frame: &Frame, px: &FramePixels, items: &[SeedItem], opts: &FrameOptions) -> Result<FrameRefinement> {
    let camera = frame.camera;
    let gray = &px.gray;
    if gray.width != camera.width as usize || gray.height != camera.height as usize {
        return Err(PipelineError::Input(format!("the image is {}x{} but its camera is {}x{}", gray.width, gray.height, camera.width, camera.height)));
    }
    let st = &settings.stages;
    let colour = px.colour(settings.colour_ends);
    let ground = frame.ground;
    let (stereo_pts, depth, pair, grounds) = match &frame.stereo {
        Some(view) => {
            let right = grey_levels(view.right);
            let (h, w) = (camera.height, camera.width);
            let regions: Vec<StereoRegion> = items
                .iter()
                .map(|it| match it {
                    SeedItem::Detection(d) => region_of(d),
                    SeedItem::Explicit { state, bbox, mask } => StereoRegion { bbox: *bbox, mask: mask.clone().filter(|m| m.width == w as usize && m.height == h as usize), seed_z: Some(state.c.z) },
                })
                .collect();
            let reference = ground.as_ref().filter(|_| st.local_ground);
            let (s, r) = points_per_region(camera, view.right_camera, &view.t_left_right, gray, &right, &regions, st.disparities, st.stereo_erode_px, reference)?;
            let grounds = s.tube_grounds(ground);
            (s.points, Some(s.depth), Some(r), grounds)
        }
        None => (vec![Vec::new(); items.len()], None, None, vec![ground; items.len()]),
    };
    let image = Plane::from_vec(gray.width, gray.height, gray.data.par_iter().map(|&v| v as f32 / 255.0).collect());
    let occlusion_depth = depth.as_ref().filter(|_| st.scene_occlusion).map(|d| (d, camera));
    let masks: Vec<Option<BinaryMask>> = if opts.mask_term { items.iter().map(SeedItem::mask).collect() } else { vec![None; items.len()] };
    let base = RefineInput { image: &image, camera, ground, scene: Scene::default() };
    let mut out = FrameRefinement { poses: Vec::with_capacity(items.len()), fit_ms: Vec::with_capacity(items.len()), ..Default::default() };
    // Each item is fitted on its own (the fit reads the shared frame, writes nothing shared):
    // in parallel, in waves of at most `wave` fits (memory), collected in item order, so the
    // result does not depend on the threads.
    let wave = concurrent_fits(camera.width as u64 * camera.height as u64);
    let fit = |k: usize, item: &SeedItem| {
        let input = RefineInput { ground: grounds[k], scene: Scene { depth: occlusion_depth, stereo_points: &stereo_pts[k], mask: masks[k].as_ref().map(|m| (m, camera)), ..Scene::default() }, ..base };
        let t0 = std::time::Instant::now();
        match item {
            SeedItem::Detection(d) => {
                let mut d = d.clone();
                if let (Some(from), Some(t)) = (&opts.detections_camera, &d.t_cam_tube) {
                    if let Some(t) = reanchored_pose(t, from, camera) {
                        d.t_cam_tube = Some(t);
                    }
                }
                let pose = refiner.refine(&input, &d, colour.as_ref());
                let ms = t0.elapsed().as_secs_f64() * 1e3;
                let seed = opts.seeds.then(|| refiner.seed(&input, &d, colour.as_ref()).ok()).flatten().and_then(|sd| TubeAxisPose::new(frame.image_id, d.score, sd.state.c, sd.state.a, 0.5).ok());
                (pose, ms, seed)
            }
            SeedItem::Explicit { state, .. } => {
                let pose = refiner.refine_seed(&input, &Seed { state: *state, end_known: true }, frame.image_id, 1.0, None);
                let ms = t0.elapsed().as_secs_f64() * 1e3;
                let seed = opts.seeds.then(|| TubeAxisPose::new(frame.image_id, 1.0, state.c, state.a, 0.5).ok()).flatten();
                (pose, ms, seed)
            }
        }
    };
    let fitted: Vec<(TubeAxisPose, f64, Option<TubeAxisPose>)> = items.chunks(wave).enumerate().flat_map(|(w, its)| its.par_iter().enumerate().map(|(j, item)| fit(w * wave + j, item)).collect::<Vec<_>>()).collect();
    for (pose, ms, seed) in fitted {
        out.poses.push(pose);
        out.fit_ms.push(ms);
        out.seeds.extend(seed);
    }
    for ((ps, its), gs) in out.poses.chunks_mut(wave).zip(items.chunks(wave)).zip(grounds.chunks(wave)) {
        ps.par_iter_mut().zip(its).zip(gs).for_each(|((p, item), g)| after_fit(st, p, item.detection(), depth.as_ref(), pair.as_ref(), g.as_ref(), refiner, camera));
    }
    out.stereo_points = if frame.stereo.is_some() { stereo_pts } else { Vec::new() };
    out.scene_depth = depth;
    out.grounds = grounds;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Large frames are fitted one tube at a time (the locator's memory bound assumes it),
    /// a 20-megapixel frame three at a time, small frames all at once on common machines.
    #[test]
    fn concurrent_fits_bound_the_fits_memory() {
        assert_eq!(concurrent_fits(crate::locator::MAX_IMAGE_PIXELS), 1);
        assert_eq!(concurrent_fits(40_000_000), 1);
        assert_eq!(concurrent_fits(5472 * 3648), 3);
        assert!(concurrent_fits(1024 * 1024) >= 32);
        assert_eq!(concurrent_fits(0), (FIT_MEMORY_BYTES / FIT_BYTES_PER_PIXEL) as usize);
        for p in [1u64, 1 << 20, 20_000_000, 100_000_000] {
            assert!(concurrent_fits(p) as u64 * FIT_BYTES_PER_PIXEL * p <= FIT_MEMORY_BYTES.max(FIT_BYTES_PER_PIXEL * p), "{p} px");
        }
    }

    /// The banded conversion gives the image crate's grey levels, bands of every height and a
    /// non-sRGB colour space included.
    #[test]
    fn grey_levels_are_the_image_crates() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for (w, h) in [(37u32, 150u32), (5, 64), (1, 1), (200, 129)] {
            let raw: Vec<u8> = (0..3 * w * h).map(|_| rng.random()).collect();
            let mut img = image::RgbImage::from_raw(w, h, raw).unwrap();
            let plain = DynamicImage::ImageRgb8(img.clone());
            assert_eq!(grey_levels(&plain).data, plain.to_luma8().into_raw(), "{w}x{h}");
            img.set_rgb_primaries(image::metadata::CicpColorPrimaries::Rgb240m);
            let wide = DynamicImage::ImageRgb8(img);
            assert_eq!(grey_levels(&wide).data, wide.to_luma8().into_raw(), "{w}x{h} SMPTE 240M");
            if w * h > 100 {
                assert_ne!(wide.to_luma8(), plain.to_luma8(), "the colour space changes the levels");
            }
        }
        let grey = DynamicImage::ImageLuma8(image::GrayImage::from_fn(9, 7, |x, y| image::Luma([(x * 7 + y) as u8])));
        assert_eq!(grey_levels(&grey).data, grey.to_luma8().into_raw());
    }
}
