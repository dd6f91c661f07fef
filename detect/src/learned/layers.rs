//! Convolution as one matrix product on channels-last (NHWC) features, for candle's CPU
//! backend.
//!
//! candle 0.11's CPU `conv2d` converts the input to NHWC serially and runs many small GEMMs,
//! and building the shifted copies with tensor ops (`narrow` + `cat`) is slower still; both
//! make thin networks slow on 2 cores (`experiments/learned/learned_conv_probe.rs`,
//! `experiments/learned/learned_matmul_probe.rs`). Features here are kept `(B, H, W, C)` and a `k x k`,
//! stride-1, zero-padded convolution is
//!
//! `y[b] = cols(x[b]) · Wᵀ + bias`, with `cols` the `(H·W, k·k·C_in)` im2col matrix (taps
//! `(dy, dx)` major, input channel minor; zero outside the image) built by the [`Im2Col`]
//! custom op (rayon over rows; its backward pass is the matching col2im sum) and `Wᵀ` the
//! `(k·k·C_in, C_out)` weight matrix. Tall-thin products like this one run 2-3x faster in
//! candle's GEMM than the `W · cols` orientation. Weights keep candle's `(C_out, C_in, k, k)`
//! layout and names (`weight`, `bias`).

use candle_core::{CpuStorage, CustomOp1, Layout, Module, Result, Shape, Tensor};
use candle_nn::VarBuilder;
use rayon::prelude::*;

/// The im2col custom op: `(B, H, W, C)` → `(B, H·W, k·k·C)`, zero padding `k / 2`.
#[derive(Clone, Copy, Debug)]
pub struct Im2Col {
    /// Kernel side (odd).
    pub k: usize,
}

/// Its adjoint: `(B, H·W, k·k·C)` → `(B, H, W, C)`, summing every tap back onto its pixel.
#[derive(Clone, Copy, Debug)]
struct Col2Im {
    k: usize,
    dims: (usize, usize, usize, usize),
}

fn contiguous<'a>(s: &'a CpuStorage, l: &Layout, op: &str) -> Result<&'a [f32]> {
    let (a, b) = l.contiguous_offsets().ok_or_else(|| candle_core::Error::Msg(format!("{op}: input must be contiguous")))?;
    Ok(&s.as_slice::<f32>()?[a..b])
}

impl CustomOp1 for Im2Col {
    fn name(&self) -> &'static str {
        "im2col-nhwc"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> Result<(CpuStorage, Shape)> {
        let (b, h, w, c) = l.shape().dims4()?;
        let x = contiguous(s, l, self.name())?;
        let (k, r) = (self.k, self.k as isize / 2);
        let row = w * k * k * c;
        let n = b * h * row;
        // Every element is written once below (a tap's channels, or zeros outside the image), so
        // the buffer is not cleared first: on a large frame clearing it cost as much as filling.
        let mut out: Vec<f32> = Vec::with_capacity(n);
        out.spare_capacity_mut()[..n].par_chunks_mut(row).enumerate().for_each(|(by, dst)| {
            let (bi, y) = (by / h, (by % h) as isize);
            let put = |d: &mut [std::mem::MaybeUninit<f32>], src: Option<&[f32]>| match src {
                Some(src) => d.iter_mut().zip(src).for_each(|(v, &s)| {
                    v.write(s);
                }),
                None => d.iter_mut().for_each(|v| {
                    v.write(0.0);
                }),
            };
            for xx in 0..w as isize {
                for dy in 0..k as isize {
                    let sy = y + dy - r;
                    // The k taps of one kernel row are k·C consecutive values of the input row.
                    let o = (xx as usize * k * k + (dy as usize) * k) * c;
                    let d = &mut dst[o..o + k * c];
                    if sy < 0 || sy >= h as isize {
                        put(d, None);
                        continue;
                    }
                    let line = (bi * h + sy as usize) * w;
                    if xx >= r && xx + r < w as isize {
                        let i = (line + (xx - r) as usize) * c;
                        put(d, Some(&x[i..i + k * c]));
                        continue;
                    }
                    for dx in 0..k as isize {
                        let sx = xx + dx - r;
                        let d = &mut d[dx as usize * c..][..c];
                        if sx < 0 || sx >= w as isize {
                            put(d, None);
                        } else {
                            let i = (line + sx as usize) * c;
                            put(d, Some(&x[i..i + c]));
                        }
                    }
                }
            }
        });
        // SAFETY: the loop above wrote all `n` elements: each row chunk covers `w` pixels x `k²`
        // taps x `c` channels, every one of them written either from `x` or as zero.
        unsafe { out.set_len(n) };
        Ok((CpuStorage::F32(out), Shape::from((b, h * w, k * k * c))))
    }

    fn bwd(&self, arg: &Tensor, _res: &Tensor, grad: &Tensor) -> Result<Option<Tensor>> {
        let dims = arg.dims4()?;
        Ok(Some(grad.contiguous()?.apply_op1_no_bwd(&Col2Im { k: self.k, dims })?))
    }
}

impl CustomOp1 for Col2Im {
    fn name(&self) -> &'static str {
        "col2im-nhwc"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> Result<(CpuStorage, Shape)> {
        let (b, h, w, c) = self.dims;
        let g = contiguous(s, l, self.name())?;
        let (k, r) = (self.k, self.k as isize / 2);
        let kkc = k * k * c;
        let mut out = vec![0f32; b * h * w * c];
        out.par_chunks_mut(w * c).enumerate().for_each(|(by, dst)| {
            let (bi, y) = (by / h, (by % h) as isize);
            for xx in 0..w as isize {
                let d = &mut dst[xx as usize * c..][..c];
                for dy in 0..k as isize {
                    // This pixel is tap (dy, dx) of output pixel (y - dy + r, x - dx + r).
                    let oy = y - dy + r;
                    for dx in 0..k as isize {
                        let ox = xx - dx + r;
                        if oy < 0 || ox < 0 || oy >= h as isize || ox >= w as isize {
                            continue;
                        }
                        let src = &g[((bi * h + oy as usize) * w + ox as usize) * kkc + (dy as usize * k + dx as usize) * c..][..c];
                        d.iter_mut().zip(src).for_each(|(a, v)| *a += v);
                    }
                }
            }
        });
        Ok((CpuStorage::F32(out), Shape::from((b, h, w, c))))
    }
}

