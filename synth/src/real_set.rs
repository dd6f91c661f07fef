//! Composite sets on real rover frames: rendered tubes with shadows on real photographs, as a
//! COCO dataset, for training and for measuring detectors on real imagery.
//!
//! The frames and their views: [`crate::real_frames`].
//!
//! Grey backgrounds give grey composites, their tubes shaded in the 600-800 nm band of the
//! rovers' monochrome cameras ([`SpectralBand::RedNir`]) and saved as 8-bit grey like the
//! camera's own product; colour backgrounds stay colour.

use crate::composite::{composite, CompositeConfig, SpectralBand};
use crate::dataset::{annotation_from_truth, pose_json, tube_category};
use crate::real_frames::RealView;
use crate::tube_shape::TubeShape;
use crate::SynthError;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde_json::{json, Map, Value};
use std::sync::Arc;
use tubeloc_core::{CocoDataset, CocoImage};

/// Options of a composite set.
#[derive(Clone, Debug)]
pub struct RealSetConfig {
    /// Tubes per composite, drawn uniformly from this inclusive range (0 = a negative frame).
    pub tubes: (usize, usize),
    /// Composites per view (each with its own seed).
    pub per_view: usize,
    /// Distance band of the tube centres from the camera, metres.
    pub range_m: (f64, f64),
    /// Dust level range of the tubes, [0, 1].
    pub dust: (f32, f32),
    /// Range of the gain on the tubes' radiance (1 = matched exposure).
    pub tube_gain: (f32, f32),
    /// Save as JPEG with a quality drawn from this range (`None`: PNG).
    pub jpeg_quality: Option<(u8, u8)>,
    /// Master seed.
    pub seed: u64,
    /// Tube geometry.
    pub tube_shape: Arc<TubeShape>,
    /// Colour frames as a monochrome 600-800 nm camera would see them ([`red_as_grey`]): the
    /// frame's red channel, the tubes shaded in [`SpectralBand::RedNir`], saved grey. More
    /// grey training composites with full-resolution texture than the grey backgrounds give.
    pub colour_as_grey: bool,
}

/// One rendered composite: its file name, encoded bytes and COCO entries.
pub struct RealSample {
    /// File name under `images/`.
    pub file_name: String,
    /// Encoded PNG or JPEG bytes.
    pub bytes: Vec<u8>,
    /// The COCO image entry.
    pub image: CocoImage,
    /// The COCO annotations (ids local to the sample, renumbered by [`assemble`]).
    pub annotations: Vec<tubeloc_core::CocoAnnotation>,
}

/// Interleaved RGB8 `rgb` as a grey frame of its red channel (in all three channels): the
/// nearest a colour camera's frame comes to a 600-800 nm monochrome camera's (Mastcam's red
/// filter peaks near 640 nm, the monochrome Navcams see 600-800 nm).
pub fn red_as_grey(rgb: &mut [u8]) {
    for p in rgb.chunks_exact_mut(3) {
        p[1] = p[0];
        p[2] = p[0];
    }
}

/// Narrowest tube body placed in a composite, pixels (the body is [`TUBE_BODY_DIAMETER_M`]
/// across).
pub const MIN_TUBE_WIDTH_PX: f64 = 3.5;

/// Diameter of the tube's body, metres (the default tube model's, `2 body_radius`), for
/// widths in pixels `f D / r`.
pub const TUBE_BODY_DIAMETER_M: f64 = 0.0171;

