//! Rover images as the PDS archives them: the `IMAGE` object of a PDS3 product (`.IMG` with
//! its label at the head, or a detached `.LBL` naming its data file), decoded to a grey or RGB
//! image of 8 or 16 bits per sample (12-bit data stay in a 16-bit container, and
//! [`crate::input::rgb8_of`] maps them by their real depth like any 16-bit image).
//!
//! Read from the label (PDS3 Standards Reference, chapter "Data Products"):
//! - `^IMAGE`: `n` (record `n` of this file, 1-based, `RECORD_BYTES` each), `n <BYTES>` (byte
//!   `n`, 1-based), or `("FILE", n)` / `"FILE"` for data in another file of the label's folder;
//! - `LINES`, `LINE_SAMPLES`, `BANDS` (1 grey, 3 RGB), `SAMPLE_BITS` (8 or 16), `SAMPLE_TYPE`
//!   (`[MSB_|LSB_|PC_|SUN_|MAC_|VAX_]UNSIGNED_INTEGER` or `..._INTEGER`: byte order and sign;
//!   negative samples are taken as 0), `BAND_STORAGE_TYPE` (`BAND_SEQUENTIAL`,
//!   `LINE_INTERLEAVED`, `SAMPLE_INTERLEAVED`), `LINE_PREFIX_BYTES`, `LINE_SUFFIX_BYTES`.
//!
//! Floating-point samples and other bit widths are refused, naming the keyword.

use image::DynamicImage;
use std::path::{Path, PathBuf};
use tubeloc_core::odl::{OdlGroup, OdlLabel};

/// The largest image read, in pixels (the pipeline's own limit).
pub const MAX_PIXELS: u64 = 100_000_000;

/// How an `IMAGE` object's samples lie in its file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ImageLayout {
    /// The file holding the samples: the label's own, or the one `^IMAGE` names.
    pub data_file: Option<String>,
    /// Byte offset of the first sample (after the first line's prefix) in the data file.
    pub offset: u64,
    /// `LINE_SAMPLES`, `LINES`.
    pub size: (u32, u32),
    /// `BANDS`: 1 or 3.
    pub bands: u32,
    /// Bytes per sample: 1 or 2.
    pub bytes: u32,
    /// Big-endian samples (`MSB_`, `SUN_`, `MAC_`, or no prefix).
    pub big_endian: bool,
    /// Signed samples (`..._INTEGER` without `UNSIGNED`).
    pub signed: bool,
    /// `BAND_STORAGE_TYPE`.
    pub storage: BandStorage,
    /// `LINE_PREFIX_BYTES`, `LINE_SUFFIX_BYTES`.
    pub line_padding: (u64, u64),
}

/// The order of the bands' samples (`BAND_STORAGE_TYPE`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BandStorage {
    /// Each band's whole image, one after the other.
    BandSequential,
    /// Each line holds the line of every band in turn.
    LineInterleaved,
    /// Each pixel holds every band's sample.
    SampleInterleaved,
}

