//! `LearnedModel`: the network, its weights and its metadata; safetensors save/load.
//!
//! File format: a safetensors file whose metadata holds `format = "tubeloc-learned"`,
//! `format_version` ([`FORMAT_VERSION`]), `meta` (JSON [`ModelMeta`]) and `checksum`: CRC-32 of
//! every tensor's name, shape (u64 LE) and little-endian f32 data, in name order. A file whose
//! format, version, checksum, tensor names or shapes do not match is refused with a
//! [`LearnedError::BadModel`] naming the file.

use super::error::LearnedError;
use super::net::{NetConfig, NetOutput, TubeNet, HEADS, STRIDE};
use super::preprocess::Preprocess;
use candle_core::{DType, Device, Tensor};
use candle_nn::{VarBuilder, VarMap};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::path::Path;

/// Version of the weights file layout; bump when names, shapes or meaning change.
pub const FORMAT_VERSION: u32 = 2;
const FORMAT_NAME: &str = "tubeloc-learned";

/// What a weights file says about the model besides its tensors.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelMeta {
    /// Architecture.
    pub net: NetConfig,
    /// Input preprocessing the model was trained with.
    pub preprocess: Preprocess,
    /// Optimizer steps done so far.
    pub steps: u64,
    /// Free-form provenance (the command that trained it, validation AP50...).
    #[serde(default)]
    pub notes: String,
}

/// A network with its weights (CPU, f32).
pub struct LearnedModel {
    pub(crate) varmap: VarMap,
    pub(crate) net: TubeNet,
    /// Metadata saved with the weights.
    pub meta: ModelMeta,
}

impl LearnedModel {
    /// A freshly initialized model: He-normal weights `N(0, 2/fan_in)` drawn from
    /// `ChaCha8Rng::seed_from_u64(seed)` in parameter-name order, zero biases, and head biases
    /// set to the foreground/centre priors (`-2.2`, i.e. p ≈ 0.1).
    pub fn new(preprocess: Preprocess, width: usize, seed: u64) -> Result<Self, LearnedError> {
        Self::with_fine_mask(preprocess, width, false, seed)
    }