/// Renders composite `k` (0-based) of `view`; returns `Ok(None)` when the tubes do not fit in
/// the range band of this view (e.g. a frame looking over the horizon).
pub fn render_sample(view: &RealView, k: usize, id: u64, cfg: &RealSetConfig) -> Result<Option<RealSample>, SynthError> {
    let err = |m: String| SynthError::Invalid(format!("{}: {m}", view.image.display()));
    let bytes = tubeloc_core::image_file::read_whole(&view.image).map_err(|e| err(e.to_string()))?;
    let mut img = image::load_from_memory(&bytes).map_err(|e| err(e.to_string()))?.to_rgb8();
    if (img.width(), img.height()) != (view.camera.width, view.camera.height) {
        return Err(err(format!("image is {}x{} but its camera is {}x{}", img.width(), img.height(), view.camera.width, view.camera.height)));
    }
    let photo_grey = tubeloc_core::monochrome::is_grey_rgb8(img.as_raw());
    if cfg.colour_as_grey && !photo_grey {
        red_as_grey(&mut img);
    }
    let grey = photo_grey || cfg.colour_as_grey;
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed ^ id.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ (k as u64) << 48);
    let tubes = rng.random_range(cfg.tubes.0..=cfg.tubes.1);
    let dust = rng.random_range(cfg.dust.0..=cfg.dust.1);
    let tube_gain = rng.random_range(cfg.tube_gain.0..=cfg.tube_gain.1);
    let seed: u64 = rng.random();
    let (n, d) = view.ground();
    // No tube narrower than MIN_TUBE_WIDTH_PX: the band ends where the body gets that thin.
    let far = cfg.range_m.1.min((view.camera.fx * view.camera.fy).sqrt() * TUBE_BODY_DIAMETER_M / MIN_TUBE_WIDTH_PX);
    if far <= cfg.range_m.0 {
        return Ok(None);
    }
    // A frame without a known sun gets one drawn for each composite
    // ([`crate::real_frames::random_sun`]); one with a sun draws nothing more.
    let sun_cam = view.sun_cam.unwrap_or_else(|| crate::real_frames::random_sun(&mut rng, &view.up_cam));
    let cc = CompositeConfig {
        ground: (n, -d),
        sun_az_el_deg: (0.0, 45.0),
        tubes,
        dust,
        seed,
        tube_shape: cfg.tube_shape.clone(),
        range_m: Some((cfg.range_m.0, far)),
        sun_cam: Some(sun_cam),
        tube_gain,
        band: SpectralBand::of_photo(grey),
        encoding: view.encoding,
    };
    let c = match composite(img.as_raw(), &view.camera, &cc) {
        Ok(c) => c,
        Err(SynthError::Invalid(m)) if m.starts_with("could place only") => return Ok(None),
        Err(e) => return Err(e),
    };
    let (w, h) = (view.camera.width, view.camera.height);
    let stem = view.image.file_stem().map(|s| s.to_string_lossy().to_string()).unwrap_or_else(|| "frame".into());
    let quality = cfg.jpeg_quality.map(|(a, b)| rng.random_range(a..=b));
    let ext = if quality.is_some() { "jpg" } else { "png" };
    let file_name = format!("{id:06}_{stem}_{k}.{ext}");
    let bytes = encode(&c.output.rgb, w, h, grey, quality).map_err(err)?;
    let mut extra = Map::new();
    extra.insert("camera".into(), serde_json::to_value(&view.camera).unwrap_or(Value::Null));
    extra.insert("ground".into(), json!({"normal": [n.x, n.y, n.z], "d": d}));
    extra.insert("T_world_cam".into(), pose_json(&c.t_ground_cam));
    extra.insert("background".into(), json!(view.image.display().to_string()));
    extra.insert("geometry".into(), json!(view.geometry));
    extra.insert("grey".into(), json!(grey));
    if grey && !photo_grey {
        extra.insert("grey_from".into(), json!("red channel"));
    }
    if let Some(s) = view.sol {
        extra.insert("sol".into(), json!(s));
    }
    let image = CocoImage { id, width: w, height: h, file_name: file_name.clone(), extra };
    let annotations = c.truth.iter().enumerate().map(|(j, t)| annotation_from_truth(j as u64 + 1, id, &view.camera, t, Map::from_iter([("dust".to_string(), json!(dust))]))).collect();
    Ok(Some(RealSample { file_name, bytes, image, annotations }))
}

/// Encodes an sRGB composite as PNG or JPEG, grey (luminance) when `grey`.
pub fn encode(rgb: &[u8], w: u32, h: u32, grey: bool, jpeg_quality: Option<u8>) -> Result<Vec<u8>, String> {
    use image::ImageEncoder;
    let (data, ct): (Vec<u8>, image::ExtendedColorType) =
        if grey { (rgb.chunks_exact(3).map(|p| (0.299 * p[0] as f32 + 0.587 * p[1] as f32 + 0.114 * p[2] as f32).round().clamp(0.0, 255.0) as u8).collect(), image::ExtendedColorType::L8) } else { (rgb.to_vec(), image::ExtendedColorType::Rgb8) };
    let mut buf = Vec::new();
    match jpeg_quality {
        Some(q) => image::codecs::jpeg::JpegEncoder::new_with_quality(&mut buf, q).write_image(&data, w, h, ct).map_err(|e| e.to_string())?,
        None => image::codecs::png::PngEncoder::new(&mut buf).write_image(&data, w, h, ct).map_err(|e| e.to_string())?,
    }
    Ok(buf)
}