impl ImageLayout {
    /// The layout of the `IMAGE` object of `label`; `Err` names the keyword at fault.
    pub fn of(label: &OdlLabel) -> Result<Self, String> {
        let root = label.root();
        let image = label.group("IMAGE").ok_or("no IMAGE object: the label describes no image")?;
        let whole = |g: &OdlGroup, key: &str, default: Option<u64>| -> Result<u64, String> {
            let v = match (g.get(key), default) {
                (None, Some(d)) => return Ok(d),
                _ => g.number(key)?,
            };
            (v >= 0.0 && v.fract() == 0.0 && v < 1e15).then_some(v as u64).ok_or_else(|| format!("{key} = {v} is not a whole number >= 0"))
        };
        let (w, h) = (whole(image, "LINE_SAMPLES", None)?, whole(image, "LINES", None)?);
        if w == 0 || h == 0 || w.checked_mul(h).is_none_or(|n| n > MAX_PIXELS) {
            return Err(format!("LINE_SAMPLES x LINES = {w} x {h}: not between 1 and {MAX_PIXELS} pixels"));
        }
        let bands = whole(image, "BANDS", Some(1))?;
        if bands != 1 && bands != 3 {
            return Err(format!("BANDS = {bands}: only grey (1) and RGB (3) images are read"));
        }
        let bits = whole(image, "SAMPLE_BITS", None)?;
        if bits != 8 && bits != 16 {
            return Err(format!("SAMPLE_BITS = {bits}: only 8- and 16-bit samples are read"));
        }
        let kind = image.text("SAMPLE_TYPE").ok_or("no SAMPLE_TYPE in the IMAGE object")?;
        let (big_endian, signed) = sample_type(kind, bits)?;
        let storage = match image.text("BAND_STORAGE_TYPE").unwrap_or("BAND_SEQUENTIAL") {
            "BAND_SEQUENTIAL" => BandStorage::BandSequential,
            "LINE_INTERLEAVED" => BandStorage::LineInterleaved,
            "SAMPLE_INTERLEAVED" => BandStorage::SampleInterleaved,
            other => return Err(format!("BAND_STORAGE_TYPE = {other}: not BAND_SEQUENTIAL, LINE_INTERLEAVED or SAMPLE_INTERLEAVED")),
        };
        let line_padding = (whole(image, "LINE_PREFIX_BYTES", Some(0))?, whole(image, "LINE_SUFFIX_BYTES", Some(0))?);
        if line_padding.0.max(line_padding.1) > 1 << 20 {
            return Err(format!("LINE_PREFIX_BYTES / LINE_SUFFIX_BYTES = {} / {}: more than 1 MiB per line", line_padding.0, line_padding.1));
        }
        let (data_file, start) = pointer(root)?;
        let offset = match start {
            Start::Record(n) => (n - 1).checked_mul(whole(root, "RECORD_BYTES", None)?).ok_or("^IMAGE: the offset overflows")?,
            Start::Byte(n) => n - 1,
        };
        Ok(ImageLayout { data_file, offset, size: (w as u32, h as u32), bands: bands as u32, bytes: (bits / 8) as u32, big_endian, signed, storage, line_padding })
    }

    /// Bytes from the first line's start to the end of the last line (at most a few GB: the
    /// size and padding are bounded).
    pub fn data_len(&self) -> u64 {
        let (w, h) = (self.size.0 as u64, self.size.1 as u64);
        let line = w * self.bytes as u64;
        let (pre, suf) = self.line_padding;
        let lines = match self.storage {
            BandStorage::BandSequential => h * self.bands as u64,
            BandStorage::LineInterleaved => h * self.bands as u64,
            BandStorage::SampleInterleaved => h,
        };
        let line_bytes = match self.storage {
            BandStorage::SampleInterleaved => line * self.bands as u64,
            _ => line,
        };
        lines * (pre + line_bytes + suf)
    }