    /// As [`LearnedModel::new`], with or without the full-resolution mask branch
    /// ([`NetConfig::fine_mask`]; its output layer starts with small weights, so its
    /// correction starts near 0).
    pub fn with_fine_mask(preprocess: Preprocess, width: usize, fine_mask: bool, seed: u64) -> Result<Self, LearnedError> {
        let net_cfg = NetConfig { in_channels: preprocess.channels(), width, fine_mask };
        let varmap = VarMap::new();
        let vb = VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu);
        let net = TubeNet::new(vb, &net_cfg)?;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        for (name, var) in sorted_vars(&varmap) {
            let shape = var.dims().to_vec();
            let n: usize = shape.iter().product();
            let vals: Vec<f32> = if name.ends_with(".weight") {
                let fan_in: usize = shape[1..].iter().product();
                let normal = Normal::new(0.0f32, (2.0 / fan_in as f32).sqrt()).map_err(|e| LearnedError::Invalid(e.to_string()))?;
                let gain = if name.starts_with("head") || name.starts_with("fine_out") { 0.1 } else { 1.0 };
                (0..n).map(|_| gain * normal.sample(&mut rng)).collect()
            } else if name == "head.bias" {
                (0..n).map(|i| if i < 2 { -2.2 } else { 0.0 }).collect()
            } else {
                vec![0.0; n]
            };
            var.set(&Tensor::from_vec(vals, shape, &Device::Cpu)?)?;
        }
        Ok(LearnedModel { varmap, net, meta: ModelMeta { net: net_cfg, preprocess, steps: 0, notes: String::new() } })
    }

    /// Raw network outputs for a batch `(B, C, H, W)` (H, W multiples of 32): the stride-4
    /// heads `(B, 5, H/4, W/4)` and, with the fine branch, `(B, 1, H, W)` mask logits.
    pub fn forward(&self, x: &Tensor) -> Result<NetOutput, LearnedError> {
        Ok(self.net.forward(x)?)
    }

    /// Trains only the fine mask branch from now on (see [`TubeNet::set_freeze_coarse`]).
    pub fn freeze_coarse(&mut self, on: bool) {
        self.net.set_freeze_coarse(on);
    }

    /// Copies every tensor of `other` whose name and shape this model also has (a warm start,
    /// e.g. adding the fine mask branch to a trained model); returns how many were copied.
    pub fn init_from(&mut self, other: &LearnedModel) -> Result<usize, LearnedError> {
        let theirs: HashMap<String, candle_core::Var> = sorted_vars(&other.varmap).into_iter().collect();
        let mut copied = 0;
        for (name, var) in sorted_vars(&self.varmap) {
            if let Some(t) = theirs.get(&name).filter(|t| t.dims() == var.dims()) {
                var.set(t.as_tensor())?;
                copied += 1;
            }
        }
        Ok(copied)
    }

    /// Warm start of an RGB model from a gray-box one: every tensor of the same name and shape
    /// is copied, and the input convolutions (`enc0a`, and `fine_in` when both have the fine
    /// branch), which see the `4C` space-to-depth channels `(2 dy + dx) C + c`, get the gray
    /// model's weight for cell `(dy, dx)` times the luma coefficient of channel `c`
    /// (0.299, 0.587, 0.114). Both normalize as `(v - 0.5) / 0.25` and the coefficients sum to
    /// 1, so the new model computes what the old one did on the luma of the image, without its
    /// box filter. Returns how many tensors were set.
    pub fn init_from_gray(&mut self, gray: &LearnedModel) -> Result<usize, LearnedError> {
        if self.meta.preprocess != Preprocess::Rgb || !matches!(gray.meta.preprocess, Preprocess::GrayBox { .. }) || self.meta.net.width != gray.meta.net.width {
            return Err(LearnedError::Invalid(format!(
                "init from gray: needs an rgb model and a gray-box model of the same width (have {:?} width {}, {:?} width {})",
                self.meta.preprocess, self.meta.net.width, gray.meta.preprocess, gray.meta.net.width
            )));
        }
        let mut set = self.init_from(gray)?;
        let theirs: HashMap<String, candle_core::Var> = sorted_vars(&gray.varmap).into_iter().collect();
        const LUMA: [f32; 3] = [0.299, 0.587, 0.114];
        for (name, var) in sorted_vars(&self.varmap) {
            if !(name == "enc0a.weight" || name == "fine_in.weight") {
                continue;
            }
            let Some(g) = theirs.get(&name) else { continue };
            let (cout, cin_g, kh, kw) = g.as_tensor().dims4()?;
            if var.dims() != [cout, 3 * cin_g, kh, kw] {
                continue;
            }
            let gv: Vec<f32> = g.as_tensor().flatten_all()?.to_vec1()?;
            let mut out = vec![0f32; cout * 3 * cin_g * kh * kw];
            let k2 = kh * kw;
            for o in 0..cout {
                for q in 0..cin_g {
                    for (c, l) in LUMA.iter().enumerate() {
                        for t in 0..k2 {
                            out[((o * 3 * cin_g) + q * 3 + c) * k2 + t] = l * gv[(o * cin_g + q) * k2 + t];
                        }
                    }
                }
            }
            var.set(&candle_core::Tensor::from_vec(out, (cout, 3 * cin_g, kh, kw), &candle_core::Device::Cpu)?)?;
            set += 1;
        }
        Ok(set)
    }

    /// Runs the network on one preprocessed image (`channels * width * height` values,
    /// channel-major) of any size: pads to a multiple of 32 with zeros (the normalized mean
    /// gray) and crops the outputs back (see [`Prediction`]).
    pub fn predict(&self, input: &[f32], width: usize, height: usize) -> Result<Prediction, LearnedError> {
        let c = self.meta.net.in_channels;
        if width == 0 || height == 0 || input.len() != c * width * height {
            return Err(LearnedError::Invalid(format!("input has {} values, expected {c} x {width} x {height}", input.len())));
        }
        match band_rows(width, height) {
            Some(rows) => self.predict_in_bands(input, width, height, rows, BAND_HALO_PX),
            None => self.predict_whole(input, width, height),
        }
    }

    /// [`LearnedModel::predict`] over horizontal bands of `rows` rows (a multiple of
    /// [`TubeNet::ALIGN`]), each run with `halo` rows of context above and below (a multiple of
    /// `ALIGN`); the band's own rows of every output are kept. Peak memory follows the band.
    fn predict_in_bands(&self, input: &[f32], width: usize, height: usize, rows: usize, halo: usize) -> Result<Prediction, LearnedError> {
        let c = self.meta.net.in_channels;
        let (cw, chh) = (width.div_ceil(STRIDE), height.div_ceil(STRIDE));
        let mut planes = vec![0f32; HEADS * cw * chh];
        let mut fine: Option<Vec<f32>> = None;
        let n = width * height;
        for y0 in (0..height).step_by(rows) {
            let y1 = (y0 + rows).min(height);
            let (a, b) = (y0.saturating_sub(halo), (y1 + halo).min(height));
            let bh = b - a;
            let mut band = Vec::with_capacity(c * width * bh);
            for ch in 0..c {
                band.extend_from_slice(&input[ch * n + a * width..ch * n + b * width]);
            }
            let p = self.predict_whole(&band, width, bh)?;
            // Rows y0..y1 of the image are rows y0-a.. of the band; a, y0 are multiples of 4.
            let (r0, r1) = ((y0 - a) / STRIDE, (y1 - a).div_ceil(STRIDE));
            for k in 0..HEADS {
                for r in r0..r1 {
                    let dst = y0 / STRIDE + (r - r0);
                    planes[k * cw * chh + dst * cw..][..cw].copy_from_slice(&p.planes[k * cw * p.out_h + r * cw..][..cw]);
                }
            }
            if let Some(f) = p.fine {
                let all = fine.get_or_insert_with(|| vec![0f32; n]);
                all[y0 * width..y1 * width].copy_from_slice(&f[(y0 - a) * width..(y1 - a) * width]);
            }
        }
        Ok(Prediction { planes, out_w: cw, out_h: chh, width, height, fine })
    }

    /// The network on the whole image at once.
    fn predict_whole(&self, input: &[f32], width: usize, height: usize) -> Result<Prediction, LearnedError> {
        let c = self.meta.net.in_channels;
        let a = TubeNet::ALIGN;
        let (pw, ph) = (width.div_ceil(a) * a, height.div_ceil(a) * a);
        let mut padded = vec![0f32; c * pw * ph];
        for ch in 0..c {
            for y in 0..height {
                let src = &input[ch * width * height + y * width..][..width];
                padded[ch * pw * ph + y * pw..][..width].copy_from_slice(src);
            }
        }
        let x = Tensor::from_vec(padded, (1, c, ph, pw), &Device::Cpu)?;
        let out = self.net.forward(&x)?;
        let (ow, oh) = (pw / STRIDE, ph / STRIDE);
        let all: Vec<f32> = out.coarse.flatten_all()?.to_vec1()?;
        let (cw, chh) = (width.div_ceil(STRIDE), height.div_ceil(STRIDE));
        let mut planes = vec![0f32; HEADS * cw * chh];
        for k in 0..HEADS {
            for y in 0..chh {
                planes[k * cw * chh + y * cw..][..cw].copy_from_slice(&all[k * ow * oh + y * ow..][..cw]);
            }
        }
        let fine = match out.fine {
            Some(f) => {
                let f: Vec<f32> = f.flatten_all()?.to_vec1()?;
                let mut m = vec![0f32; width * height];
                for y in 0..height {
                    m[y * width..][..width].copy_from_slice(&f[y * pw..][..width]);
                }
                Some(m)
            }
            None => None,
        };
        Ok(Prediction { planes, out_w: cw, out_h: chh, width, height, fine })
    }

    /// [`LearnedModel::predict`] averaged over the image and its left-right mirror
    /// (test-time augmentation; the network was trained with mirrored crops). The mirror's
    /// outputs are mirrored back (cell `i` of a `4 n` px wide image ↔ cell `n - 1 - i`) and the
    /// axis channel `sin 2θ` changes sign (θ → π − θ); logits, `cos 2θ` and lengths are averaged
    /// as they are. An image whose width is not a multiple of 4 is mirrored with zero columns
    /// added on its right up to the next multiple (the network pads with zeros there anyway), so
    /// that cells stay aligned; the fine mask is cut back to the image's width.
    pub fn predict_mirror_averaged(&self, input: &[f32], width: usize, height: usize) -> Result<Prediction, LearnedError> {
        let mut p = self.predict(input, width, height)?;
        let pw = width.div_ceil(STRIDE) * STRIDE;
        let mirrored: Vec<f32> = input.chunks_exact(width).flat_map(|row| std::iter::repeat_n(0.0, pw - width).chain(row.iter().rev().copied())).collect();
        let q = self.predict(&mirrored, pw, height)?;
        let (cw, n) = (p.out_w, p.out_w * p.out_h);
        for k in 0..HEADS {
            let sign = if k == 3 { -1.0 } else { 1.0 };
            for y in 0..p.out_h {
                let (a, b) = (&mut p.planes[k * n + y * cw..][..cw], &q.planes[k * n + y * cw..][..cw]);
                for (i, v) in a.iter_mut().enumerate() {
                    *v = 0.5 * (*v + sign * b[cw - 1 - i]);
                }
            }
        }
        if let (Some(f), Some(g)) = (p.fine.as_mut(), q.fine.as_ref()) {
            for (a, b) in f.chunks_exact_mut(width).zip(g.chunks_exact(pw)) {
                for (i, v) in a.iter_mut().enumerate() {
                    *v = 0.5 * (*v + b[pw - 1 - i]);
                }
            }
        }
        Ok(p)
    }

    /// Serializes weights and metadata (see the module doc) to bytes.
    pub fn to_bytes(&self) -> Result<Vec<u8>, LearnedError> {
        let mut blobs = Vec::new();
        for (name, var) in sorted_vars(&self.varmap) {
            let v: Vec<f32> = var.as_tensor().flatten_all()?.to_vec1()?;
            let bytes: Vec<u8> = v.iter().flat_map(|x| x.to_le_bytes()).collect();
            blobs.push((name, var.dims().to_vec(), bytes));
        }
        let checksum = checksum(blobs.iter().map(|(n, s, b)| (n.as_str(), s.as_slice(), b.as_slice())));
        let mut md = HashMap::new();
        md.insert("format".to_string(), FORMAT_NAME.to_string());
        md.insert("format_version".to_string(), FORMAT_VERSION.to_string());
        md.insert("meta".to_string(), serde_json::to_string(&self.meta).map_err(|e| LearnedError::Invalid(e.to_string()))?);
        md.insert("checksum".to_string(), format!("{checksum:08x}"));
        let views =
            blobs.iter().map(|(n, s, b)| Ok((n.clone(), safetensors::tensor::TensorView::new(safetensors::Dtype::F32, s.clone(), b)?))).collect::<Result<Vec<_>, safetensors::SafeTensorError>>().map_err(|e| LearnedError::Invalid(e.to_string()))?;
        let bytes = safetensors::serialize(views, Some(md)).map_err(|e| LearnedError::Invalid(e.to_string()))?;
        sort_header_metadata(bytes)
    }

    /// Writes the model atomically to `path`.
    pub fn save(&self, path: &Path) -> Result<(), LearnedError> {
        let bytes = self.to_bytes()?;
        tubeloc_core::files::write_atomic(path, &bytes).map_err(|e| LearnedError::Io { path: path.to_path_buf(), error: std::io::Error::other(e.to_string()) })
    }

    /// Reads a model file; see [`LearnedModel::from_bytes`].
    pub fn load(path: &Path) -> Result<Self, LearnedError> {
        let bytes = std::fs::read(path).map_err(|e| LearnedError::Io { path: path.to_path_buf(), error: e })?;
        Self::from_bytes(&bytes, path)
    }

    /// Parses a model from bytes; `origin` names the file in errors. Checks the format name,
    /// version, checksum and that every tensor the architecture needs is present with the
    /// right shape (and no others).
    pub fn from_bytes(bytes: &[u8], origin: &Path) -> Result<Self, LearnedError> {
        let bad = |m: String| LearnedError::bad_model(origin, m);
        let st = safetensors::SafeTensors::deserialize(bytes).map_err(|e| bad(format!("not a safetensors file ({e})")))?;
        let (_, header) = safetensors::SafeTensors::read_metadata(bytes).map_err(|e| bad(e.to_string()))?;
        let md = header.metadata().clone().unwrap_or_default();
        if md.get("format").map(String::as_str) != Some(FORMAT_NAME) {
            return Err(bad(format!("not a tubeloc learned model (format {:?})", md.get("format"))));
        }
        let ver = md.get("format_version").cloned().unwrap_or_default();
        if ver != FORMAT_VERSION.to_string() {
            return Err(bad(format!("format version {ver} but this program reads version {FORMAT_VERSION}")));
        }
        let meta: ModelMeta = serde_json::from_str(md.get("meta").map(String::as_str).unwrap_or("")).map_err(|e| bad(format!("bad meta: {e}")))?;
        let mut tensors = st.tensors();
        tensors.sort_by(|a, b| a.0.cmp(&b.0));
        for (n, t) in &tensors {
            if t.dtype() != safetensors::Dtype::F32 {
                return Err(bad(format!("tensor {n} has dtype {:?}, expected F32", t.dtype())));
            }
        }
        let sum = checksum(tensors.iter().map(|(n, t)| (n.as_str(), t.shape(), t.data())));
        let want = md.get("checksum").cloned().unwrap_or_default();
        if format!("{sum:08x}") != want {
            return Err(bad(format!("checksum mismatch (file says {want}, data gives {sum:08x}): the file is corrupt")));
        }
        if meta.net.in_channels != meta.preprocess.channels() || meta.net.width == 0 || meta.net.width > 256 {
            return Err(bad(format!("inconsistent architecture {:?} for preprocessing {:?}", meta.net, meta.preprocess)));
        }
        let mut model = LearnedModel::with_fine_mask(meta.preprocess, meta.net.width, meta.net.fine_mask, 0)?;
        model.meta = meta;
        let vars = sorted_vars(&model.varmap);
        if vars.len() != tensors.len() {
            return Err(bad(format!("{} tensors, the architecture has {}", tensors.len(), vars.len())));
        }
        for ((name, var), (tn, t)) in vars.iter().zip(&tensors) {
            if name != tn || var.dims() != t.shape() {
                return Err(bad(format!("tensor {tn} {:?} does not match the architecture's {name} {:?}", t.shape(), var.dims())));
            }
            let vals: Vec<f32> = t.data().chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
            var.set(&Tensor::from_vec(vals, t.shape(), &Device::Cpu)?)?;
        }
        Ok(model)
    }
}

