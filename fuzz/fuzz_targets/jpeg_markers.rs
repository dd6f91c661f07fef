//! The JPEG marker walk that refuses truncated files (`image_file::jpeg_ends_early`) on
//! arbitrary bytes: no panic, and a stream it reads as complete stays complete with bytes
//! appended after it (it stopped at the end-of-image marker).
#![no_main]
use libfuzzer_sys::fuzz_target;
use tubeloc_core::image_file::jpeg_ends_early;

fuzz_target!(|data: &[u8]| {
    let mut v = vec![0xFF, 0xD8];
    v.extend_from_slice(data);
    if !jpeg_ends_early(&v) {
        v.extend_from_slice(&[0xFF, 0xDA, 0x00]);
        assert!(!jpeg_ends_early(&v));
    }
    let _ = jpeg_ends_early(data);
});
