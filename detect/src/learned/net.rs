//! `TubeNet`: a thin U-Net-like encoder-decoder whose heads sit at stride 4 of the image.
//!
//! Input `(B, C, H, W)` at image resolution (`H`, `W` multiples of [`TubeNet::ALIGN`]).
//! 1. 2x2 mean pooling (the network sees the image at half resolution), then a 2x2
//!    space-to-depth (`4C` channels at stride 4).
//! 2. Encoder, four levels at strides 4, 8, 16, 32 with widths `w, 2w, 4w, 4w` (base width
//!    `w`): two 3x3 convolutions + ReLU per level, 2x2 max pooling between levels.
//! 3. Decoder: nearest 2x upsampling of the coarser level *added* to the encoder feature of the
//!    same stride, a 3x3 convolution + ReLU (widths `2w`, `w`, `w` at strides 16, 8, 4).
//! 4. A 1x1 head gives the [`HEADS`] channels at stride 4:
//!
//! | channel | meaning | target |
//! |---|---|---|
//! | 0 | foreground logit (the shared mask logits) | fraction of tube pixels in the 4x4 cell |
//! | 1 | centre heatmap logit | `exp(-d²/2σ²)` around each tube's axis centre |
//! | 2, 3 | `cos 2θ`, `sin 2θ` of the axis angle θ (image frame, x right, y down) | on tube cells |
//! | 4 | half-length of the tube / [`LENGTH_SCALE`] pixels | on tube cells |
//!
//! 5. Optional full-resolution mask branch ([`NetConfig::fine_mask`]): the input image at full
//!    resolution, 2x2 space-to-depth (`4C` channels at stride 2) and a 3x3 convolution to
//!    [`FINE_WIDTH`] channels, plus the stride-4 decoder feature through a 1x1 convolution to
//!    the same width, upsampled 2x; ReLU, a 1x1 convolution + ReLU and a 1x1 convolution to 4
//!    channels, which depth-to-space turns into one value per image pixel (channel `2 dy + dx`
//!    is pixel `(2x + dx, 2y + dy)`). That value is a *correction*: the mask logit is
//!    `fine = correction + bilinear↑4(o₀)`, with the foreground logit `o₀` of the stride-4 head
//!    bilinearly upsampled (cell `i` centred on pixel `4i + 1.5`) and detached from the graph.
//!    Tubes are 10-20 pixels wide, so stride-4 mask logits leave their outlines 1-3 pixels
//!    off; the branch only has to learn where the image's edges move them.
//!
//! The receptive field is about 300 image pixels, the length of a tube in the 1024x1024
//! crops. All convolutions are [`super::layers::Conv`] (one matrix product each), which is
//! several times faster than candle's CPU `conv2d` for these thin layers.

use super::layers::{max_pool2, upsample2, Conv};
use candle_core::{Module, Result, Tensor};
use candle_nn::VarBuilder;
use serde::{Deserialize, Serialize};

/// Number of output channels (see the module doc).
pub const HEADS: usize = 5;
/// Output stride in image pixels.
pub const STRIDE: usize = 4;
/// Channels of the full-resolution mask branch.
pub const FINE_WIDTH: usize = 16;
/// Half-lengths are regressed in units of this many pixels.
pub const LENGTH_SCALE: f32 = 64.0;

/// Architecture hyper-parameters, stored in the weights file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct NetConfig {
    /// Input channels (1 for gray-box, 3 for RGB).
    pub in_channels: usize,
    /// Base width `w` (channels at stride 4).
    pub width: usize,
    /// Whether the full-resolution mask branch exists (absent in files written before it).
    #[serde(default)]
    pub fine_mask: bool,
}

impl Default for NetConfig {
    fn default() -> Self {
        NetConfig { in_channels: 1, width: 12, fine_mask: false }
    }
}

