//! The JPEG luma reader of tag detection (`grey::jpeg_luma`) on arbitrary bytes: it returns
//! an error or a grey image whose buffer is exactly its width times height, never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(img) = tubeloc_calib::grey::jpeg_luma(data) {
        assert_eq!(img.as_raw().len(), img.width() as usize * img.height() as usize);
    }
});
