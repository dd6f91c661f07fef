//! Quick probe of candle CPU convolution speed for the layer shapes `TubeNet` could use
//! (median of 9 runs each, forward only, batch 1). Run:
//! `RAYON_NUM_THREADS=2 cargo run --release --manifest-path experiments/Cargo.toml --bin learned_conv_probe`.

use candle_core::{DType, Device, Module, Tensor};
use candle_nn::{Conv2dConfig, VarBuilder, VarMap};
use std::time::Instant;
use tubeloc_detect::learned::augment::{AugmentConfig, TrainImage};
use tubeloc_detect::learned::layers::Conv;
use tubeloc_detect::learned::{detect_rgb, DecodeConfig, LearnedModel, Preprocess, TrainConfig, Trainer};

fn median_ms(mut f: impl FnMut()) -> f64 {
    f();
    let mut t: Vec<f64> = (0..9)
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[4]
}

fn main() -> candle_core::Result<()> {
    let dev = Device::Cpu;
    let vm = VarMap::new();
    let vb = VarBuilder::from_varmap(&vm, DType::F32, &dev);
    // (name, cin, cout, k, stride, groups, input side)
    let cases = [
        ("3x3 s2 1->8 @512", 1, 8, 3, 2, 1, 512),
        ("3x3 s1 8->8 @256", 8, 8, 3, 1, 1, 256),
        ("3x3 s1 16->16 @256", 16, 16, 3, 1, 1, 256),
        ("1x1 s1 16->16 @256", 16, 16, 1, 1, 1, 256),
        ("dw3x3 s1 16 @256", 16, 16, 3, 1, 16, 256),
        ("3x3 s2 8->16 @256", 8, 16, 3, 2, 1, 256),
        ("3x3 s1 16->16 @128", 16, 16, 3, 1, 1, 128),
        ("3x3 s1 32->32 @64", 32, 32, 3, 1, 1, 64),
        ("3x3 s1 64->64 @32", 64, 64, 3, 1, 1, 32),
        ("3x3 s1 24->8 @256", 24, 8, 3, 1, 1, 256),
        ("5x5 s2 1->8 @1024 (old stem)", 1, 8, 5, 2, 1, 1024),
    ];
    let only_net = std::env::var("ONLY_NET").is_ok();
    for (i, &(name, cin, cout, k, stride, groups, side)) in cases.iter().enumerate().filter(|_| !only_net) {
        let cfg = Conv2dConfig { padding: k / 2, stride, dilation: 1, groups, cudnn_fwd_algo: None };
        let conv = candle_nn::conv2d(cin, cout, k, cfg, vb.pp(format!("c{i}")))?;
        let x = Tensor::randn(0f32, 1.0, (1, cin, side, side), &dev)?;
        let ms = median_ms(|| {
            conv.forward(&x).unwrap().relu().unwrap();
        });
        let out = side / stride;
        let gmac = (out * out * cout * cin / groups * k * k) as f64 / 1e9;
        println!("{name:32} {ms:8.2} ms  {:6.2} GFLOP/s", 2.0 * gmac / (ms / 1e3));
    }
    let x = Tensor::randn(0f32, 1.0, (1, 16, 128, 128), &dev)?;
    let s = Tensor::randn(0f32, 1.0, (1, 8, 256, 256), &dev)?;
    let ms = median_ms(|| {
        Tensor::cat(&[&x.upsample_nearest2d(256, 256).unwrap(), &s], 1).unwrap();
    });
    println!("{:32} {ms:8.2} ms", "upsample 16@128->256 + cat 8");
    // Matrix-product convolution (learned::layers::Conv) on the same shapes.
    for (i, &(name, cin, cout, k, stride, groups, side)) in cases.iter().enumerate() {
        if stride != 1 || groups != 1 || only_net {
            continue;
        }
        let conv = Conv::new(vb.pp(format!("m{i}")), cin, cout, k)?;
        let x = Tensor::randn(0f32, 1.0, (1, side, side, cin), &dev)?;
        let ms = median_ms(|| {
            conv.forward(&x).unwrap().relu().unwrap();
        });
        println!("matmul-conv {name:20} {ms:8.2} ms  {:6.2} GFLOP/s", 2.0 * (side * side * cout * cin * k * k) as f64 / 1e9 / (ms / 1e3));
    }
    // Whole network: 1024x1024 forward and training steps.
    let width: usize = std::env::var("PROBE_WIDTH").ok().and_then(|v| v.parse().ok()).unwrap_or(12);
    let pre = Preprocess::default();
    let model = LearnedModel::new(pre, width, 1).map_err(|e| candle_core::Error::Msg(e.to_string()))?;
    let x = Tensor::randn(0f32, 1.0, (1, 1, 1024, 1024), &dev)?;
    let ms = median_ms(|| {
        model.forward(&x).unwrap();
    });
    println!("TubeNet w{width} forward 1x1x1024x1024   {ms:8.2} ms");
    let mut rgb = vec![90u8; 1024 * 1024 * 3];
    let mut mask = vec![0u8; 1024 * 1024];
    for y in 500..514 {
        for x in 300..500 {
            rgb[(y * 1024 + x) * 3..][..3].copy_from_slice(&[200, 200, 200]);
            mask[y * 1024 + x] = 1;
        }
    }
    let ms = median_ms(|| {
        detect_rgb(&model, &rgb, 1024, 1024, &DecodeConfig::default()).unwrap();
    });
    println!("detect_rgb 1024x1024 (w{width})        {ms:8.2} ms");
    let images = vec![TrainImage::new(1024, 1024, pre.apply(&rgb, 1024, 1024), &[mask])];
    for (batch, crop) in [(8usize, 384usize), (8, 512)] {
        let cfg = TrainConfig { batch, augment: AugmentConfig { crop, ..Default::default() }, ..Default::default() };
        let mut trainer = Trainer::new(LearnedModel::new(pre, width, 1).unwrap(), cfg).unwrap();
        let ms = median_ms(|| {
            trainer.step(&images).unwrap();
        });
        println!("train step {batch}x{crop}x{crop} (w{width})      {ms:8.2} ms");
    }
    Ok(())
}