/// Puts samples together into one COCO dataset (annotation ids renumbered from 1, in order).
pub fn assemble(samples: Vec<(CocoImage, Vec<tubeloc_core::CocoAnnotation>)>, info: Value) -> CocoDataset {
    let mut images = Vec::new();
    let mut annotations = Vec::new();
    for (im, anns) in samples {
        for mut a in anns {
            a.id = annotations.len() as u64 + 1;
            annotations.push(a);
        }
        images.push(im);
    }
    CocoDataset { info: Some(info), licenses: None, images, annotations, categories: vec![tube_category()], extra: Map::new() }
}

/// Where the tubes of a composite set lie: the 10th, 50th and 90th percentiles (nearest rank,
/// `round((n - 1) q)` of the sorted values) of their centres' distance from the camera
/// (metres) and of their body's image width `w = f D / r` (pixels; `f` the image's focal
/// length, `D` = [`TUBE_BODY_DIAMETER_M`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TubeSpread {
    /// Distance percentiles (p10, p50, p90), metres.
    pub range_m: [f64; 3],
    /// Image width percentiles (p10, p50, p90), pixels.
    pub width_px: [f64; 3],
}

/// For each annotation of a composite set, in order, its tube centre's distance from the
/// camera `r` (metres) and its body's image width `w = f D / r` (pixels; `f` the image camera's
/// `fx`, `D` = [`TUBE_BODY_DIAMETER_M`]); `None` for an annotation without `T_cam_tube` or
/// whose image has no camera.
pub fn tube_ranges_and_widths(ds: &CocoDataset) -> Vec<Option<(f64, f64)>> {
    let fx: std::collections::HashMap<u64, f64> = ds.images.iter().filter_map(|im| Some((im.id, im.extra.get("camera")?.get("fx")?.as_f64()?))).collect();
    ds.annotations
        .iter()
        .map(|a| {
            let t = a.extra.get("T_cam_tube")?.get("translation")?.as_array()?;
            let r = t.iter().filter_map(|v| v.as_f64()).map(|v| v * v).sum::<f64>().sqrt();
            let f = fx.get(&a.image_id)?;
            (r > 0.0).then(|| (r, f * TUBE_BODY_DIAMETER_M / r))
        })
        .collect()
}

