//! RLE tests: round trips, and agreement with outputs recorded from pycocotools 2.0.11
//! (`scripts/coco_rle_fixtures.py` -> `tests/fixtures/rle_pycocotools.json`).

use serde_json::Value;
use tubeloc_core::mask::bbox_iou;
use tubeloc_core::{BinaryMask, BoundedMask, Rle};

fn fixture() -> Value {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/rle_pycocotools.json");
    serde_json::from_slice(&std::fs::read(&p).expect("fixture present")).expect("fixture JSON")
}

fn mask_from_rows(h: usize, w: usize, rows: &Value) -> BinaryMask {
    let rows: Vec<&str> = rows.as_array().unwrap().iter().map(|r| r.as_str().unwrap()).collect();
    BinaryMask::from_fn(w, h, |x, y| rows[y].as_bytes()[x] == b'1')
}

fn hw(c: &Value) -> (u32, u32) {
    (c["h"].as_u64().unwrap() as u32, c["w"].as_u64().unwrap() as u32)
}

#[test]
fn encode_matches_pycocotools_strings_area_and_bbox() {
    let f = fixture();
    let cases = f["masks"].as_array().unwrap();
    assert!(cases.len() >= 30);
    for (i, c) in cases.iter().enumerate() {
        let (h, w) = hw(c);
        let m = mask_from_rows(h as usize, w as usize, &c["rows"]);
        let rle = Rle::from_mask(&m);
        assert_eq!(rle.to_compressed_string(), c["counts"].as_str().unwrap(), "mask {i}");
        assert_eq!(rle.area(), c["area"].as_u64().unwrap(), "mask {i}");
        assert_eq!(m.area(), rle.area());
        let bb: Vec<f64> = c["bbox"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
        assert_eq!(rle.to_bbox().to_vec(), bb, "mask {i}");
        assert_eq!(m.bbox().to_vec(), bb, "mask {i}: BinaryMask::bbox");
        // string -> rle -> mask round trip
        let back = Rle::from_compressed_string(c["counts"].as_str().unwrap(), [h, w]).unwrap();
        assert_eq!(back, rle);
        assert_eq!(back.to_mask().unwrap(), m);
    }
}

#[test]
fn large_sparse_mask_multi_chunk_counts() {
    let f = fixture();
    let c = &f["big"];
    let (h, w) = hw(c);
    let mut m = BinaryMask::new(w as usize, h as usize);
    for p in c["ones"].as_array().unwrap() {
        m.set(p[1].as_u64().unwrap() as usize, p[0].as_u64().unwrap() as usize, true);
    }
    let rle = Rle::from_mask(&m);
    let s = c["counts"].as_str().unwrap();
    assert_eq!(rle.to_compressed_string(), s);
    assert_eq!(Rle::from_compressed_string(s, [h, w]).unwrap(), rle);
    assert_eq!(rle.area(), c["area"].as_u64().unwrap());
    let bb: Vec<f64> = c["bbox"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    assert_eq!(rle.to_bbox().to_vec(), bb);
}

#[test]
fn merge_matches_pycocotools() {
    let f = fixture();
    let masks = f["masks"].as_array().unwrap();
    let merges = f["merges"].as_array().unwrap();
    assert!(!merges.is_empty());
    for c in merges {
        let rles: Vec<Rle> = c["inputs"]
            .as_array()
            .unwrap()
            .iter()
            .map(|i| {
                let m = &masks[i.as_u64().unwrap() as usize];
                let (h, w) = hw(m);
                Rle::from_compressed_string(m["counts"].as_str().unwrap(), [h, w]).unwrap()
            })
            .collect();
        assert_eq!(Rle::merge(&rles, false).unwrap().to_compressed_string(), c["union"].as_str().unwrap());
        assert_eq!(Rle::merge(&rles, true).unwrap().to_compressed_string(), c["intersection"].as_str().unwrap());
    }
}

#[test]
fn mask_iou_matches_pycocotools_including_crowd() {
    let f = fixture();
    for c in f["ious"].as_array().unwrap() {
        let (h, w) = hw(c);
        let dec = |k: &str| -> Vec<Rle> { c[k].as_array().unwrap().iter().map(|s| Rle::from_compressed_string(s.as_str().unwrap(), [h, w]).unwrap()).collect() };
        let (dt, gt) = (dec("dt"), dec("gt"));
        let crowd: Vec<bool> = c["iscrowd"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap() == 1).collect();
        let got = Rle::iou(&dt, &gt, &crowd);
        let want = c["iou"].as_array().unwrap();
        for d in 0..dt.len() {
            for g in 0..gt.len() {
                assert_eq!(got[d * gt.len() + g], want[d][g].as_f64().unwrap(), "d {d} g {g}");
            }
        }
    }
}

#[test]
fn polygons_rasterize_like_rle_fr_poly() {
    let f = fixture();
    for (i, c) in f["polygons"].as_array().unwrap().iter().enumerate() {
        let (h, w) = hw(c);
        let polys: Vec<Vec<f64>> = serde_json::from_value(c["polygons"].clone()).unwrap();
        for (j, p) in polys.iter().enumerate() {
            let rle = Rle::from_polygon(p, h, w);
            assert_eq!(rle.to_compressed_string(), c["each"][j].as_str().unwrap(), "case {i} polygon {j}");
            rle.check().unwrap();
        }
        let merged = Rle::from_polygons(&polys, h, w).unwrap();
        assert_eq!(merged.to_compressed_string(), c["merged"].as_str().unwrap(), "case {i} merged");
    }
}

#[test]
fn boxes_rasterize_like_rle_fr_bbox() {
    let f = fixture();
    for (i, c) in f["boxes"].as_array().unwrap().iter().enumerate() {
        let (h, w) = hw(c);
        let bb: [f64; 4] = serde_json::from_value(c["bbox"].clone()).unwrap();
        assert_eq!(Rle::from_bbox(bb, h, w).to_compressed_string(), c["counts"].as_str().unwrap(), "box {i}");
    }
}

#[test]
fn bbox_iou_matches_pycocotools() {
    let f = fixture();
    let c = &f["bbox_iou"];
    let dt: Vec<[f64; 4]> = serde_json::from_value(c["dt"].clone()).unwrap();
    let gt: Vec<[f64; 4]> = serde_json::from_value(c["gt"].clone()).unwrap();
    let crowd: Vec<bool> = c["iscrowd"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap() == 1).collect();
    let got = bbox_iou(&dt, &gt, &crowd);
    let want: Vec<Vec<f64>> = serde_json::from_value(c["iou"].clone()).unwrap();
    for d in 0..dt.len() {
        for g in 0..gt.len() {
            assert_eq!(got[d * gt.len() + g], want[d][g], "d {d} g {g}");
        }
    }
    assert!((got[0] - 1.0).abs() < 1e-12, "identical box against a crowd gt: {}", got[0]);
}

#[test]
fn malformed_strings_and_sizes_are_errors() {
    // character outside the alphabet
    let e = Rle::from_compressed_string("12 3", [2, 3]).unwrap_err().to_string();
    assert!(e.contains("byte 2"), "{e}");
    // continuation bit set on the last byte: truncated
    let e = Rle::from_compressed_string("0P", [1, 1]).unwrap_err().to_string();
    assert!(e.contains("truncated"), "{e}");
    // counts that do not cover the image
    let good = Rle::from_mask(&BinaryMask::from_fn(4, 3, |x, y| x == y)).to_compressed_string();
    let e = Rle::from_compressed_string(&good, [3, 5]).unwrap_err().to_string();
    assert!(e.contains("sum to 12"), "{e}");
    // merge of different sizes
    let a = Rle::from_mask(&BinaryMask::new(2, 2));
    let b = Rle::from_mask(&BinaryMask::new(3, 2));
    assert!(Rle::merge(&[a.clone(), b.clone()], false).is_err());
    assert_eq!(Rle::iou(&[a], &[b], &[false]), vec![0.0], "empty masks: zero bbox overlap");
}

#[test]
fn round_trip_random_masks() {
    use std::num::Wrapping;
    let mut s = Wrapping(0x9e3779b97f4a7c15u64);
    for trial in 0..50 {
        let (w, h) = (1 + trial % 13, 1 + (trial * 7) % 11);
        let m = BinaryMask::from_fn(w, h, |_, _| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            // Dense masks, and sparse ones whose box is smaller than the image.
            s.0 % if trial % 2 == 0 { 3 } else { 29 } == 0
        });
        let rle = Rle::from_mask(&m);
        let text = rle.to_compressed_string();
        let back = Rle::from_compressed_string(&text, [h as u32, w as u32]).unwrap();
        assert_eq!(back.to_mask().unwrap(), m);
        assert_eq!(Rle::merge(&[rle.clone(), rle.clone()], true).unwrap(), rle);
        // The box found while decoding is the scanned one, and the windowed operations agree.
        let bounded = rle.to_bounded_mask().unwrap();
        assert_eq!(*bounded, m);
        assert_eq!(bounded.bbox(), m.bbox(), "trial {trial}: {w}x{h}");
        assert_eq!(Rle::from_bounded_mask(&bounded), rle);
        assert_eq!(bounded.dilated_window(2), m.dilated_window(2));
        assert_eq!(BoundedMask::new(m.clone()), bounded);
    }
}

/// Reference morphology over the whole image, one 4-neighbour step at a time.
fn morph_reference(m: &BinaryMask, r: usize, grow: bool) -> BinaryMask {
    let (w, h) = (m.width, m.height);
    let mut cur = m.clone();
    for _ in 0..r {
        let p = cur.clone();
        cur = BinaryMask::from_fn(w, h, |x, y| {
            let n = [x > 0 && p.get(x - 1, y), p.get(x + 1, y), y > 0 && p.get(x, y - 1), p.get(x, y + 1)];
            if grow {
                p.get(x, y) || n.iter().any(|&b| b)
            } else {
                p.get(x, y) && x > 0 && y > 0 && x + 1 < w && y + 1 < h && n.iter().all(|&b| b)
            }
        });
    }
    cur
}

#[test]
fn erosion_clears_a_pixel_ring() {
    let m = BinaryMask::from_fn(10, 10, |x, y| (2..8).contains(&x) && (2..8).contains(&y));
    let e = m.eroded(1);
    assert_eq!(m.area(), 36);
    assert_eq!(e.area(), 16);
    assert!(e.get(3, 3) && !e.get(2, 3));
}

#[test]
fn erosion_within_the_image_keeps_a_border_cut_edge() {
    // A 6x6 block cut by the left border: the border does not erode, the other sides do.
    let m = BinaryMask::from_fn(10, 10, |x, y| x < 6 && (2..8).contains(&y));
    let e = m.eroded_within_image(1);
    assert_eq!(e.area(), 5 * 4);
    assert!(e.get(0, 3) && e.get(4, 6) && !e.get(5, 3) && !e.get(0, 2));
    assert_eq!(m.eroded(1).area(), 4 * 4, "plain erosion clears the border column too");
    // The whole image set stays set.
    let full = BinaryMask::from_fn(7, 5, |_, _| true);
    assert_eq!(full.eroded_within_image(2), full);
}

#[test]
fn dilation_grows_a_pixel_into_a_diamond() {
    let m = BinaryMask::from_fn(11, 11, |x, y| x == 5 && y == 5);
    let d = m.dilated(2);
    assert_eq!(d.area(), 13, "L1 diamond of radius 2");
    assert!(d.get(5, 3) && d.get(4, 4) && !d.get(3, 3));
}

/// The bounding-box windowed morphology equals the whole-image reference, blobs at the image
/// border and scattered pixels included.
#[test]
fn windowed_morphology_matches_the_whole_image_reference() {
    let mut next = uniform_below(0x2545f4914f6cdd1d);
    for _ in 0..40 {
        let (w, h) = (1 + next(39), 1 + next(39));
        let (cx, cy, rad) = (next(w) as f64, next(h) as f64, 0.5 + next(8) as f64);
        let sparse = next(5) + 7;
        let m = BinaryMask::from_fn(w, h, |x, y| (x as f64 - cx).hypot(y as f64 - cy) < rad || (x * 7 + y * 3) % (sparse * 3) == 0);
        for r in 0..5 {
            let dilated = morph_reference(&m, r, true);
            assert_eq!(m.dilated(r), dilated, "dilate r {r} on {w}x{h}");
            // The window: the same pixels, none set outside it.
            let win = m.dilated_window(r);
            assert!((0..h + 2).all(|y| (0..w + 2).all(|x| win.get(x, y) == dilated.get(x, y))), "dilated window r {r} on {w}x{h}");
            assert!(win.x0 + win.mask.width <= w && win.y0 + win.mask.height <= h);
            assert_eq!(m.eroded(r), morph_reference(&m, r, false), "erode r {r} on {w}x{h}");
            // Within the image: as if the image went on with set pixels beyond its border.
            let pad = r + 1;
            let padded = BinaryMask::from_fn(w + 2 * pad, h + 2 * pad, |x, y| x < pad || y < pad || x >= w + pad || y >= h + pad || m.get(x - pad, y - pad));
            let reference = morph_reference(&padded, r, false);
            assert_eq!(m.eroded_within_image(r), BinaryMask::from_fn(w, h, |x, y| reference.get(x + pad, y + pad)), "erode within the image r {r} on {w}x{h}");
        }
    }
}

#[test]
fn a_crop_is_the_window_and_clear_beyond_the_mask() {
    let m = BinaryMask::from_fn(9, 7, |x, y| (x * 7 + y * 3) % 5 == 0);
    let c = m.crop(2, 3, 4, 3);
    assert_eq!((c.width, c.height), (4, 3));
    for y in 0..3 {
        for x in 0..4 {
            assert_eq!(c.get(x, y), m.get(x + 2, y + 3), "pixel ({x}, {y})");
        }
    }
    // A window hanging over the right and bottom edges, and one wholly outside.
    let over = m.crop(6, 5, 6, 4);
    assert!((0..4).all(|y| (0..6).all(|x| over.get(x, y) == m.get(x + 6, y + 5))));
    assert_eq!(m.crop(20, 20, 3, 3), BinaryMask::new(3, 3));
}

/// `BinaryMask::bbox` (word-wise search) equals the box of a pixel-by-pixel scan, on widths
/// that are and are not multiples of 8, with blobs touching each border and single pixels.
#[test]
fn bbox_matches_a_pixel_scan() {
    let mut next = uniform_below(0x9e3779b97f4a7c15);
    for case in 0..300 {
        let (w, h) = (1 + next(70), 1 + next(40));
        let m = match case % 3 {
            0 => BinaryMask::from_fn(w, h, |x, y| x == next(w).min(x) && y == next(h).min(y) && next(9) == 0),
            1 => {
                let (cx, cy, r) = (next(w) as f64, next(h) as f64, next(12) as f64);
                BinaryMask::from_fn(w, h, |x, y| (x as f64 - cx).hypot(y as f64 - cy) <= r)
            }
            _ => {
                let (x, y) = (next(w), next(h));
                BinaryMask::from_fn(w, h, |i, j| i == x && j == y)
            }
        };
        let set: Vec<(usize, usize)> = (0..h).flat_map(|y| (0..w).map(move |x| (x, y))).filter(|&(x, y)| m.get(x, y)).collect();
        let expect = match (set.iter().map(|p| p.0).min(), set.iter().map(|p| p.0).max(), set.iter().map(|p| p.1).min(), set.iter().map(|p| p.1).max()) {
            (Some(x0), Some(x1), Some(y0), Some(y1)) => [x0 as f64, y0 as f64, (x1 - x0 + 1) as f64, (y1 - y0 + 1) as f64],
            _ => [0.0; 4],
        };
        assert_eq!(m.bbox(), expect, "case {case}: {w}x{h}, {} set pixels", set.len());
    }
}

/// A reproducible stream of integers, `next(n)` in `0..n` (xorshift64 from `seed`, nonzero).
fn uniform_below(seed: u64) -> impl FnMut(usize) -> usize {
    let mut s = seed;
    move |n| {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s % n as u64) as usize
    }
}