/// Working images with more pixels than this run through the network in horizontal bands
/// ([`LearnedModel::predict`]; the network needs about 120 bytes of activations per pixel).
/// Smaller images (a 1024² Navcam frame at its working scale included) run whole.
pub const WHOLE_MAX_PIXELS: usize = 3_000_000;
/// Most pixels of one band with its halo: ~180 MB of activations however large the image.
pub const BAND_PIXELS: usize = 1_500_000;
/// Rows of context above and below each band, pixels (a multiple of [`TubeNet::ALIGN`]).
/// The network's receptive field is larger, so banded logits differ from whole-image ones
/// by context far from the tube; the network was trained on crops smaller than a band.
pub const BAND_HALO_PX: usize = 96;

/// Band height for an image of `width x height` working pixels: `None` when the image runs
/// whole (at most [`WHOLE_MAX_PIXELS`]); otherwise the largest multiple of [`TubeNet::ALIGN`]
/// whose band with its halo holds at most [`BAND_PIXELS`] (at least one `ALIGN`).
pub fn band_rows(width: usize, height: usize) -> Option<usize> {
    if width * height <= WHOLE_MAX_PIXELS {
        return None;
    }
    let a = TubeNet::ALIGN;
    let rows = (BAND_PIXELS / width).saturating_sub(2 * BAND_HALO_PX) / a * a;
    Some(rows.max(a))
}

