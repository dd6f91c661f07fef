//! Learned segmenter: training lowers the loss, save/load round trip, refusal of bad files,
//! decoding of hand-made network outputs.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::collections::HashMap;
use tubeloc_detect::learned::augment::{AugmentConfig, TrainImage};
use tubeloc_detect::learned::net::{upsample4_bilinear, HEADS, LENGTH_SCALE};
use tubeloc_detect::learned::train::make_batch;
use tubeloc_detect::learned::{decode, DecodeConfig, LearnedModel, Prediction, Preprocess, TrainConfig, Trainer};

/// A textured image with bright bars ("tubes") at random places and angles, plus their masks.
fn bar_image(size: usize, bars: usize, seed: u64) -> (Vec<u8>, Vec<Vec<u8>>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut rgb: Vec<u8> = (0..size * size)
        .flat_map(|_| {
            let v = rng.random_range(70u8..130);
            [v, v, v]
        })
        .collect();
    let mut masks = Vec::new();
    for _ in 0..bars {
        let (cx, cy) = (rng.random_range(0.25..0.75) * size as f64, rng.random_range(0.25..0.75) * size as f64);
        let th: f64 = rng.random_range(0.0..std::f64::consts::PI);
        let (len, wid) = (rng.random_range(40.0..70.0), rng.random_range(5.0..8.0));
        let mut m = vec![0u8; size * size];
        for y in 0..size {
            for x in 0..size {
                let (dx, dy) = (x as f64 - cx, y as f64 - cy);
                let (a, b) = (dx * th.cos() + dy * th.sin(), -dx * th.sin() + dy * th.cos());
                if a.abs() < len / 2.0 && b.abs() < wid / 2.0 {
                    m[y * size + x] = 1;
                    rgb[(y * size + x) * 3..][..3].copy_from_slice(&[215, 215, 215]);
                }
            }
        }
        masks.push(m);
    }
    (rgb, masks)
}

fn tiny_set(pre: Preprocess) -> Vec<TrainImage> {
    (0..3)
        .map(|i| {
            let (rgb, masks) = bar_image(192, 2, 100 + i);
            TrainImage::new(192, 192, pre.apply(&rgb, 192, 192), &masks)
        })
        .collect()
}

#[test]
fn training_a_few_steps_lowers_the_loss() {
    let pre = Preprocess::default();
    let images = tiny_set(pre);
    let aug = AugmentConfig { crop: 128, ..Default::default() };
    let cfg = TrainConfig { batch: 4, lr: 3e-3, warmup: 5, total_steps: 60, seed: 7, augment: aug, ..Default::default() };
    let model = LearnedModel::new(pre, 8, 3).unwrap();
    let mut trainer = Trainer::new(model, cfg).unwrap();
    let held = make_batch(&images, &aug, 8, 12345, 0).unwrap();
    let before = trainer.eval_loss(&held).unwrap();
    for _ in 0..60 {
        let l = trainer.step(&images).unwrap();
        assert!(l.is_finite());
    }
    let after = trainer.eval_loss(&held).unwrap();
    assert_eq!(trainer.model.meta.steps, 60);
    assert!(after < 0.7 * before, "loss {before} -> {after}");
}

#[test]
fn same_seed_gives_same_weights_and_save_load_gives_identical_outputs() {
    let pre = Preprocess::GrayBox { radius: 2 };
    let a = LearnedModel::new(pre, 4, 11).unwrap();
    let b = LearnedModel::new(pre, 4, 11).unwrap();
    let c = LearnedModel::new(pre, 4, 12).unwrap();
    // Same seed -> same tensor bytes (the safetensors header's metadata key order may vary).
    let tensors = |m: &LearnedModel| {
        let bytes = m.to_bytes().unwrap();
        let st = safetensors::SafeTensors::deserialize(&bytes).unwrap();
        let mut v: Vec<(String, Vec<u8>)> = st.tensors().into_iter().map(|(n, t)| (n, t.data().to_vec())).collect();
        v.sort();
        v
    };
    assert_eq!(tensors(&a), tensors(&b));
    assert_ne!(tensors(&a), tensors(&c));

    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.safetensors");
    a.save(&path).unwrap();
    let loaded = LearnedModel::load(&path).unwrap();
    assert_eq!(loaded.meta, a.meta);
    let (rgb, _) = bar_image(100, 1, 5);
    let input = pre.apply(&rgb, 100, 100);
    let p1 = a.predict(&input, 100, 100).unwrap();
    let p2 = loaded.predict(&input, 100, 100).unwrap();
    assert_eq!((p1.out_w, p1.out_h), (25, 25));
    assert_eq!((p1.out_w, p1.out_h), (p2.out_w, p2.out_h));
    assert!(p1.planes.iter().zip(&p2.planes).all(|(x, y)| x.to_bits() == y.to_bits()));
}

