//! 16-bit sensor data at 8 bits per channel, by their real bit depth.
//!
//! Rover EDRs hold 12-bit data in 16-bit containers. The data's depth is taken as the bits of
//! the largest value, at least 8: `b = clamp(⌈log2(max + 1)⌉, 8, 16)`, and values map to
//! `round(v · 255 / (2^b - 1))`, so 12-bit data fill the 8-bit range instead of being divided
//! by 257 into its bottom sixteenth.

/// Bits of data in 16-bit values whose largest is `max`: `clamp(⌈log2(max + 1)⌉, 8, 16)`.
pub fn data_bits(max: u16) -> u8 {
    (16 - max.leading_zeros() as u8).max(8)
}

/// 16-bit values at 8 bits by their real depth (see the module doc), and that depth in bits.
pub fn eight_bit_levels(values: &[u16]) -> (Vec<u8>, u8) {
    let bits = data_bits(values.iter().copied().max().unwrap_or(0));
    let scale = 255.0 / ((1u32 << bits) - 1) as f32;
    (values.iter().map(|&v| (v as f32 * scale).round().min(255.0) as u8).collect(), bits)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn twelve_bit_data_fill_the_eight_bit_range() {
        assert_eq!(data_bits(0), 8);
        assert_eq!(data_bits(255), 8);
        assert_eq!(data_bits(256), 9);
        assert_eq!(data_bits(4095), 12);
        assert_eq!(data_bits(u16::MAX), 16);
        let (levels, bits) = eight_bit_levels(&[0, 2048, 4095]);
        assert_eq!((levels, bits), (vec![0, 128, 255], 12));
        // Full 16-bit data are the usual division by 257.
        let (levels, bits) = eight_bit_levels(&[257, 65535]);
        assert_eq!((levels, bits), (vec![1, 255], 16));
        // 8-bit data in a 16-bit container keep their levels.
        assert_eq!(eight_bit_levels(&[7, 200]).0, vec![7, 200]);
    }
}
