//! Whether a frame is monochrome.
//!
//! Rover Navcams, Hazcams and Pancam through one filter take grey frames; stored as RGB (or
//! decoded to RGB) their three channels are equal at every pixel. The detectors, the
//! composites and the verifiers treat such frames by their own rules (the 600-800 nm band of
//! those cameras, per-kind cuts), so they share this one test.

/// Whether interleaved RGB8 `rgb` is grey: `r = g = b` at every pixel (an empty image is).
pub fn is_grey_rgb8(rgb: &[u8]) -> bool {
    rgb.chunks_exact(3).all(|p| p[0] == p[1] && p[1] == p[2])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_coloured_pixel_makes_a_frame_colour() {
        let mut rgb = vec![7u8; 3 * 100];
        assert!(is_grey_rgb8(&rgb));
        rgb[3 * 57 + 2] = 8;
        assert!(!is_grey_rgb8(&rgb));
        assert!(is_grey_rgb8(&[]));
    }
}
