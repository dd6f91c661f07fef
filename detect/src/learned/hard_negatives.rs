//! Hard negatives for training: crops of tube-free real frames around the detector's own
//! confident detections there, at the frame's working scale ([`crate::scale`]).
//!
//! A frame without tubes is searched by a trained model; each detection whose calibrated
//! probability of being a tube reaches a floor marks clutter the model takes for a tube. The
//! frame is resampled by its working scale `s` (as inference resamples it) and a
//! `C x C` crop cut around each such detection, its centre `s · c` (`c` the detection's centre
//! in the frame's pixels) clamped so the crop lies inside. Trained on as images without
//! tubes, the crops put that clutter in front of the network far more often than random crops
//! of whole frames would (record 0076).

use super::decode::LearnedInstance;

/// The centres (frame pixels) of the `instances` whose probability `probability(score)`
/// reaches `min_probability`, in the instances' order, each kept only when it lies more than
/// `spacing_px` from every centre kept before it.
pub fn negative_centres(instances: &[LearnedInstance], probability: impl Fn(f64) -> f64, min_probability: f64, spacing_px: f64) -> Vec<[f64; 2]> {
    let mut kept: Vec<[f64; 2]> = Vec::new();
    for inst in instances {
        let c = inst.axis.centre_px;
        if probability(inst.score) >= min_probability && kept.iter().all(|k| (k[0] - c[0]).hypot(k[1] - c[1]) > spacing_px) {
            kept.push(c);
        }
    }
    kept
}

/// The `crop x crop` crops (smaller where the resampled frame is) of the interleaved RGB8
/// frame `rgb` (`width x height`) resampled by `scale` ([`crate::scale::scaled_size`],
/// [`crate::scale::resample_planes`]), one around each of `centres` (frame pixels), shifted
/// to lie inside the resampled frame.
pub fn working_scale_crops(rgb: &[u8], width: usize, height: usize, scale: f64, centres: &[[f64; 2]], crop: usize) -> Vec<image::RgbImage> {
    if centres.is_empty() {
        return Vec::new();
    }
    let (nw, nh) = crate::scale::scaled_size(width, height, scale);
    let planes: Vec<f32> = (0..3).flat_map(|c| rgb.iter().skip(c).step_by(3).map(|&v| v as f32)).collect();
    let big = crate::scale::resample_planes(&planes, 3, width, height, nw, nh);
    let (cw, ch) = (crop.min(nw), crop.min(nh));
    centres
        .iter()
        .map(|c| {
            let x0 = ((c[0] * scale) as i64 - cw as i64 / 2).clamp(0, (nw - cw) as i64) as usize;
            let y0 = ((c[1] * scale) as i64 - ch as i64 / 2).clamp(0, (nh - ch) as i64) as usize;
            image::RgbImage::from_fn(cw as u32, ch as u32, |i, j| {
                let at = |k: usize| big[k * nw * nh + (y0 + j as usize) * nw + x0 + i as usize].round().clamp(0.0, 255.0) as u8;
                image::Rgb([at(0), at(1), at(2)])
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use tubeloc_core::{AxisSeed, Rle};

    fn instance(score: f64, centre: [f64; 2]) -> LearnedInstance {
        LearnedInstance { score, mask: Rle { size: [1, 1], counts: vec![1] }, bbox: [0.0; 4], axis: AxisSeed { centre_px: centre, direction_px: [1.0, 0.0], length_px: 10.0, width_px: 2.0 } }
    }

    #[test]
    fn centres_above_the_floor_and_apart_are_kept_in_order() {
        let inst = [instance(0.9, [10.0, 10.0]), instance(0.8, [50.0, 10.0]), instance(0.1, [300.0, 300.0]), instance(0.7, [400.0, 10.0])];
        // probability = score; floor 0.5; 100 px apart: the second is too near the first.
        assert_eq!(negative_centres(&inst, |s| s, 0.5, 100.0), vec![[10.0, 10.0], [400.0, 10.0]]);
        assert!(negative_centres(&inst, |s| s, 0.95, 100.0).is_empty());
    }

    #[test]
    fn a_crop_is_the_resampled_frame_around_its_centre_clamped_inside() {
        // A 40x30 frame whose red channel is x and green channel y, enlarged 2x: a 16 px crop
        // around frame pixel (10, 12) starts at (12, 16) of the 80x60 resampled frame; one
        // around the corner (39, 29) is shifted inside, ending at the resampled frame's edge.
        let (w, h) = (40usize, 30usize);
        let rgb: Vec<u8> = (0..w * h).flat_map(|i| [(i % w) as u8 * 4, (i / w) as u8 * 4, 7]).collect();
        let crops = working_scale_crops(&rgb, w, h, 2.0, &[[10.0, 12.0], [39.0, 29.0]], 16);
        assert_eq!(crops.len(), 2);
        assert_eq!(crops[0].dimensions(), (16, 16));
        let big = crate::scale::resample_planes(&(0..3).flat_map(|c| rgb.iter().skip(c).step_by(3).map(|&v| v as f32)).collect::<Vec<_>>(), 3, w, h, 80, 60);
        for (crop, (x0, y0)) in crops.iter().zip([(12usize, 16usize), (64, 44)]) {
            for (i, j) in [(0u32, 0u32), (15, 15), (7, 3)] {
                let want = |k: usize| big[k * 80 * 60 + (y0 + j as usize) * 80 + x0 + i as usize].round() as u8;
                assert_eq!(crop.get_pixel(i, j).0, [want(0), want(1), want(2)], "crop at ({x0}, {y0}), pixel ({i}, {j})");
            }
        }
        assert!(working_scale_crops(&rgb, w, h, 2.0, &[], 16).is_empty());
        // A crop larger than the resampled frame is the whole frame.
        assert_eq!(working_scale_crops(&rgb, w, h, 0.5, &[[5.0, 5.0]], 64)[0].dimensions(), (20, 15));
    }
}
