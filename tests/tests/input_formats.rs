//! One scene in several file formats gives the same learned detections: 8-bit colour, 8-bit
//! grey, 16-bit grey holding 12-bit data (in memory, PGM and TIFF files), 16-bit RGBA, JPEG,
//! BMP and WebP. The scene is a composite of
//! rendered tubes on a real Navcam frame with its PDS camera model (`../shared/data`), detected
//! at its working scale with the shipped model.

use std::path::{Path, PathBuf};
use tubeloc_detect::learned::{detect_rgb_at_scale, DecodeConfig, LearnedModel};
use tubeloc_synth::real_frames::views_from_cameras_json;
use tubeloc_synth::real_set::{render_sample, RealSetConfig};

fn data() -> PathBuf {
    let d = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/real_mars");
    assert!(d.join("MANIFEST.tsv").exists(), "{} is missing: these tests need ../shared/data beside the repository", d.display());
    d
}

fn model() -> LearnedModel {
    LearnedModel::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/models/tubenet.safetensors")).unwrap()
}

/// Mask IoU of two detections' masks.
fn iou(a: &[u8], b: &[u8]) -> f64 {
    let (mut i, mut u) = (0usize, 0usize);
    for (&x, &y) in a.iter().zip(b) {
        i += (x != 0 && y != 0) as usize;
        u += (x != 0 || y != 0) as usize;
    }
    i as f64 / u.max(1) as f64
}