#[test]
fn corrupt_or_mismatched_weights_are_refused_with_a_clear_error() {
    let model = LearnedModel::new(Preprocess::default(), 4, 1).unwrap();
    let bytes = model.to_bytes().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, b: &[u8]| {
        let p = dir.path().join(name);
        std::fs::write(&p, b).unwrap();
        p
    };
    let err = |p: &std::path::Path| LearnedModel::load(p).err().expect("must be refused").to_string();

    // A flipped bit in the tensor data.
    let mut flipped = bytes.clone();
    let n = flipped.len();
    flipped[n - 10] ^= 0x40;
    let e = err(&write("flipped.safetensors", &flipped));
    assert!(e.contains("flipped.safetensors") && e.contains("checksum mismatch"), "{e}");

    // Truncated.
    let e = err(&write("short.safetensors", &bytes[..bytes.len() / 2]));
    assert!(e.contains("short.safetensors") && e.contains("not a safetensors file"), "{e}");

    // Another format version / another program's file.
    let st = safetensors::SafeTensors::deserialize(&bytes).unwrap();
    let (_, header) = safetensors::SafeTensors::read_metadata(&bytes).unwrap();
    let md: HashMap<String, String> = header.metadata().clone().unwrap();
    let rewrite = |md: HashMap<String, String>| safetensors::serialize(st.tensors(), Some(md)).unwrap();
    let mut v2 = md.clone();
    v2.insert("format_version".into(), "999".into());
    let e = err(&write("v999.safetensors", &rewrite(v2)));
    assert!(e.contains("v999.safetensors") && e.contains("format version 999"), "{e}");
    let mut other = md.clone();
    other.remove("format");
    let e = err(&write("other.safetensors", &rewrite(other)));
    assert!(e.contains("not a tubeloc learned model"), "{e}");

    // Width changed in the metadata: tensors no longer match the architecture.
    let mut wide = md.clone();
    wide.insert("meta".into(), md["meta"].replace("\"width\":4", "\"width\":8"));
    let e = err(&write("wide.safetensors", &rewrite(wide)));
    assert!(e.contains("does not match the architecture"), "{e}");

    // Missing file.
    let e = err(&dir.path().join("absent.safetensors"));
    assert!(e.contains("absent.safetensors"), "{e}");
}

