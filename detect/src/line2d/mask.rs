//! COCO run-length encoding of a placed template silhouette, scanning only the template's box
//! (the rest of the image is background), into the core [`Rle`] type.

use tubeloc_core::Rle;

/// Encodes a mask given by `inside(x, y)` over an `height x width` image as a COCO [`Rle`]
/// (column-major runs starting with zeros), scanning only columns `x0..x1` and rows `y0..y1`.
pub fn rle_from_box(height: u32, width: u32, x0: u32, x1: u32, y0: u32, y1: u32, inside: impl Fn(u32, u32) -> bool) -> Rle {
    {
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
        Rle { size: [height, width], counts }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rle_counts_column_major() {
        // 3x4 image (h=3, w=4), foreground at (x=1, y=1) and (x=1, y=2), (x=2, y=0).
        let fg = [(1u32, 1u32), (1, 2), (2, 0)];
        let r = rle_from_box(3, 4, 1, 3, 0, 3, |x, y| fg.contains(&(x, y)));
        // Column-major sequence: col0 000, col1 011, col2 100, col3 000 -> 4 zeros, 3 ones, 8 zeros...
        assert_eq!(r.counts, vec![4, 3, 5]);
        assert_eq!(r.area(), 3);
        // Known pycocotools encoding of counts [4, 3, 5] is "435".
        assert_eq!(r.to_compressed_string(), "435");
        let full = tubeloc_core::BinaryMask::from_fn(4, 3, |x, y| fg.contains(&(x as u32, y as u32)));
        assert_eq!(r, Rle::from_mask(&full));
    }
}