/// Column-major run-length encoding, pixel by pixel (the definition `from_mask` must match).
fn reference_rle(m: &BinaryMask) -> Vec<u32> {
    let (mut counts, mut prev, mut run) = (Vec::new(), false, 0u32);
    for x in 0..m.width {
        for y in 0..m.height {
            let v = m.data[y * m.width + x] != 0;
            if v != prev {
                counts.push(run);
                run = 0;
                prev = v;
            }
            run += 1;
        }
    }
    counts.push(run);
    counts
}

/// `from_mask` (which reads only the set pixels' box) equals the pixel-by-pixel encoding, and
/// `to_mask` inverts it, on random masks: empty, full, blobs touching each border, one pixel,
/// and degenerate 1-wide / 1-tall frames.
#[test]
fn rle_encoding_reads_only_the_box_and_round_trips() {
    let mut state = 0x9e3779b97f4a7c15u64;
    let mut next = move |n: usize| {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state % n as u64) as usize
    };
    for trial in 0..400 {
        let (w, h) = (1 + next(23), 1 + next(19));
        let mut m = BinaryMask::new(w, h);
        match trial % 5 {
            0 => {}
            1 => m.data.fill(1),
            2 => m.set(next(w), next(h), true),
            _ => {
                let (x0, y0) = (next(w), next(h));
                let (x1, y1) = (x0 + next(w - x0), y0 + next(h - y0));
                for y in y0..=y1 {
                    for x in x0..=x1 {
                        m.data[y * w + x] = (next(3) != 0) as u8 * (1 + next(200) as u8);
                    }
                }
            }
        }
        let rle = Rle::from_mask(&m);
        assert_eq!(rle.counts, reference_rle(&m), "trial {trial}: {w}x{h}");
        let back = rle.to_mask().unwrap();
        let set: Vec<u8> = m.data.iter().map(|&v| (v != 0) as u8).collect();
        assert_eq!(back.data, set, "trial {trial}: {w}x{h} round trip");
    }
}