/// Hand-made outputs: two parallel bars in one connected blob plus a separate diagonal one.
#[test]
fn decoding_splits_touching_tubes_and_recovers_axes() {
    let (ow, oh) = (64, 64);
    let n = ow * oh;
    let mut out = vec![-6.0f32; HEADS * n];
    let mut put = |cx: f32, cy: f32, th: f32, half: f32, wid: f32| {
        for y in 0..oh {
            for x in 0..ow {
                let (dx, dy) = (x as f32 - cx, y as f32 - cy);
                let (a, b) = (dx * th.cos() + dy * th.sin(), -dx * th.sin() + dy * th.cos());
                let c = y * ow + x;
                if a.abs() <= half && b.abs() <= wid {
                    out[c] = 4.0;
                    out[2 * n + c] = (2.0 * th).cos();
                    out[3 * n + c] = (2.0 * th).sin();
                    out[4 * n + c] = half * 4.0 / LENGTH_SCALE;
                }
                let g = (-(dx * dx + dy * dy) / 4.5).exp();
                let h = &mut out[n + c];
                let p = (1.0 / (1.0 + (-*h).exp())).max(0.95 * g);
                *h = (p / (1.0 - p)).ln();
            }
        }
    };
    // Two horizontal bars stacked so their masks touch (rows 20..22 and 23..25).
    put(20.0, 21.0, 0.0, 10.0, 1.0);
    put(20.0, 24.0, 0.0, 10.0, 1.0);
    // A diagonal bar far away.
    put(45.0, 45.0, std::f32::consts::FRAC_PI_4, 8.0, 1.0);
    let pred = Prediction { planes: out, out_w: ow, out_h: oh, width: 256, height: 256, fine: None };
    let inst = decode(&pred, &DecodeConfig::default());
    assert_eq!(inst.len(), 3, "{:?}", inst.iter().map(|i| i.axis).collect::<Vec<_>>());
    let diag = inst.iter().find(|i| i.axis.centre_px[0] > 150.0).unwrap();
    // Cell 45 -> pixel 45 * 4 + 1.5 = 181.5.
    assert!((diag.axis.centre_px[0] - 181.5).abs() < 1.0 && (diag.axis.centre_px[1] - 181.5).abs() < 1.0, "{:?}", diag.axis);
    let s = std::f64::consts::FRAC_1_SQRT_2;
    assert!((diag.axis.direction_px[0] - s).abs() < 0.02 && (diag.axis.direction_px[1] - s).abs() < 0.02, "{:?}", diag.axis);
    assert!((diag.axis.length_px - 64.0).abs() < 2.0, "{:?}", diag.axis);
    for i in &inst {
        let area = i.mask.area();
        assert!(area > 100, "area {area}");
        assert!(i.score > 0.5 && i.score <= 1.0, "score {}", i.score);
    }
    // The two touching bars are separate instances with disjoint masks.
    let bars: Vec<_> = inst.iter().filter(|i| i.axis.centre_px[0] < 150.0).collect();
    assert_eq!(bars.len(), 2);
    let (m0, m1) = (bars[0].mask.to_mask().unwrap(), bars[1].mask.to_mask().unwrap());
    assert!(m0.data.iter().zip(&m1.data).all(|(a, b)| *a == 0 || *b == 0));
    let mut ys: Vec<f64> = bars.iter().map(|b| b.axis.centre_px[1]).collect();
    ys.sort_by(f64::total_cmp);
    // Rows 21 and 24 -> pixels 85.5 and 97.5.
    assert!((ys[0] - 85.5).abs() < 2.0 && (ys[1] - 97.5).abs() < 2.0, "{ys:?}");
}

#[test]
fn resumed_training_continues_exactly() {
    let pre = Preprocess::default();
    let images = tiny_set(pre);
    let cfg = TrainConfig { batch: 2, lr: 3e-3, warmup: 2, total_steps: 6, seed: 5, augment: AugmentConfig { crop: 64, ..Default::default() }, ..Default::default() };
    let weights = |t: &Trainer| {
        let st = t.model.to_bytes().unwrap();
        let st = safetensors::SafeTensors::deserialize(&st).unwrap();
        let mut v: Vec<(String, Vec<u8>)> = st.tensors().into_iter().map(|(n, t)| (n, t.data().to_vec())).collect();
        v.sort();
        v
    };
    let mut straight = Trainer::new(LearnedModel::new(pre, 4, 9).unwrap(), cfg).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let ckpt = dir.path().join("run.ckpt");
    for k in 0..6 {
        straight.step(&images).unwrap();
        if k == 2 {
            straight.save_checkpoint(&ckpt).unwrap();
        }
    }
    let (mut resumed, had_opt) = Trainer::resume(&ckpt, cfg).unwrap();
    assert!(had_opt);
    assert_eq!(resumed.model.meta.steps, 3);
    for _ in 3..6 {
        resumed.step(&images).unwrap();
    }
    assert_eq!(weights(&resumed), weights(&straight));
    // Without the optimizer state the continuation differs (fresh moments).
    std::fs::remove_file(tubeloc_detect::learned::train::opt_path(&ckpt)).unwrap();
    let (mut fresh, had_opt) = Trainer::resume(&ckpt, cfg).unwrap();
    assert!(!had_opt);
    for _ in 3..6 {
        fresh.step(&images).unwrap();
    }
    assert_ne!(weights(&fresh), weights(&straight));
}

