//! `Rle::from_compressed_string` on any bytes and any size; for every accepted string the
//! decode -> encode -> decode round trip must give the same counts, and (for masks up to 2^20
//! pixels) the mask -> RLE -> mask round trip the same pixels, area and (canonical counts) box.
#![no_main]
use libfuzzer_sys::fuzz_target;
use tubeloc_core::mask::Rle;

fuzz_target!(|data: &[u8]| {
    if data.len() < 8 {
        return;
    }
    let h = u32::from_le_bytes([data[0], data[1], data[2], data[3]]);
    let w = u32::from_le_bytes([data[4], data[5], data[6], data[7]]);
    let Ok(s) = std::str::from_utf8(&data[8..]) else { return };
    let Ok(rle) = Rle::from_compressed_string(s, [h, w]) else { return };
    let again = Rle::from_compressed_string(&rle.to_compressed_string(), [h, w]).expect("re-encoded string decodes");
    assert_eq!(again, rle, "decode -> encode -> decode changed the counts");
    let _ = rle.to_bbox();
    // Boxes agree only for canonical counts: like pycocotools' `rleToBbox`, `to_bbox` counts the
    // end position of a zero-length run of ones as a pixel, so non-canonical strings may differ.
    let canonical = rle.counts.iter().skip(1).all(|&c| c > 0);
    if (h as u64) * (w as u64) <= 1 << 20 {
        let mask = rle.to_mask().expect("checked RLE decodes");
        let canon = Rle::from_mask(&mask);
        assert_eq!(canon.area(), rle.area());
        assert_eq!(canon.to_mask().expect("canonical RLE decodes").data, mask.data);
        if canonical {
            assert_eq!(canon.to_bbox(), rle.to_bbox());
        }
    }
});
