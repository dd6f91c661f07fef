//! The Line2D template library loader (`TemplateLibrary::from_bytes`, what `load` runs).
//! Inputs whose first byte is odd are raw files; otherwise the rest is a payload that gets a
//! valid header (magic, version, length, CRC-32), so the fuzzer reaches the payload parser.
#![no_main]
use libfuzzer_sys::fuzz_target;
use tubeloc_detect::line2d::format::{FORMAT_VERSION, MAGIC};
use tubeloc_detect::line2d::TemplateLibrary;

fuzz_target!(|data: &[u8]| {
    let Some((&mode, rest)) = data.split_first() else { return };
    if mode & 1 == 1 {
        let _ = TemplateLibrary::from_bytes(rest);
        return;
    }
    let mut file = Vec::with_capacity(24 + rest.len());
    file.extend_from_slice(MAGIC);
    file.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    file.extend_from_slice(&(rest.len() as u64).to_le_bytes());
    file.extend_from_slice(&crc32(rest).to_le_bytes());
    file.extend_from_slice(rest);
    let _ = TemplateLibrary::from_bytes(&file);
});

/// CRC-32 (IEEE, reflected, polynomial 0xEDB88320), as `crc32fast::hash`.
fn crc32(bytes: &[u8]) -> u32 {
    let mut c = !0u32;
    for &b in bytes {
        c ^= b as u32;
        for _ in 0..8 {
            c = if c & 1 != 0 { (c >> 1) ^ 0xEDB8_8320 } else { c >> 1 };
        }
    }
    !c
}