#[test]
fn fine_mask_branch_warm_starts_trains_and_round_trips() {
    let pre = Preprocess::default();
    let plain = LearnedModel::new(pre, 8, 3).unwrap();
    let mut fine = LearnedModel::with_fine_mask(pre, 8, true, 22).unwrap();
    // Every tensor of the plain model is copied; the stride-4 heads then agree bit for bit.
    let n_plain = safetensors::SafeTensors::deserialize(&plain.to_bytes().unwrap()).unwrap().tensors().len();
    assert_eq!(fine.init_from(&plain).unwrap(), n_plain);
    let (rgb, _) = bar_image(96, 1, 4);
    let input = pre.apply(&rgb, 96, 96);
    let (pp, pf) = (plain.predict(&input, 96, 96).unwrap(), fine.predict(&input, 96, 96).unwrap());
    assert!(pp.fine.is_none());
    assert!(pp.planes.iter().zip(&pf.planes).all(|(a, b)| a.to_bits() == b.to_bits()));
    assert_eq!(pf.fine.as_ref().map(Vec::len), Some(96 * 96));

    // Training lowers the loss, which now includes the full-resolution mask term.
    let images = tiny_set(pre);
    let aug = AugmentConfig { crop: 128, ..Default::default() };
    let cfg = TrainConfig { batch: 4, lr: 3e-3, warmup: 5, total_steps: 60, seed: 7, augment: aug, ..Default::default() };
    let mut trainer = Trainer::new(fine, cfg).unwrap();
    let held = make_batch(&images, &aug, 8, 12345, 0).unwrap();
    let before = trainer.eval_loss(&held).unwrap();
    for _ in 0..60 {
        assert!(trainer.step(&images).unwrap().is_finite());
    }
    let after = trainer.eval_loss(&held).unwrap();
    assert!(after < 0.7 * before, "loss {before} -> {after}");

    // Save and load keep the branch and give identical full-resolution logits.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("fine.safetensors");
    trainer.model.save(&path).unwrap();
    let loaded = LearnedModel::load(&path).unwrap();
    assert!(loaded.meta.net.fine_mask);
    let (a, b) = (trainer.model.predict(&input, 96, 96).unwrap(), loaded.predict(&input, 96, 96).unwrap());
    assert!(a.fine.unwrap().iter().zip(&b.fine.unwrap()).all(|(x, y)| x.to_bits() == y.to_bits()));
}

#[test]
fn freezing_the_coarse_layers_trains_only_the_fine_branch() {
    let pre = Preprocess::default();
    let mut model = LearnedModel::with_fine_mask(pre, 4, true, 5).unwrap();
    model.freeze_coarse(true);
    let tensors = |m: &LearnedModel| {
        let st = m.to_bytes().unwrap();
        let st = safetensors::SafeTensors::deserialize(&st).unwrap();
        st.tensors().into_iter().map(|(n, t)| (n, t.data().to_vec())).collect::<HashMap<String, Vec<u8>>>()
    };
    let before = tensors(&model);
    let cfg = TrainConfig { batch: 2, lr: 3e-3, warmup: 1, total_steps: 3, seed: 2, augment: AugmentConfig { crop: 64, ..Default::default() }, ..Default::default() };
    let mut t = Trainer::new(model, cfg).unwrap();
    let images = tiny_set(pre);
    for _ in 0..3 {
        t.step(&images).unwrap();
    }
    let after = tensors(&t.model);
    for (name, v) in &before {
        if name.starts_with("fine_") {
            assert_ne!(&after[name], v, "{name} did not change");
        } else {
            assert_eq!(&after[name], v, "{name} changed although frozen");
        }
    }
}