/// The [`TubeSpread`] of a composite set (annotations with `T_cam_tube`, images with
/// `camera`), or `None` when it holds no such tube.
pub fn tube_spread(ds: &CocoDataset) -> Option<TubeSpread> {
    let (mut ranges, mut widths): (Vec<f64>, Vec<f64>) = tube_ranges_and_widths(ds).into_iter().flatten().unzip();
    let pct = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        [0.1, 0.5, 0.9].map(|q| v[((v.len() - 1) as f64 * q).round() as usize])
    };
    (!ranges.is_empty()).then(|| TubeSpread { range_m: pct(&mut ranges), width_px: pct(&mut widths) })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::real_frames::{assumed_real_view, AssumedView};
    use std::path::PathBuf;

    /// Two tubes per composite at 1.5-4 m, no dust, gain or JPEG: the options of these tests.
    fn two_tubes(seed: u64, colour_as_grey: bool) -> RealSetConfig {
        RealSetConfig { tubes: (2, 2), per_view: 1, range_m: (1.5, 4.0), dust: (0.0, 0.0), tube_gain: (1.0, 1.0), jpeg_quality: None, seed, tube_shape: Arc::new(TubeShape::from_model(&tubeloc_core::TubeModel::default())), colour_as_grey }
    }

    /// The photo at `path` under a camera 1.5 m up looking 40 degrees down (40 degree field).
    fn view_of(path: PathBuf, w: u32, h: u32) -> RealView {
        let view = AssumedView { hfov_deg: 40.0, height_m: 1.5, pitch_deg: 40.0, roll_deg: 0.0 };
        assumed_real_view(&view, path, w, h, None, &mut ChaCha8Rng::seed_from_u64(1))
    }

    /// With `colour_as_grey` a colour frame gives a grey composite whose ground is the frame's
    /// red channel (not its luminance), with its tubes drawn on it; without it, a colour one.
    #[test]
    fn colour_as_grey_composites_on_the_red_channel() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("colour.png");
        let (w, h) = (400u32, 300u32);
        // A reddish frame with a little texture: red 140-160, green 60, blue 30.
        let rgb: Vec<u8> = (0..w * h).flat_map(|i| [140 + (i * 7 % 21) as u8, 60, 30]).collect();
        image::save_buffer(&path, &rgb, w, h, image::ExtendedColorType::Rgb8).unwrap();
        let view = view_of(path, w, h);
        let cfg = |colour_as_grey| two_tubes(3, colour_as_grey);
        let grey = render_sample(&view, 0, 1, &cfg(true)).unwrap().expect("two tubes fit");
        assert_eq!(grey.annotations.len(), 2);
        assert_eq!(grey.image.extra["grey"], json!(true));
        assert_eq!(grey.image.extra["grey_from"], json!("red channel"));
        let img = image::load_from_memory(&grey.bytes).unwrap();
        assert_eq!(img.color(), image::ColorType::L8);
        let out = img.to_luma8();
        let same = out.as_raw().iter().zip(rgb.chunks_exact(3)).filter(|(o, p)| **o == p[0]).count();
        assert!(same as f64 > 0.9 * (w * h) as f64, "{same} of {} pixels keep the red channel", w * h);
        let changed = out.as_raw().iter().zip(rgb.chunks_exact(3)).filter(|(o, p)| o.abs_diff(p[0]) > 20).count();
        assert!(changed > 100, "the tubes and shadows change {changed} pixels");
        let colour = render_sample(&view, 0, 1, &cfg(false)).unwrap().expect("two tubes fit");
        assert_eq!(colour.image.extra["grey"], json!(false));
        assert!(colour.image.extra.get("grey_from").is_none());
        assert_eq!(image::load_from_memory(&colour.bytes).unwrap().color(), image::ColorType::Rgb8);
    }

    /// A frame whose sun is not known is lit by a sun drawn for each composite from its seed:
    /// the same composite again is the same bytes, and another seed lights it otherwise.
    #[test]
    fn a_frame_without_a_known_sun_is_lit_by_a_drawn_one_reproducibly() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("grey.png");
        let (w, h) = (400u32, 300u32);
        let luma: Vec<u8> = (0..w * h).map(|i| 100 + (i * 7 % 21) as u8).collect();
        image::save_buffer(&path, &luma, w, h, image::ExtendedColorType::L8).unwrap();
        let mut view = view_of(path, w, h);
        view.sun_cam = None;
        let cfg = |seed| two_tubes(seed, false);
        let a = render_sample(&view, 0, 1, &cfg(3)).unwrap().expect("two tubes fit");
        let b = render_sample(&view, 0, 1, &cfg(3)).unwrap().expect("two tubes fit");
        assert_eq!(a.bytes, b.bytes);
        assert_eq!(a.annotations.len(), 2);
        assert_ne!(render_sample(&view, 0, 1, &cfg(4)).unwrap().expect("two tubes fit").bytes, a.bytes);
    }

    #[test]
    fn the_body_diameter_is_the_default_tube_models() {
        assert!((TUBE_BODY_DIAMETER_M - 2.0 * tubeloc_core::TubeModel::default().body_radius()).abs() < 1e-12);
    }

    /// Ten tubes at 1..10 m under f = 1000 px: p10 / p50 / p90 at ranks 1 / 5 / 8 of 0..9
    /// (rounded), i.e. 2 / 6 / 9 m, and widths f D / r at 9 / 5 / 2 m; a tube without a pose is
    /// not counted, a set without one is None.
    #[test]
    fn tube_spread_takes_percentiles_of_range_and_width() {
        let image = |id: u64| CocoImage { id, width: 10, height: 10, file_name: format!("{id}.png"), extra: serde_json::from_value(serde_json::json!({"camera": {"fx": 1000.0}})).unwrap() };
        let ann = |id: u64, r: Option<f64>| {
            let mut a: tubeloc_core::CocoAnnotation = serde_json::from_value(serde_json::json!({"id": id, "image_id": 1, "category_id": 1, "area": 1.0, "bbox": [0, 0, 1, 1], "iscrowd": 0})).unwrap();
            if let Some(r) = r {
                a.extra.insert("T_cam_tube".into(), serde_json::json!({"rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "translation": [0.0, 0.6 * r, 0.8 * r]}));
            }
            a
        };
        let mut anns: Vec<_> = (1..=10).map(|k| ann(k, Some(k as f64))).collect();
        anns.push(ann(11, None));
        let ds = assemble(vec![(image(1), anns)], serde_json::json!({}));
        let s = tube_spread(&ds).unwrap();
        for (got, want) in s.range_m.iter().zip([2.0, 6.0, 9.0]) {
            assert!((got - want).abs() < 1e-9, "{s:?}");
        }
        for (got, want) in s.width_px.iter().zip([17.1 / 9.0, 17.1 / 5.0, 17.1 / 2.0]) {
            assert!((got - want).abs() < 1e-9, "{s:?}");
        }
        assert_eq!(tube_spread(&assemble(vec![(image(1), vec![ann(1, None)])], serde_json::json!({}))), None);
    }
}
