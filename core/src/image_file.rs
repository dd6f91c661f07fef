//! Checks on image files' bytes before decoding.
//!
//! A JPEG cut short (a partial download or downlink) still decodes: the decoders fill the
//! missing rows with grey and report nothing, and detectors then run on half an image. So the
//! stream's markers are walked first: segments by their lengths (an EXIF thumbnail with its
//! own markers is skipped whole), each scan's entropy-coded data up to the next marker (`FF`
//! followed by neither `00`, a stuffed byte, nor `D0`-`D7`, a restart marker), until the
//! end-of-image marker `FF D9`. A stream that runs out first ends early.

/// Whether `bytes` start like a JPEG stream (SOI marker `FF D8`).
pub fn is_jpeg(bytes: &[u8]) -> bool {
    bytes.starts_with(&[0xFF, 0xD8])
}

/// Whether `bytes` are a JPEG stream ([`is_jpeg`]) that ends before its end-of-image marker:
/// the file was cut short. `false` for other formats. O(bytes), no allocation.
pub fn jpeg_ends_early(bytes: &[u8]) -> bool {
    if !is_jpeg(bytes) {
        return false;
    }
    let mut at = 2;
    loop {
        // The next marker: FF (fill bytes FF allowed) then its code.
        while bytes.get(at) == Some(&0xFF) && bytes.get(at + 1) == Some(&0xFF) {
            at += 1;
        }
        let (Some(&0xFF), Some(&code)) = (bytes.get(at), bytes.get(at + 1)) else { return true };
        at += 2;
        match code {
            0xD9 => return false,
            // Standalone markers: TEM, RSTn, SOI.
            0x01 | 0xD0..=0xD8 => continue,
            _ => {}
        }
        let (Some(&hi), Some(&lo)) = (bytes.get(at), bytes.get(at + 1)) else { return true };
        let len = u16::from_be_bytes([hi, lo]) as usize;
        if len < 2 {
            return true;
        }
        at += len;
        if at > bytes.len() {
            return true;
        }
        if code == 0xDA {
            // Entropy-coded data: up to a marker that is neither stuffing nor a restart.
            loop {
                match (bytes.get(at), bytes.get(at + 1)) {
                    (Some(&0xFF), Some(&next)) if next == 0x00 || (0xD0..=0xD7).contains(&next) || next == 0xFF => at += if next == 0xFF { 1 } else { 2 },
                    (Some(&0xFF), Some(_)) => break,
                    (Some(_), _) => at += 1,
                    (None, _) => return true,
                }
            }
        }
    }
}

/// [`jpeg_ends_early`] as an error message, or `Ok` for a complete stream or another format.
/// An empty file is refused too (a decoder would only say that it cannot tell the format).
pub fn check_complete(bytes: &[u8]) -> Result<(), String> {
    if bytes.is_empty() {
        return Err("the file is empty (0 bytes)".into());
    }
    if jpeg_ends_early(bytes) {
        return Err(format!("the JPEG data end before the end-of-image marker ({} bytes): the file is truncated, and a decoded image would be partly blank", bytes.len()));
    }
    Ok(())
}

/// The bytes of an image file, refused when it is a JPEG cut short ([`check_complete`]; an
/// [`std::io::ErrorKind::InvalidData`] error saying so), for a decoder to read from memory.
pub fn read_whole(path: &std::path::Path) -> std::io::Result<Vec<u8>> {
    let bytes = std::fs::read(path)?;
    check_complete(&bytes).map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidData, e))?;
    Ok(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A minimal marker skeleton: SOI, an APP segment holding a thumbnail's markers, SOS with
    /// stuffed bytes and a restart marker in its data, EOI.
    fn skeleton() -> Vec<u8> {
        let mut b = vec![0xFF, 0xD8, 0xFF, 0xE1, 0x00, 0x08, 0xFF, 0xDA, 0xFF, 0xD9, 0x00, 0x00];
        b.extend([0xFF, 0xDA, 0x00, 0x04, 0x01, 0x02, 0x12, 0xFF, 0x00, 0x34, 0xFF, 0xD3, 0x56, 0xFF, 0xD9]);
        b
    }

    #[test]
    fn a_jpeg_cut_before_its_end_marker_ends_early() {
        let full = skeleton();
        assert!(!jpeg_ends_early(&full));
        assert!(check_complete(&full).is_ok());
        // Bytes after the end marker (camera trailers) are allowed.
        let mut trailer = full.clone();
        trailer.extend([0u8; 16]);
        assert!(!jpeg_ends_early(&trailer));
        // Cut inside the scan, or before any scan (the thumbnail's end marker does not count).
        for cut in [full.len() - 1, full.len() - 2, full.len() - 5, 13, 4, 2] {
            assert!(jpeg_ends_early(&full[..cut]), "cut at {cut}");
            assert!(check_complete(&full[..cut]).unwrap_err().contains("truncated"));
        }
        // Files: the whole stream is read, the cut one refused as invalid data.
        let dir = tempfile::tempdir().unwrap();
        let (whole, cut) = (dir.path().join("whole.jpg"), dir.path().join("cut.jpg"));
        std::fs::write(&whole, &full).unwrap();
        std::fs::write(&cut, &full[..13]).unwrap();
        assert_eq!(read_whole(&whole).unwrap(), full);
        let e = read_whole(&cut).unwrap_err();
        assert!(e.kind() == std::io::ErrorKind::InvalidData && e.to_string().contains("truncated"), "{e}");
        // Not a JPEG: nothing to say.
        assert!(!jpeg_ends_early(b"\x89PNG\r\n\x1a\n"));
        assert!(!jpeg_ends_early(&[]));
        let empty = dir.path().join("empty.png");
        std::fs::write(&empty, []).unwrap();
        let e = read_whole(&empty).unwrap_err();
        assert!(e.kind() == std::io::ErrorKind::InvalidData && e.to_string().contains("empty (0 bytes)"), "{e}");
    }
}