#[test]
fn decoding_with_fine_logits_follows_them_to_the_pixel() {
    // One horizontal tube: foreground cells in row 30, columns 20..=39 (pixels 80..159 x
    // 120..123), its centre peak at cell (30, 30); the full-resolution logits mark pixel rows
    // 121..=126 (half of them in the background cell row 31) and columns 82..=157.
    let (ow, oh) = (64, 64);
    let n = ow * oh;
    let mut planes = vec![-4.0f32; HEADS * n];
    for x in 20..40 {
        let c = 30 * ow + x;
        planes[c] = 4.0;
        planes[2 * n + c] = 1.0;
        planes[3 * n + c] = 0.0;
        planes[4 * n + c] = 40.0 / LENGTH_SCALE;
    }
    planes[n + 30 * ow + 30] = 3.0;
    let mut fine = vec![-5.0f32; 256 * 256];
    for y in 121..=126 {
        for x in 82..=157 {
            fine[y * 256 + x] = 5.0;
        }
    }
    let pred = Prediction { planes, out_w: ow, out_h: oh, width: 256, height: 256, fine: Some(fine.clone()) };
    let inst = decode(&pred, &DecodeConfig::default());
    assert_eq!(inst.len(), 1);
    let m = &inst[0].mask.to_mask().unwrap().data;
    assert!(m.iter().zip(&fine).all(|(&a, &f)| (a != 0) == (f > 0.0)), "mask differs from the fine logits");
    assert_eq!(inst[0].bbox, [82.0, 121.0, 76.0, 6.0]);
    assert!((inst[0].axis.width_px - 6.0).abs() < 1e-9, "{:?}", inst[0].axis);
}

#[test]
fn fine_mask_branch_learns_pixel_outlines_that_stride_4_logits_miss() {
    // Bars 5-8 px wide: bilinear stride-4 logits round their outlines; the full-resolution
    // branch, trained briefly on the same images, must place them closer to the truth.
    let pre = Preprocess::default();
    let s = 256;
    let images: Vec<TrainImage> = (0..8)
        .map(|i| {
            let (rgb, masks) = bar_image(s, 4, 200 + i);
            TrainImage::new(s, s, pre.apply(&rgb, s, s), &masks)
        })
        .collect();
    let aug = AugmentConfig { crop: 128, ..Default::default() };
    let cfg = TrainConfig { batch: 4, lr: 3e-3, warmup: 20, total_steps: 300, seed: 1, augment: aug, ..Default::default() };
    let mut t = Trainer::new(LearnedModel::with_fine_mask(pre, 8, true, 1).unwrap(), cfg).unwrap();
    for _ in 0..300 {
        t.step(&images).unwrap();
    }
    let (mut fine_iu, mut coarse_iu) = ([0usize; 2], [0usize; 2]);
    for i in 0..4 {
        let (rgb, masks) = bar_image(s, 4, 300 + i);
        let p = t.model.predict(&pre.apply(&rgb, s, s), s, s).unwrap();
        let fine = p.fine.unwrap();
        let coarse = upsample4_bilinear(&p.planes[..p.out_w * p.out_h], p.out_w, p.out_h, s, s);
        for q in 0..s * s {
            let gt = masks.iter().any(|m| m[q] != 0);
            for (iu, v) in [(&mut fine_iu, fine[q]), (&mut coarse_iu, coarse[q])] {
                iu[0] += (v > 0.0 && gt) as usize;
                iu[1] += (v > 0.0 || gt) as usize;
            }
        }
    }
    let iou = |iu: [usize; 2]| iu[0] as f64 / iu[1].max(1) as f64;
    let (f, c) = (iou(fine_iu), iou(coarse_iu));
    assert!(f > 0.8 && f > c + 0.05, "pixel IoU: fine {f:.3}, stride-4 {c:.3}");
}