/// Network outputs for one image, cropped to it.
#[derive(Clone, Debug)]
pub struct Prediction {
    /// The `HEADS` stride-4 planes, `planes[c * out_w * out_h + y * out_w + x]` (cell `(x, y)`
    /// covers pixels `4x..4x+3` x `4y..4y+3`).
    pub planes: Vec<f32>,
    /// Plane width, `ceil(width / 4)`.
    pub out_w: usize,
    /// Plane height, `ceil(height / 4)`.
    pub out_h: usize,
    /// Image width, pixels.
    pub width: usize,
    /// Image height, pixels.
    pub height: usize,
    /// Full-resolution mask logits (`width * height`, row-major) when the model has the fine
    /// branch.
    pub fine: Option<Vec<f32>>,
}

pub(crate) fn sorted_vars(varmap: &VarMap) -> Vec<(String, candle_core::Var)> {
    let data = varmap.data().lock().expect("varmap lock poisoned");
    let mut v: Vec<(String, candle_core::Var)> = data.iter().map(|(k, v)| (k.clone(), v.clone())).collect();
    v.sort_by(|a, b| a.0.cmp(&b.0));
    v
}

fn checksum<'a>(items: impl Iterator<Item = (&'a str, &'a [usize], &'a [u8])>) -> u32 {
    let mut h = crc32fast::Hasher::new();
    for (name, shape, data) in items {
        h.update(name.as_bytes());
        for &d in shape {
            h.update(&(d as u64).to_le_bytes());
        }
        h.update(data);
    }
    h.finalize()
}

