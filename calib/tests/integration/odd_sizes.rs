//! The AprilTag wrapper never hands the C detector an input it cannot take (hardening issue,
//! item 1): 1 or 2 px tall images, and any image whose decimated quad image is that small,
//! crashed the process with a segmentation fault (SIGFPE for 1.5 decimation of 1-2 px wide
//! images, an abort for sides over 32767 px).

use tubeloc_calib::detect::{check_decimation, quad_image_size, MAX_IMAGE_SIDE, MIN_QUAD_SIDE};
use tubeloc_calib::{DetectorConfig, TagDetector};

/// A checkerboard-ish pattern so the C code's thresholding sees contrast everywhere.
fn pattern(w: usize, h: usize) -> Vec<u8> {
    (0..w * h).map(|i| if ((i % w) / 3 + (i / w) / 2) % 2 == 0 { 20 } else { 230 }).collect()
}

fn decimations() -> Vec<f32> {
    let mut d = vec![1.0, 1.5];
    d.extend((2..=64).map(|k| k as f32));
    d
}

#[test]
fn odd_sizes_and_decimations_never_crash() {
    let sizes = [(1, 1), (2, 2), (8, 1), (1, 8), (4000, 1), (1, 4000), (4000, 2), (2, 4000), (3, 3), (4, 4), (7, 7), (8, 8), (9, 9), (16, 2), (2, 16), (12, 12), (13, 17), (24, 5), (5, 24), (33, 33), (64, 9), (9, 64), (130, 130), (200, 3), (600, 17)];
    for dec in decimations() {
        let mut det = TagDetector::new(DetectorConfig { decimation: dec, ..Default::default() }).unwrap();
        for &(w, h) in &sizes {
            let img = pattern(w, h);
            let r = det.detect_raw(w, h, w, &img);
            let (qw, qh) = quad_image_size(w, h, dec);
            match r {
                Ok(tags) => assert!(tags.is_empty(), "{w}x{h} at {dec}: tags in a pattern?"),
                Err(e) => panic!("{w}x{h} at decimation {dec} (quad {qw}x{qh}): {e}"),
            }
        }
    }
}

#[test]
fn blur_kernel_wider_than_the_image_is_skipped() {
    for sigma in [0.5f32, 2.0, 5.0, 16.0] {
        let mut det = TagDetector::new(DetectorConfig { sigma, ..Default::default() }).unwrap();
        for (w, h) in [(8, 8), (9, 9), (20, 20), (33, 33), (64, 65), (100, 10)] {
            assert!(det.detect_raw(w, h, w, &pattern(w, h)).unwrap().is_empty());
        }
    }
}

#[test]
fn decimation_values_are_checked() {
    for ok in [1.0f32, 1.5, 2.0, 3.0, 64.0] {
        assert!(check_decimation(ok).is_ok(), "{ok}");
        assert!(TagDetector::new(DetectorConfig { decimation: ok, ..Default::default() }).is_ok());
    }
    for bad in [0.0f32, 0.5, 0.99, 1.2, 2.5, 65.0, 200.0, 300.0, f32::NAN, f32::INFINITY, -1.0] {
        let e = TagDetector::new(DetectorConfig { decimation: bad, ..Default::default() }).unwrap_err().to_string();
        assert!(e.contains("decimation"), "{bad}: {e}");
    }
    for bad in [f32::NAN, f32::INFINITY, -0.5, 16.5] {
        assert!(TagDetector::new(DetectorConfig { sigma: bad, ..Default::default() }).is_err(), "sigma {bad}");
    }
}

#[test]
fn too_large_and_inconsistent_buffers_are_errors() {
    let mut det = TagDetector::new(DetectorConfig::default()).unwrap();
    let w = MAX_IMAGE_SIDE + 1;
    let e = det.detect_raw(w, 8, w, &vec![0u8; w * 8]).unwrap_err().to_string();
    assert!(e.contains("32767"), "{e}");
    assert!(det.detect_raw(8, w, 8, &vec![0u8; w * 8]).is_err());
    // Buffers that do not hold the image, stride overflow, zero sizes.
    assert!(det.detect_raw(10, 10, 10, &[0u8; 99]).is_err());
    assert!(det.detect_raw(10, 10, 9, &[0u8; 100]).is_err());
    assert!(det.detect_raw(0, 10, 10, &[0u8; 100]).is_err());
    assert!(det.detect_raw(10, 0, 10, &[0u8; 100]).is_err());
    assert!(det.detect_raw(usize::MAX / 2, 3, usize::MAX / 2, &[0u8; 100]).is_err());
    // The smallest quad image that reaches the C code.
    let m = MIN_QUAD_SIDE;
    assert!(det.detect_raw(m, m, m, &pattern(m, m)).unwrap().is_empty());
    // Images with stride padding.
    let (w, h, s) = (50, 3, 64);
    assert!(det.detect_raw(w, h, s, &vec![128u8; s * h]).unwrap().is_empty());
}
