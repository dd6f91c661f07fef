//! A minimal COCO run-length encoding of placed template silhouettes (column-major counts,
//! starting with a run of zeros), with the compressed string form of pycocotools' `maskApi.c`.
//!
//! Kept internal to the detector; [`Line2dDetection`](crate::line2d::Line2dDetection) exposes
//! COCO JSON through it.

/// An uncompressed COCO RLE of an `height x width` mask.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RleMask {
    /// Image height, pixels.
    pub height: u32,
    /// Image width, pixels.
    pub width: u32,
    /// Alternating run lengths of 0s and 1s in column-major order, starting with 0s.
    pub counts: Vec<u32>,
}

impl RleMask {
    /// Encodes a mask given by `inside(x, y)` over an `height x width` image, scanning only
    /// columns `x0..x1` and rows `y0..y1` (everything else is 0).
    pub fn from_box(height: u32, width: u32, x0: u32, x1: u32, y0: u32, y1: u32, inside: impl Fn(u32, u32) -> bool) -> RleMask {
        let mut counts = Vec::new();
        let mut cur = 0u8;
        let mut run = 0u32;
        let push = |v: u8, n: u32, counts: &mut Vec<u32>, cur: &mut u8, run: &mut u32| {
            if n == 0 {
                return;
            }
            if v != *cur {
                counts.push(*run);
                *run = 0;
                *cur = v;
            }
            *run += n;
        };
        push(0, x0 * height, &mut counts, &mut cur, &mut run);
        for x in x0..x1 {
            push(0, y0, &mut counts, &mut cur, &mut run);
            for y in y0..y1 {
                push(inside(x, y) as u8, 1, &mut counts, &mut cur, &mut run);
            }
            push(0, height - y1, &mut counts, &mut cur, &mut run);
        }
        push(0, (width - x1) * height, &mut counts, &mut cur, &mut run);
        counts.push(run);
        RleMask { height, width, counts }
    }

    /// Number of foreground pixels.
    pub fn area(&self) -> u64 {
        self.counts.iter().skip(1).step_by(2).map(|&c| c as u64).sum()
    }

    /// The compressed `counts` string of pycocotools (`rleToString`): deltas against the count
    /// two places back (from the fourth on), 5 bits per character with a continuation bit,
    /// offset by 48.
    pub fn to_compressed_string(&self) -> String {
        let mut s = String::new();
        for i in 0..self.counts.len() {
            let mut x = self.counts[i] as i64;
            if i > 2 {
                x -= self.counts[i - 2] as i64;
            }
            loop {
                let mut c = (x & 0x1f) as u8;
                x >>= 5;
                let more = if c & 0x10 != 0 { x != -1 } else { x != 0 };
                if more {
                    c |= 0x20;
                }
                s.push((c + 48) as char);
                if !more {
                    break;
                }
            }
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rle_counts_column_major() {
        // 3x4 image (h=3, w=4), foreground at (x=1, y=1) and (x=1, y=2), (x=2, y=0).
        let fg = [(1u32, 1u32), (1, 2), (2, 0)];
        let r = RleMask::from_box(3, 4, 1, 3, 0, 3, |x, y| fg.contains(&(x, y)));
        // Column-major sequence: col0 000, col1 011, col2 100, col3 000 -> 4 zeros, 3 ones, 8 zeros... 
        assert_eq!(r.counts, vec![4, 3, 5]);
        assert_eq!(r.area(), 3);
        // Known pycocotools encoding of counts [4, 3, 5] is "435".
        assert_eq!(r.to_compressed_string(), "435");
        let big = RleMask { height: 100, width: 100, counts: vec![100, 50, 9850] };
        assert_eq!(big.to_compressed_string().len(), 7);
    }
}
