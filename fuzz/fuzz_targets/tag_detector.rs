//! The AprilTag wrapper (`TagDetector::detect_raw`, the one caller of the C detector) with odd
//! sizes, strides, decimations and blurs. Input: width (u16 LE), height (u16 LE), stride extra
//! (u8), decimation index (u8: 1, 1.5, 2..=64, anything else is refused), sigma (u8, /16 px),
//! flags (u8: refine edges, linearize sRGB), then pixels (repeated to fill the image). Any
//! width and height up to 4096 x 4096 are tried; sizes beyond [`MAX_IMAGE_SIDE`] are checked
//! for an error without allocating them.
#![no_main]
use libfuzzer_sys::fuzz_target;
use tubeloc_calib::detect::MAX_IMAGE_SIDE;
use tubeloc_calib::{DetectorConfig, TagDetector};

fuzz_target!(|data: &[u8]| {
    if data.len() < 8 {
        return;
    }
    let w = u16::from_le_bytes([data[0], data[1]]) as usize;
    let h = u16::from_le_bytes([data[2], data[3]]) as usize;
    let stride = w + data[4] as usize % 64;
    let decimation = match data[5] {
        0 => 1.0,
        1 => 1.5,
        k => k as f32, // 2..=255: above 64 refused by TagDetector::new
    };
    let sigma = data[6] as f32 / 16.0;
    let cfg = DetectorConfig { decimation, sigma, refine_edges: data[7] & 1 == 1, linearize_srgb: data[7] & 2 == 2, ..Default::default() };
    let Ok(mut det) = TagDetector::new(cfg) else { return };
    if w > MAX_IMAGE_SIDE || h > MAX_IMAGE_SIDE {
        assert!(det.detect_raw(w, h, stride, &[]).is_err());
        return;
    }
    // Keep each input cheap: at most 4096 x 4096 (16 MiB) of pixels.
    let (w, h) = (w.min(4096), h.min(4096));
    let stride = stride.min(w + 63);
    let pixels = &data[8..];
    let n = stride * h.saturating_sub(1) + w;
    let buf: Vec<u8> = if pixels.is_empty() { vec![0; n] } else { pixels.iter().copied().cycle().take(n).collect() };
    let _ = det.detect_raw(w, h, stride, &buf);
    // A short buffer is an error, never a read past its end.
    if n > 0 {
        assert!(det.detect_raw(w, h, stride, &buf[..n - 1]).is_err());
    }
});
