//! `TubeNet`: a small U-Net-like encoder-decoder with a stride-4 output.
//!
//! Encoder (input `C x H x W`, `H` and `W` multiples of [`TubeNet::ALIGN`]): a 5x5 stride-2
//! stem, then 3x3 convolutions with strides 2,1,2,1,2,1,2,1 (widths `w, 2w, 2w, 4w, 4w, 8w,
//! 8w, 8w, 8w` for base width `w`), ReLU after each. Decoder: nearest-neighbour upsampling by 2
//! and concatenation with the encoder feature of the same stride (1/16, 1/8, 1/4), a 3x3 conv
//! + ReLU after each; the last 3x3 conv gives the [`HEADS`] channels at stride 4:
//!
//! | channel | meaning | target |
//! |---|---|---|
//! | 0 | foreground logit | fraction of tube pixels in the 4x4 cell |
//! | 1 | centre heatmap logit | `exp(-d²/2σ²)` around each tube's axis centre |
//! | 2, 3 | `cos 2θ`, `sin 2θ` of the axis angle θ (image frame, x right, y down) | on tube cells |
//! | 4 | half-length of the tube / [`LENGTH_SCALE`] pixels | on tube cells |
//!
//! The receptive field (~190 px) spans the tubes' length in 1024x1024 crops.

use candle_core::{Module, Result, Tensor};
use candle_nn::{Conv2d, Conv2dConfig, VarBuilder};
use serde::{Deserialize, Serialize};

/// Number of output channels (see the module doc).
pub const HEADS: usize = 5;
/// Output stride in pixels.
pub const STRIDE: usize = 4;
/// Half-lengths are regressed in units of this many pixels.
pub const LENGTH_SCALE: f32 = 64.0;

/// Architecture hyper-parameters, stored in the weights file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct NetConfig {
    /// Input channels (1 for gray-box, 3 for RGB).
    pub in_channels: usize,
    /// Base width `w` (channels of the stem).
    pub width: usize,
}

impl Default for NetConfig {
    fn default() -> Self {
        NetConfig { in_channels: 1, width: 8 }
    }
}

fn conv(vb: VarBuilder, cin: usize, cout: usize, k: usize, stride: usize) -> Result<Conv2d> {
    let cfg = Conv2dConfig { padding: k / 2, stride, dilation: 1, groups: 1, cudnn_fwd_algo: None };
    candle_nn::conv2d(cin, cout, k, cfg, vb)
}

/// The network (weights live in the `VarMap` behind the `VarBuilder` it was built from).
pub struct TubeNet {
    enc: Vec<Conv2d>,
    dec: Vec<Conv2d>,
    head: Conv2d,
}

impl TubeNet {
    /// Input sizes must be multiples of this (five stride-2 stages).
    pub const ALIGN: usize = 32;

    /// Builds the layers; parameter names are `enc{i}`, `dec{i}`, `head` (`.weight`, `.bias`).
    pub fn new(vb: VarBuilder, cfg: &NetConfig) -> Result<Self> {
        let w = cfg.width;
        let spec = [(cfg.in_channels, w, 5, 2), (w, 2 * w, 3, 2), (2 * w, 2 * w, 3, 1), (2 * w, 4 * w, 3, 2), (4 * w, 4 * w, 3, 1),
            (4 * w, 8 * w, 3, 2), (8 * w, 8 * w, 3, 1), (8 * w, 8 * w, 3, 2), (8 * w, 8 * w, 3, 1)];
        let enc = spec.iter().enumerate().map(|(i, &(a, b, k, s))| conv(vb.pp(format!("enc{i}")), a, b, k, s)).collect::<Result<Vec<_>>>()?;
        let dec = vec![
            conv(vb.pp("dec0"), 16 * w, 4 * w, 3, 1)?,
            conv(vb.pp("dec1"), 8 * w, 2 * w, 3, 1)?,
        ];
        let head = conv(vb.pp("head"), 4 * w, HEADS, 3, 1)?;
        Ok(TubeNet { enc, dec, head })
    }

    /// `x`: `(B, C, H, W)` normalized input; returns `(B, HEADS, H/4, W/4)` raw outputs.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let mut feats = Vec::with_capacity(self.enc.len());
        let mut h = x.clone();
        for c in &self.enc {
            h = c.forward(&h)?.relu()?;
            feats.push(h.clone());
        }
        // Skips: feats[2] at 1/4, feats[4] at 1/8, feats[6] at 1/16.
        let up_cat = |h: &Tensor, skip: &Tensor| -> Result<Tensor> {
            let (_, _, sh, sw) = skip.dims4()?;
            Tensor::cat(&[&h.upsample_nearest2d(sh, sw)?, skip], 1)
        };
        let h = self.dec[0].forward(&up_cat(&h, &feats[6])?)?.relu()?;
        let h = self.dec[1].forward(&up_cat(&h, &feats[4])?)?.relu()?;
        self.head.forward(&up_cat(&h, &feats[2])?)
    }
}