#[test]
fn mirror_averaged_predictions_are_mirror_symmetric() {
    // Averaging over the image and its mirror makes the outputs equivariant: the prediction of
    // the mirrored image is the mirrored prediction (sin 2θ changes sign), even for an
    // untrained network that is not.
    let pre = Preprocess::GrayBox { radius: 1 };
    let m = LearnedModel::new(pre, 4, 3).unwrap();
    let (s, cw) = (96, 24);
    let (rgb, _) = bar_image(s, 2, 9);
    let input = pre.apply(&rgb, s, s);
    let mirrored: Vec<f32> = input.chunks_exact(s).flat_map(|r| r.iter().rev().copied()).collect();
    let (p, q) = (m.predict_mirror_averaged(&input, s, s).unwrap(), m.predict_mirror_averaged(&mirrored, s, s).unwrap());
    let (plain_p, plain_q) = (m.predict(&input, s, s).unwrap(), m.predict(&mirrored, s, s).unwrap());
    let n = cw * cw;
    let gap = |a: &Prediction, b: &Prediction| {
        let mut worst = 0f32;
        for k in 0..HEADS {
            let sign = if k == 3 { -1.0 } else { 1.0 };
            for y in 0..cw {
                for x in 0..cw {
                    worst = worst.max((a.planes[k * n + y * cw + x] - sign * b.planes[k * n + y * cw + cw - 1 - x]).abs());
                }
            }
        }
        worst
    };
    assert!(gap(&p, &q) < 1e-4, "mirror-averaged outputs differ by {}", gap(&p, &q));
    assert!(gap(&plain_p, &plain_q) > 1e-3, "the plain network is not symmetric by itself");
    // A width that is not a multiple of 4 is averaged too, as if zero-padded on the right to
    // the next multiple (where the network pads with zeros anyway): the same cells, and the
    // fine mask cut back to the image's width.
    let odd = pre.apply(&rgb[..(s * 95 * 3)].to_vec().chunks_exact(s * 3).flat_map(|r| r[..95 * 3].to_vec()).collect::<Vec<_>>(), 95, 95);
    let padded: Vec<f32> = odd.chunks_exact(95).flat_map(|r| r.iter().copied().chain(std::iter::once(0.0))).collect();
    let (a, b) = (m.predict_mirror_averaged(&odd, 95, 95).unwrap(), m.predict_mirror_averaged(&padded, 96, 95).unwrap());
    assert_eq!((a.out_w, a.planes.len()), (b.out_w, b.planes.len()));
    let worst = a.planes.iter().zip(&b.planes).map(|(x, y)| (x - y).abs()).fold(0f32, f32::max);
    assert!(worst < 1e-5, "odd width vs zero-padded: {worst}");
    assert!(a.planes != m.predict(&odd, 95, 95).unwrap().planes, "the odd width is mirror-averaged, not the plain prediction");
    if let (Some(fa), Some(fb)) = (&a.fine, &b.fine) {
        assert_eq!(fa.len(), 95 * 95);
        let worst = fa.chunks_exact(95).zip(fb.chunks_exact(96)).flat_map(|(x, y)| x.iter().zip(y).map(|(u, v)| (u - v).abs())).fold(0f32, f32::max);
        assert!(worst < 1e-5, "fine mask: {worst}");
    }
}

/// An RGB model warm-started from a gray model computes what the gray model computes on the
/// image's luma (here without a box filter, radius 0, so the two inputs agree exactly).
#[test]
fn rgb_model_started_from_a_gray_model_matches_it_on_the_luma() {
    let gray = LearnedModel::new(Preprocess::GrayBox { radius: 0 }, 4, 3).unwrap();
    let mut rgb = LearnedModel::new(Preprocess::Rgb, 4, 9).unwrap();
    let n = rgb.init_from_gray(&gray).unwrap();
    assert!(n >= 10, "only {n} tensors set");
    let (w, h) = (64usize, 64usize);
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let pixels: Vec<u8> = (0..w * h * 3).map(|_| rng.random_range(0..=255u8)).collect();
    let pg = gray.predict(&Preprocess::GrayBox { radius: 0 }.apply(&pixels, w, h), w, h).unwrap();
    let pr = rgb.predict(&Preprocess::Rgb.apply(&pixels, w, h), w, h).unwrap();
    let worst = pg.planes.iter().zip(&pr.planes).map(|(a, b)| (a - b).abs()).fold(0f32, f32::max);
    assert!(worst < 1e-3, "largest output difference {worst}");
    // A fresh RGB model differs: the equality above comes from the warm start.
    let fresh = LearnedModel::new(Preprocess::Rgb, 4, 9).unwrap();
    let pf = fresh.predict(&Preprocess::Rgb.apply(&pixels, w, h), w, h).unwrap();
    assert!(pg.planes.iter().zip(&pf.planes).any(|(a, b)| (a - b).abs() > 1e-2));
    // Mismatched kinds are refused.
    let mut g2 = LearnedModel::new(Preprocess::GrayBox { radius: 1 }, 4, 1).unwrap();
    assert!(g2.init_from_gray(&gray).is_err());
}