/// A `k x k` stride-1 convolution with zero padding `k / 2` (odd `k`) and bias, on
/// `(B, H, W, C)` features.
pub struct Conv {
    weight: Tensor,
    bias: Tensor,
    k: usize,
}

impl Conv {
    /// Creates (or fetches from `vb`) `weight` `(cout, cin, k, k)` and `bias` `(cout)`.
    pub fn new(vb: VarBuilder, cin: usize, cout: usize, k: usize) -> Result<Self> {
        let weight = vb.get_with_hints((cout, cin, k, k), "weight", candle_nn::init::DEFAULT_KAIMING_NORMAL)?;
        let bias = vb.get_with_hints(cout, "bias", candle_nn::init::ZERO)?;
        Ok(Conv { weight, bias, k })
    }
}

impl Module for Conv {
    /// `x`: `(B, H, W, C_in)` → `(B, H, W, C_out)`.
    fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let (b, h, w, c) = x.dims4()?;
        let cout = self.weight.dim(0)?;
        let k = self.k;
        let wt = self.weight.permute((2, 3, 1, 0))?.reshape((k * k * c, cout))?;
        let cols = if k == 1 { x.reshape((b, h * w, c))? } else { x.contiguous()?.apply_op1(Im2Col { k })? };
        cols.broadcast_matmul(&wt)?.broadcast_add(&self.bias)?.reshape((b, h, w, cout))
    }
}

/// 2x2 max pooling of `(B, H, W, C)` (even `H`, `W`).
pub fn max_pool2(x: &Tensor) -> Result<Tensor> {
    let (b, h, w, c) = x.dims4()?;
    x.reshape((b, h / 2, 2, w / 2, 2, c))?.max(4)?.max(2)
}

/// Nearest-neighbour 2x upsampling of `(B, H, W, C)`.
pub fn upsample2(x: &Tensor) -> Result<Tensor> {
    let (b, h, w, c) = x.dims4()?;
    x.reshape((b, h, 1, w, 1, c))?.broadcast_as((b, h, 2, w, 2, c))?.contiguous()?.reshape((b, 2 * h, 2 * w, c))
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{DType, Device, Var};
    use candle_nn::VarMap;

    fn max_diff(a: &Tensor, b: &Tensor) -> f32 {
        (a - b).unwrap().abs().unwrap().flatten_all().unwrap().max(0).unwrap().to_scalar::<f32>().unwrap()
    }

    #[test]
    fn matches_candle_conv2d_forward_and_backward() {
        let vm = VarMap::new();
        let vb = VarBuilder::from_varmap(&vm, DType::F32, &Device::Cpu);
        for (i, k) in [1usize, 3, 5].into_iter().enumerate() {
            let conv = Conv::new(vb.pp(format!("c{i}")), 3, 4, k).unwrap();
            let bias = Tensor::new(&[0.5f32, -1.0, 2.0, 0.0], &Device::Cpu).unwrap();
            let conv = Conv { bias: bias.clone(), ..conv };
            let x = Var::from_tensor(&Tensor::randn(0f32, 1.0, (2, 3, 7, 9), &Device::Cpu).unwrap()).unwrap();
            let nhwc = x.permute((0, 2, 3, 1)).unwrap();
            let mine = conv.forward(&nhwc).unwrap().permute((0, 3, 1, 2)).unwrap();
            let reference = x.conv2d(&conv.weight, k / 2, 1, 1, 1).unwrap().broadcast_add(&bias.reshape((1, 4, 1, 1)).unwrap()).unwrap();
            assert_eq!(mine.dims(), reference.dims());
            let d = max_diff(&mine, &reference);
            assert!(d < 1e-4, "k={k}: forward max difference {d}");
            // Input gradient of a weighted sum.
            let wts = Tensor::randn(0f32, 1.0, mine.dims(), &Device::Cpu).unwrap();
            let g1 = (mine * &wts).unwrap().sum_all().unwrap().backward().unwrap();
            let g2 = (reference * &wts).unwrap().sum_all().unwrap().backward().unwrap();
            let d = max_diff(g1.get(&x).unwrap(), g2.get(&x).unwrap());
            assert!(d < 1e-3, "k={k}: input gradient max difference {d}");
        }
    }

    #[test]
    fn pooling_and_upsampling() {
        let x = Tensor::arange(0f32, 32.0, &Device::Cpu).unwrap().reshape((1, 4, 4, 2)).unwrap();
        let p = max_pool2(&x).unwrap();
        // Channel 0 of the top-left 2x2 block holds 0, 2, 8, 10.
        assert_eq!(p.dims(), &[1, 2, 2, 2]);
        assert_eq!(p.flatten_all().unwrap().to_vec1::<f32>().unwrap()[..2], [10.0, 11.0]);
        let u = upsample2(&p).unwrap();
        assert_eq!(u.dims(), &[1, 4, 4, 2]);
        let v = u.flatten_all().unwrap().to_vec1::<f32>().unwrap();
        assert_eq!((v[0], v[2], v[8], v[10]), (10.0, 10.0, 10.0, 10.0));
    }
}