    /// Decodes the samples from `data` (the data file's bytes).
    pub fn decode(&self, data: &[u8]) -> Result<DynamicImage, String> {
        let need = self.offset.checked_add(self.data_len()).ok_or("the image's extent overflows")?;
        if (data.len() as u64) < need {
            return Err(format!("the image is cut short: its {}x{}x{} samples need bytes {}..{}, the file has {}", self.size.0, self.size.1, self.bands, self.offset, need, data.len()));
        }
        let (w, h, bands) = (self.size.0 as usize, self.size.1 as usize, self.bands as usize);
        let (pre, suf) = (self.line_padding.0 as usize, self.line_padding.1 as usize);
        let bytes = self.bytes as usize;
        let line_bytes = if self.storage == BandStorage::SampleInterleaved { w * bands * bytes } else { w * bytes };
        let stride = pre + line_bytes + suf;
        let base = self.offset as usize;
        // Byte position of sample (x, y, band b).
        let at = |x: usize, y: usize, b: usize| -> usize {
            let (line, col) = match self.storage {
                BandStorage::BandSequential => (b * h + y, x),
                BandStorage::LineInterleaved => (y * bands + b, x),
                BandStorage::SampleInterleaved => (y, x * bands + b),
            };
            base + line * stride + pre + col * bytes
        };
        let sample = |p: usize| -> u16 {
            if bytes == 1 {
                return if self.signed { (data[p] as i8).max(0) as u16 } else { data[p] as u16 };
            }
            let raw = if self.big_endian { u16::from_be_bytes([data[p], data[p + 1]]) } else { u16::from_le_bytes([data[p], data[p + 1]]) };
            if self.signed {
                (raw as i16).max(0) as u16
            } else {
                raw
            }
        };
        // Samples in pixel order (row by row, each pixel's bands together), straight into the
        // image's own sample type.
        let positions = || (0..h).flat_map(move |y| (0..w).flat_map(move |x| (0..bands).map(move |b| at(x, y, b))));
        let (w32, h32) = (w as u32, h as u32);
        let image = match (bytes, bands) {
            (1, 1) => DynamicImage::ImageLuma8(image::GrayImage::from_raw(w32, h32, positions().map(|p| sample(p) as u8).collect()).expect("w x h")),
            (1, _) => DynamicImage::ImageRgb8(image::RgbImage::from_raw(w32, h32, positions().map(|p| sample(p) as u8).collect()).expect("w x h x 3")),
            (_, 1) => DynamicImage::ImageLuma16(image::ImageBuffer::from_raw(w32, h32, positions().map(sample).collect()).expect("w x h")),
            _ => DynamicImage::ImageRgb16(image::ImageBuffer::from_raw(w32, h32, positions().map(sample).collect()).expect("w x h x 3")),
        };
        Ok(image)
    }
}

enum Start {
    Record(u64),
    Byte(u64),
}

/// `^IMAGE`: the data file it names (if any) and where the image starts.
fn pointer(root: &OdlGroup) -> Result<(Option<String>, Start), String> {
    let (v, line) = root.get("^IMAGE").ok_or("no ^IMAGE pointer: where the image starts is not given")?;
    let bad = || format!("line {line}: ^IMAGE = {v:?} is not n, n <BYTES>, (\"FILE\", n) or \"FILE\"");
    let v = v.trim();
    let (file, start) = match v.strip_prefix('(').and_then(|s| s.strip_suffix(')')) {
        Some(inner) => {
            let (f, n) = inner.split_once(',').ok_or_else(bad)?;
            (Some(f.trim().trim_matches('"').to_string()), n.trim())
        }
        None if v.starts_with('"') => (Some(v.trim_matches('"').to_string()), "1"),
        None => (None, v),
    };
    let (n, unit) = match start.split_once('<') {
        Some((n, u)) => (n.trim(), u.trim_end_matches('>').trim()),
        None => (start, ""),
    };
    let n: u64 = n.parse().ok().filter(|&n| n >= 1).ok_or_else(bad)?;
    let start = match unit {
        "" => Start::Record(n),
        u if u.eq_ignore_ascii_case("BYTES") => Start::Byte(n),
        _ => return Err(bad()),
    };
    if file.as_deref().is_some_and(|f| f.is_empty() || f.contains(['/', '\\'])) {
        return Err(format!("line {line}: ^IMAGE names {file:?}: a data file must be a bare file name beside the label"));
    }
    Ok((file, start))
}

/// Byte order and sign of a `SAMPLE_TYPE`.
fn sample_type(kind: &str, bits: u64) -> Result<(bool, bool), String> {
    let (order, rest) = match kind.split_once('_') {
        Some((p @ ("MSB" | "LSB" | "PC" | "SUN" | "MAC" | "VAX" | "IEEE"), rest)) => (p, rest),
        _ => ("", kind),
    };
    let signed = match rest {
        "UNSIGNED_INTEGER" => false,
        "INTEGER" => true,
        _ => return Err(format!("SAMPLE_TYPE = {kind}: only integer samples are read")),
    };
    let big_endian = !matches!(order, "LSB" | "PC" | "VAX");
    Ok((big_endian || bits == 8, signed))
}