#[test]
fn grey_sixteen_bit_rgba_jpeg_pgm_tiff_bmp_and_webp_give_the_detections_of_the_eight_bit_colour_image() {
    let views = views_from_cameras_json(&data().join("with_cameras/cameras.json")).unwrap();
    let view = views.iter().find(|v| v.camera.width == 1024 && v.sol == Some(38)).expect("a sol-38 Navcam frame");
    let cfg = RealSetConfig {
        tubes: (3, 3),
        per_view: 1,
        range_m: (1.5, 5.0),
        dust: (0.0, 0.0),
        tube_gain: (1.0, 1.0),
        jpeg_quality: None,
        seed: 5,
        tube_shape: std::sync::Arc::new(tubeloc_synth::TubeShape::from_model(&tubeloc_core::TubeModel::default())),
        colour_as_grey: false,
    };
    let sample = render_sample(view, 0, 1, &cfg).unwrap().expect("three tubes fit on the frame");
    let decoded = image::load_from_memory(&sample.bytes).unwrap();
    let grey8 = decoded.to_luma8();
    let (w, h) = grey8.dimensions();
    let cam = view.camera.clone();
    let s = tubeloc_detect::scale::working_scale(&cam, Some(view.ground()), Default::default());
    assert!(s > 1.5, "a Navcam frame is scaled up to the working scale, got {s}");
    let m = model();
    let cfg = DecodeConfig::default();
    let run = |img: image::DynamicImage| {
        let input = tubeloc_detect::input::rgb8_of(&img);
        assert!(input.info.warning().is_none());
        detect_rgb_at_scale(&m, &input.rgb, input.width, input.height, s, &cfg).unwrap()
    };
    // The 8-bit colour version: the grey frame replicated in R, G and B.
    let colour = image::DynamicImage::ImageRgb8(image::DynamicImage::ImageLuma8(grey8.clone()).to_rgb8());
    let reference = run(colour);
    assert!(reference.len() >= 2, "the composite's tubes are found: {} detections", reference.len());
    let twelve = image::ImageBuffer::<image::Luma<u16>, _>::from_fn(w, h, |x, y| image::Luma([grey8.get_pixel(x, y).0[0] as u16 * 16 + 8]));
    let rgba16 = image::DynamicImage::ImageLuma8(grey8.clone()).to_rgba16();
    let mut jpeg = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, 95).encode_image(&grey8).unwrap();
    // Files as a rover pipeline may write them, read by `open_image` as the CLI reads them:
    // 12-bit data in a 16-bit PGM (big-endian, `maxval` 4095 or 65535), 16-bit TIFF, BMP and
    // (lossless) WebP.
    let dir = tempfile::tempdir().unwrap();
    let pgm = |maxval: u32| {
        let mut b = format!("P5\n{w} {h}\n{maxval}\n").into_bytes();
        b.extend(twelve.pixels().flat_map(|p| p.0[0].to_be_bytes()));
        b
    };
    let files: [(&str, Vec<u8>); 2] = [("twelve_4095.pgm", pgm(4095)), ("twelve_65535.pgm", pgm(65535))];
    for (name, bytes) in &files {
        std::fs::write(dir.path().join(name), bytes).unwrap();
    }
    image::DynamicImage::ImageLuma16(twelve.clone()).save(dir.path().join("twelve.tif")).unwrap();
    image::DynamicImage::ImageLuma8(grey8.clone()).save(dir.path().join("grey.bmp")).unwrap();
    image::DynamicImage::ImageRgb8(image::DynamicImage::ImageLuma8(grey8.clone()).to_rgb8()).save(dir.path().join("colour.webp")).unwrap();
    let read = |name: &str| tubeloc_detect::input::open_image(dir.path().join(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
    let variants: Vec<(&str, image::DynamicImage)> = vec![
        ("8-bit grey", image::DynamicImage::ImageLuma8(grey8.clone())),
        ("12-bit data in 16-bit grey", image::DynamicImage::ImageLuma16(twelve)),
        ("16-bit RGBA", image::DynamicImage::ImageRgba16(rgba16)),
        ("JPEG q95", image::load_from_memory(&jpeg).unwrap()),
        ("PGM, 12-bit maxval 4095", read("twelve_4095.pgm")),
        ("PGM, 12-bit data under maxval 65535", read("twelve_65535.pgm")),
        ("16-bit TIFF, 12-bit data", read("twelve.tif")),
        ("BMP", read("grey.bmp")),
        ("WebP", read("colour.webp")),
    ];
    for (name, img) in variants {
        let found = run(img);
        // Tolerance: the same number of detections above 0.3, each matching a reference mask
        // at IoU >= 0.8 with a score within 0.1 (JPEG and the 12-bit rounding move pixels by
        // up to a few DN).
        let strong = |v: &[tubeloc_detect::learned::LearnedInstance]| v.iter().filter(|d| d.score >= 0.3).count();
        assert_eq!(strong(&found), strong(&reference), "{name}: {} vs {} detections above 0.3", strong(&found), strong(&reference));
        for r in reference.iter().filter(|d| d.score >= 0.3) {
            let best = found.iter().map(|f| (iou(&f.mask.to_mask().unwrap().data, &r.mask.to_mask().unwrap().data), f.score)).max_by(|a, b| a.0.total_cmp(&b.0)).unwrap();
            assert!(best.0 >= 0.8 && (best.1 - r.score).abs() <= 0.1, "{name}: best IoU {:.3}, score {:.3} vs {:.3}", best.0, best.1, r.score);
        }
    }
}

/// Every real JPEG in `../shared/data` (rover frames, tag photos) reads as complete, and each
/// cut short at a few points is refused by `open_image` with a message saying it is truncated,
/// where the decoder alone would return an image with blank rows.
#[test]
fn real_jpegs_read_whole_and_cut_ones_are_refused() {
    fn jpegs(dir: &Path, out: &mut Vec<PathBuf>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                jpegs(&p, out);
            } else if p.extension().is_some_and(|e| e.eq_ignore_ascii_case("jpg") || e.eq_ignore_ascii_case("jpeg")) {
                out.push(p);
            }
        }
    }
    let mut files = Vec::new();
    jpegs(&data(), &mut files);
    jpegs(&data().join("../apriltag"), &mut files);
    files.sort();
    assert!(files.len() > 300, "{} JPEGs", files.len());
    let dir = tempfile::tempdir().unwrap();
    for (k, f) in files.iter().enumerate() {
        let bytes = std::fs::read(f).unwrap();
        assert!(!tubeloc_core::image_file::jpeg_ends_early(&bytes), "{} reads as truncated", f.display());
        if k % 50 == 0 {
            for frac in [0.3, 0.9] {
                let cut = dir.path().join(format!("cut_{k}.jpg"));
                std::fs::write(&cut, &bytes[..(bytes.len() as f64 * frac) as usize]).unwrap();
                assert!(image::open(&cut).is_ok(), "the decoder alone accepts the cut {}", f.display());
                let e = tubeloc_detect::input::open_image(&cut).unwrap_err().to_string();
                assert!(e.contains("truncated"), "{}: {e}", f.display());
            }
        }
    }
}