/// The network (weights live in the `VarMap` behind the `VarBuilder` it was built from).
pub struct TubeNet {
    enc: Vec<(Conv, Conv)>,
    dec: Vec<Conv>,
    head: Conv,
    fine: Option<[Conv; 4]>,
    /// Train only the fine branch: the stride-4 outputs and features are detached, so no
    /// gradient reaches the other layers (see [`TubeNet::set_freeze_coarse`]).
    freeze_coarse: bool,
}

/// Raw outputs of [`TubeNet::forward`].
pub struct NetOutput {
    /// `(B, HEADS, H/4, W/4)`: the stride-4 heads of the module doc.
    pub coarse: Tensor,
    /// `(B, 1, H, W)`: full-resolution mask logits, with [`NetConfig::fine_mask`].
    pub fine: Option<Tensor>,
}

/// Bilinear upsampling of a stride-4 plane (`ow x oh`, cell `i` centred on pixel `4i + 1.5`)
/// to `width x height` pixels, clamped at the borders:
/// `v(x) = (1 - t) p[⌊u⌋] + t p[⌊u⌋ + 1]` with `u = (x - 1.5) / 4`, `t = u - ⌊u⌋`, per axis.
pub fn upsample4_bilinear(plane: &[f32], ow: usize, oh: usize, width: usize, height: usize) -> Vec<f32> {
    let mut out = Vec::with_capacity(width * height);
    for y in 0..height {
        out.extend((0..width).map(|x| bilinear4_at(plane, ow, oh, x, y)));
    }
    out
}

/// One pixel `(x, y)` of [`upsample4_bilinear`] (for reading a few pixels without the plane).
#[inline]
pub fn bilinear4_at(plane: &[f32], ow: usize, oh: usize, x: usize, y: usize) -> f32 {
    let taps = |x: usize, n: usize| {
        let u = ((x as f32 - 1.5) / STRIDE as f32).clamp(0.0, (n - 1) as f32);
        let i = u.floor() as usize;
        (i, (i + 1).min(n - 1), u - i as f32)
    };
    let ((u0, u1, fu), (v0, v1, fv)) = (taps(x, ow), taps(y, oh));
    let (r0, r1) = (&plane[v0 * ow..][..ow], &plane[v1 * ow..][..ow]);
    (r0[u0] * (1.0 - fu) + r0[u1] * fu) * (1.0 - fv) + (r1[u0] * (1.0 - fu) + r1[u1] * fu) * fv
}

/// `(B, C, H, W)` → channels-last `(B, H/2, W/2, 4C)`, channel `(2 dy + dx) C + c`.
fn space_to_depth(x: &Tensor) -> Result<Tensor> {
    let (b, c, h, w) = x.dims4()?;
    x.reshape((b, c, h / 2, 2, w / 2, 2))?.permute((0, 2, 4, 3, 5, 1))?.reshape((b, h / 2, w / 2, 4 * c))
}

impl TubeNet {
    /// Input sizes must be multiples of this (2x pooling, space-to-depth, three poolings).
    pub const ALIGN: usize = 32;

    /// Builds the layers; parameter names are `enc{level}{a|b}`, `dec{i}`, `head` (`.weight`,
    /// `.bias`), `dec0` at stride 16 and `dec2` at stride 4; the fine branch's are `fine_in`,
    /// `fine_proj`, `fine_mid`, `fine_out`.
    pub fn new(vb: VarBuilder, cfg: &NetConfig) -> Result<Self> {
        let w = cfg.width;
        let widths = [w, 2 * w, 4 * w, 4 * w];
        let mut enc = Vec::new();
        let mut cin = 4 * cfg.in_channels;
        for (l, &c) in widths.iter().enumerate() {
            enc.push((Conv::new(vb.pp(format!("enc{l}a")), cin, c, 3)?, Conv::new(vb.pp(format!("enc{l}b")), c, c, 3)?));
            cin = c;
        }
        let dec = vec![Conv::new(vb.pp("dec0"), 4 * w, 2 * w, 3)?, Conv::new(vb.pp("dec1"), 2 * w, w, 3)?, Conv::new(vb.pp("dec2"), w, w, 3)?];
        let head = Conv::new(vb.pp("head"), w, HEADS, 1)?;
        let fine = if cfg.fine_mask {
            let f = FINE_WIDTH;
            Some([Conv::new(vb.pp("fine_in"), 4 * cfg.in_channels, f, 3)?, Conv::new(vb.pp("fine_proj"), w, f, 1)?, Conv::new(vb.pp("fine_mid"), f, f, 1)?, Conv::new(vb.pp("fine_out"), f, 4, 1)?])
        } else {
            None
        };
        Ok(TubeNet { enc, dec, head, fine, freeze_coarse: false })
    }