/// Rewrites a safetensors file's header with its `__metadata__` entries in key order.
/// `safetensors::serialize` takes the metadata as a `HashMap` and writes it in the map's
/// (randomly seeded) iteration order, so the same model gave different bytes from run to run.
/// Tensor entries and data are kept as they are (data offsets are relative to the data start).
pub(crate) fn sort_header_metadata(bytes: Vec<u8>) -> Result<Vec<u8>, LearnedError> {
    let bad = |m: &str| LearnedError::Invalid(format!("serialized safetensors header: {m}"));
    let n = u64::from_le_bytes(bytes.get(..8).ok_or_else(|| bad("too short"))?.try_into().map_err(|_| bad("too short"))?) as usize;
    let header = bytes.get(8..8 + n).ok_or_else(|| bad("length out of range"))?;
    let mut value: serde_json::Map<String, serde_json::Value> = serde_json::from_slice(header).map_err(|e| bad(&e.to_string()))?;
    if let Some(serde_json::Value::Object(md)) = value.get_mut("__metadata__") {
        let mut entries: Vec<(String, serde_json::Value)> = std::mem::take(md).into_iter().collect();
        entries.sort_by(|a, b| a.0.cmp(&b.0));
        md.extend(entries);
    }
    // `__metadata__` first, then the tensors in the order safetensors wrote them.
    let mut ordered = serde_json::Map::new();
    if let Some(md) = value.remove("__metadata__") {
        ordered.insert("__metadata__".to_string(), md);
    }
    ordered.extend(value);
    let mut text = serde_json::to_vec(&ordered).map_err(|e| bad(&e.to_string()))?;
    text.resize(text.len().next_multiple_of(8), b' ');
    let mut out = Vec::with_capacity(8 + text.len() + bytes.len() - 8 - n);
    out.extend((text.len() as u64).to_le_bytes());
    out.extend(text);
    out.extend(&bytes[8 + n..]);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// With a halo wider than the network's receptive field, the bands stitch into the
    /// whole-image prediction (coarse planes and fine logits).
    #[test]
    fn bands_with_a_wide_halo_stitch_into_the_whole_prediction() {
        let model = LearnedModel::with_fine_mask(Preprocess::GrayNorm, 8, true, 7).unwrap();
        let (w, h) = (32, 1024);
        let input: Vec<f32> = (0..w * h).map(|i| (((i * 7919) % 613) as f32 / 613.0 - 0.5) * 2.0).collect();
        let whole = model.predict_whole(&input, w, h).unwrap();
        let banded = model.predict_in_bands(&input, w, h, 64, 256).unwrap();
        assert_eq!((banded.out_w, banded.out_h), (whole.out_w, whole.out_h));
        let max_diff = |a: &[f32], b: &[f32]| a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0f32, f32::max);
        assert!(max_diff(&banded.planes, &whole.planes) < 1e-4, "coarse planes differ by {}", max_diff(&banded.planes, &whole.planes));
        let (bf, wf) = (banded.fine.unwrap(), whole.fine.unwrap());
        assert!(max_diff(&bf, &wf) < 1e-4, "fine logits differ by {}", max_diff(&bf, &wf));
        // A halo of one ALIGN changes the logits only by the missing far context.
        let narrow = model.predict_in_bands(&input, w, h, 32, 32).unwrap();
        assert_eq!(narrow.planes.len(), whole.planes.len());
    }

    #[test]
    fn band_rows_keep_small_images_whole_and_bound_the_band() {
        assert_eq!(band_rows(1024, 1024), None);
        assert_eq!(band_rows(1600, 1600), None);
        let rows = band_rows(2977, 1985).unwrap();
        assert_eq!(rows % TubeNet::ALIGN, 0);
        assert!((rows + 2 * BAND_HALO_PX) * 2977 <= BAND_PIXELS, "{rows}");
        assert_eq!(band_rows(200_000, 100), Some(TubeNet::ALIGN));
    }
}