/// Decodes the PDS3 product whose label is at the start of `bytes` (read from `path`; a
/// detached label's data file is read from `path`'s folder). Errors name the file.
pub fn decode(bytes: &[u8], path: &Path) -> Result<DynamicImage, String> {
    let fail = |m: String| format!("{}: PDS3 image: {m}", path.display());
    let label = OdlLabel::parse(bytes).map_err(fail)?;
    let layout = ImageLayout::of(&label).map_err(fail)?;
    match &layout.data_file {
        None => layout.decode(bytes).map_err(fail),
        Some(name) => {
            let data_path = data_file_path(path, name).map_err(fail)?;
            let data = std::fs::read(&data_path).map_err(|e| fail(format!("reading its data file {}: {e}", data_path.display())))?;
            layout.decode(&data).map_err(|m| format!("{}: PDS3 image (label {}): {m}", data_path.display(), path.display()))
        }
    }
}

/// The width and height of the PDS3 product labelled at the start of `bytes`.
pub fn size(bytes: &[u8], path: &Path) -> Result<(u32, u32), String> {
    let label = OdlLabel::parse(bytes).map_err(|m| format!("{}: PDS3 image: {m}", path.display()))?;
    ImageLayout::of(&label).map(|l| l.size).map_err(|m| format!("{}: PDS3 image: {m}", path.display()))
}