    /// With `on`, gradients of the loss reach only the fine mask branch (the stride-4 layers
    /// keep their weights: warm-starting the branch on a trained model).
    pub fn set_freeze_coarse(&mut self, on: bool) {
        self.freeze_coarse = on;
    }

    /// `x`: `(B, C, H, W)` normalized input at image resolution; returns the raw outputs.
    pub fn forward(&self, x: &Tensor) -> Result<NetOutput> {
        let (b, _, h, w) = x.dims4()?;
        // Half resolution, then space-to-depth into channels-last features (B, H/4, W/4, 4C).
        let mut f = space_to_depth(&x.avg_pool2d(2)?)?;
        let mut feats = Vec::with_capacity(self.enc.len());
        for (l, (ca, cb)) in self.enc.iter().enumerate() {
            if l > 0 {
                f = max_pool2(&f)?;
            }
            f = cb.forward(&ca.forward(&f)?.relu()?)?.relu()?;
            feats.push(f.clone());
        }
        for (d, skip) in self.dec.iter().zip(feats[..3].iter().rev()) {
            f = d.forward(&(upsample2(&f)? + skip)?)?.relu()?;
        }
        let mut coarse = self.head.forward(&f)?.permute((0, 3, 1, 2))?.contiguous()?;
        if self.freeze_coarse {
            (f, coarse) = (f.detach(), coarse.detach());
        }
        let fine = match &self.fine {
            Some([cin, cproj, cmid, cout]) => {
                let g = (cin.forward(&space_to_depth(x)?)? + upsample2(&cproj.forward(&f)?)?)?.relu()?;
                let g = cout.forward(&cmid.forward(&g)?.relu()?)?;
                // Depth-to-space: (B, H/2, W/2, 2, 2) -> (B, H/2, 2, W/2, 2) -> (B, 1, H, W).
                let correction = g.reshape((b, h / 2, w / 2, 2, 2))?.permute((0, 1, 3, 2, 4))?.reshape((b, 1, h, w))?;
                let fg: Vec<f32> = coarse.narrow(1, 0, 1)?.flatten_all()?.to_vec1()?;
                let (ow, oh) = (w / STRIDE, h / STRIDE);
                let base: Vec<f32> = fg.chunks_exact(ow * oh).flat_map(|p| upsample4_bilinear(p, ow, oh, w, h)).collect();
                Some((correction + Tensor::from_vec(base, (b, 1, h, w), x.device())?)?)
            }
            None => None,
        };
        Ok(NetOutput { coarse, fine })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bilinear_upsampling_reproduces_a_ramp_and_clamps_at_the_border() {
        // p[i] = i along x, 10 j along y: interior pixels read (x - 1.5) / 4 + 10 (y - 1.5) / 4.
        let (ow, oh) = (5, 3);
        let plane: Vec<f32> = (0..oh).flat_map(|j| (0..ow).map(move |i| i as f32 + 10.0 * j as f32)).collect();
        let up = upsample4_bilinear(&plane, ow, oh, 20, 12);
        for y in 0..12 {
            for x in 0..20 {
                let u = ((x as f32 - 1.5) / 4.0).clamp(0.0, 4.0);
                let v = ((y as f32 - 1.5) / 4.0).clamp(0.0, 2.0);
                assert!((up[y * 20 + x] - (u + 10.0 * v)).abs() < 1e-5, "({x}, {y}): {}", up[y * 20 + x]);
            }
        }
    }
}