/// The data file `name` beside the label `path`: that name, or the one name of the folder
/// that equals it but for case (archives name files in capitals, copies often in small
/// letters).
fn data_file_path(path: &Path, name: &str) -> Result<PathBuf, String> {
    let dir = path.parent().unwrap_or(Path::new("."));
    let exact = dir.join(name);
    if exact.is_file() {
        return Ok(exact);
    }
    let found: Vec<PathBuf> = std::fs::read_dir(dir).into_iter().flatten().flatten().map(|e| e.path()).filter(|p| p.file_name().and_then(|f| f.to_str()).is_some_and(|f| f.eq_ignore_ascii_case(name))).collect();
    match found.as_slice() {
        [one] => Ok(one.clone()),
        [] => Err(format!("^IMAGE names the data file {name:?}, which is not beside the label in {}", dir.display())),
        _ => Err(format!("^IMAGE names {name:?}, and {} files of {} match it but for case", found.len(), dir.display())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A label with records of 64 bytes, `^IMAGE = pointer` and `image_keys` in its IMAGE object.
    fn label(pointer: &str, image_keys: &str) -> String {
        format!("PDS_VERSION_ID = PDS3\nRECORD_TYPE = FIXED_LENGTH\nRECORD_BYTES = 64\n^IMAGE = {pointer}\nOBJECT = IMAGE\n{image_keys}\nEND_OBJECT = IMAGE\nEND\n")
    }

    /// `text` padded with spaces to `records` records of 64 bytes.
    fn padded(text: &str, records: usize) -> Vec<u8> {
        let mut b = text.as_bytes().to_vec();
        assert!(b.len() <= records * 64);
        b.resize(records * 64, b' ');
        b
    }

    #[test]
    fn a_12_bit_msb_image_with_line_prefixes_is_read_at_its_record() {
        let keys = "LINES = 2\nLINE_SAMPLES = 3\nSAMPLE_TYPE = MSB_INTEGER\nSAMPLE_BITS = 16\nLINE_PREFIX_BYTES = 2";
        let mut file = padded(&label("5", keys), 4);
        let values: [[i16; 3]; 2] = [[0, 4095, 17], [-3, 2048, 1]];
        for row in values {
            file.extend([0xEE, 0xEE]);
            for v in row {
                file.extend(v.to_be_bytes());
            }
        }
        let img = decode(&file, Path::new("a.IMG")).unwrap();
        let DynamicImage::ImageLuma16(g) = &img else { panic!("{:?}", img.color()) };
        assert_eq!(g.as_raw(), &vec![0, 4095, 17, 0, 2048, 1], "negative samples are 0");
        assert_eq!(size(&file, Path::new("a.IMG")).unwrap(), (3, 2));
        // The real bit depth maps 4095 to 255, as for a 16-bit PNG.
        assert_eq!(crate::input::rgb8_of(&img).info.data_bits, 12);
        // One byte short: refused, naming the file and the extent.
        let err = decode(&file[..file.len() - 1], Path::new("dir/a.IMG")).unwrap_err();
        assert!(err.contains("dir/a.IMG") && err.contains("cut short") && err.contains("256..272"), "{err}");
    }

    #[test]
    fn band_orders_and_byte_pointers_give_the_same_rgb_image() {
        // 2 x 1 RGB: pixel 0 = (1, 2, 3), pixel 1 = (4, 5, 6), little-endian unsigned 16-bit.
        let pixels = [[1u16, 2, 3], [4, 5, 6]];
        let mut images = Vec::new();
        for (storage, order) in [("BAND_SEQUENTIAL", [(0, 0), (1, 0), (0, 1), (1, 1), (0, 2), (1, 2)]), ("SAMPLE_INTERLEAVED", [(0, 0), (0, 1), (0, 2), (1, 0), (1, 1), (1, 2)]), ("LINE_INTERLEAVED", [(0, 0), (1, 0), (0, 1), (1, 1), (0, 2), (1, 2)])]
        {
            let keys = format!("LINES = 1\nLINE_SAMPLES = 2\nBANDS = 3\nSAMPLE_TYPE = LSB_UNSIGNED_INTEGER\nSAMPLE_BITS = 16\nBAND_STORAGE_TYPE = {storage}");
            let mut file = padded(&label("449 <BYTES>", &keys), 7);
            for (x, b) in order {
                file.extend(pixels[x][b].to_le_bytes());
            }
            images.push(decode(&file, Path::new("c.IMG")).unwrap());
        }
        for img in &images {
            assert_eq!(img.as_rgb16().expect("RGB16").as_raw(), &vec![1, 2, 3, 4, 5, 6]);
        }
    }

    #[test]
    fn a_detached_label_reads_its_data_file_whatever_its_case() {
        let dir = tempfile::tempdir().unwrap();
        let keys = "LINES = 2\nLINE_SAMPLES = 2\nSAMPLE_TYPE = UNSIGNED_INTEGER\nSAMPLE_BITS = 8";
        std::fs::write(dir.path().join("x.lbl"), label("(\"X.IMG\", 2)", keys)).unwrap();
        let mut data = vec![9u8; 64];
        data.extend([10, 20, 30, 40]);
        std::fs::write(dir.path().join("x.img"), &data).unwrap();
        let lbl = dir.path().join("x.lbl");
        let img = decode(&std::fs::read(&lbl).unwrap(), &lbl).unwrap();
        assert_eq!(img.as_luma8().expect("grey 8-bit").as_raw(), &vec![10, 20, 30, 40]);
        std::fs::remove_file(dir.path().join("x.img")).unwrap();
        let err = decode(&std::fs::read(&lbl).unwrap(), &lbl).unwrap_err();
        assert!(err.contains("x.lbl") && err.contains("\"X.IMG\"") && err.contains("not beside the label"), "{err}");
    }

    #[test]
    fn what_cannot_be_read_is_refused_naming_the_keyword() {
        let base = "LINES = 2\nLINE_SAMPLES = 2\nSAMPLE_TYPE = MSB_INTEGER\nSAMPLE_BITS = 16";
        let cases = [
            (base.replace("MSB_INTEGER", "IEEE_REAL"), "SAMPLE_TYPE = IEEE_REAL"),
            (base.replace("16", "32"), "SAMPLE_BITS = 32"),
            (format!("{base}\nBANDS = 4"), "BANDS = 4"),
            (base.replace("LINES = 2", "LINES = 200000000"), "not between 1 and"),
            (format!("{base}\nBAND_STORAGE_TYPE = WHATEVER"), "BAND_STORAGE_TYPE = WHATEVER"),
        ];
        for (keys, want) in cases {
            let err = decode(&padded(&label("8", &keys), 7), Path::new("b.IMG")).unwrap_err();
            assert!(err.contains("b.IMG") && err.contains(want), "{keys}: {err}");
        }
        let err = decode(&padded(&label("0", base), 7), Path::new("b.IMG")).unwrap_err();
        assert!(err.contains("^IMAGE"), "{err}");
        let err = decode(&padded(&label("(\"../x.IMG\", 2)", base), 7), Path::new("b.IMG")).unwrap_err();
        assert!(err.contains("bare file name"), "{err}");
    }
}
