//! `tubeloc stereo`: disparity (and optionally a point cloud) from a stereo pair.
//!
//! Outputs in `--out DIR`:
//! - `disparity.pfm`: float disparity in pixels (Middlebury PFM, invalid = +inf),
//! - `disparity16.png`: 16-bit PNG with `round(16 d)`, 0 = invalid,
//! - `disparity_preview.png`: colour preview (blue = far/small d, red = near, black = invalid),
//! - `disparity.json`: header (sizes, parameters, regions, rectification P1/P2/Q and valid
//!   regions when `--rig` is given),
//! - with `--rig`: `rectified_left.png`, `rectified_right.png`; with `--ply` also `points.ply`
//!   (points in the original left camera frame, metres, with per-point `sigma_z`).
//!
//! With `--set DIR` (a `tubeloc synth stereo` folder) instead of `--left/--right`, every pair of
//! the set is matched and scored against its exact disparity: bad-1/bad-2/MAE over valid and
//! over tube pixels, and distances of triangulated tube points to the true tube surface
//! (median, p90); results in `--out DIR/stereo_eval.json`.

use anyhow::{bail, Context, Result};
use clap::Args;
use std::path::{Path, PathBuf};
use tubeloc_core::{files::write_atomic, Plane};
use tubeloc_stereo::{disparity_regions, io, Paths, Roi, SgmMatcher, SgmParams, StereoRectification};

/// Arguments of `tubeloc stereo`.
#[derive(Args, Debug)]
pub struct StereoArgs {
    /// Left image (any format the image crate reads; converted to grey).
    #[arg(long, required_unless_present = "set")]
    left: Option<PathBuf>,
    /// Right image.
    #[arg(long, required_unless_present = "set")]
    right: Option<PathBuf>,
    /// Evaluate on a synthetic stereo set (`tubeloc synth stereo` output) instead of one pair.
    #[arg(long, conflicts_with_all = ["left", "right", "rig", "rois", "ply"])]
    set: Option<PathBuf>,
    /// With --set: evaluate at most this many pairs.
    #[arg(long, value_parser = crate::args::positive_usize)]
    limit: Option<usize>,
    /// Rig file (tubeloc JSON, OpenCV YAML or kalibr camchain): the pair is rectified with it before matching.
    #[arg(long)]
    rig: Option<PathBuf>,
    /// Camera names of the pair in the rig, "LEFT,RIGHT" (default: the rig's first stereo pair).
    #[arg(long)]
    pair: Option<String>,
    /// Number of disparities searched (multiple of 16).
    #[arg(long, default_value_t = 128, value_parser = disparities_arg)]
    disparities: usize,
    /// Smallest disparity searched, pixels.
    #[arg(long, default_value_t = 0, allow_hyphen_values = true)]
    min_disparity: i32,
    /// Aggregation paths: 8 or 4.
    #[arg(long, default_value_t = 8, value_parser = paths_arg)]
    paths: u8,
    /// Region of interest "x,y,w,h" in (rectified) left pixels; repeatable. Without it the whole image is matched.
    #[arg(long = "roi", value_parser = roi_arg)]
    rois: Vec<String>,
    /// Margin (pixels) added around each region of interest.
    #[arg(long, default_value_t = 32)]
    margin: usize,
    /// JSON file overriding SGM parameters (fields of SgmParams).
    #[arg(long)]
    params: Option<PathBuf>,
    /// Write a PLY point cloud (needs --rig).
    #[arg(long)]
    ply: bool,
    /// Disparity standard deviation (pixels) used for the depth uncertainty.
    #[arg(long, default_value_t = 0.25, value_parser = crate::args::positive_f64)]
    sigma_d: f64,
    /// Output folder.
    #[arg(long)]
    out: PathBuf,
}

/// Reads an image as 8-bit grey, naming the file on error.
pub(crate) fn load_gray(path: &Path) -> Result<Plane<u8>> {
    let img = tubeloc_detect::input::open_eight_bit(path).with_context(|| format!("cannot read image {}", path.display()))?.to_luma8();
    Ok(Plane::from_vec(img.width() as usize, img.height() as usize, img.into_raw()))
}

fn png_bytes<P: image::PixelWithColorType>(img: image::ImageBuffer<P, Vec<P::Subpixel>>) -> Result<Vec<u8>>
where
    [P::Subpixel]: image::EncodableLayout,
{
    let mut buf = std::io::Cursor::new(Vec::new());
    img.write_to(&mut buf, image::ImageFormat::Png).context("cannot encode PNG")?;
    Ok(buf.into_inner())
}

fn parse_roi(s: &str) -> Result<Roi> {
    let v: Vec<i64> = s.split(',').map(|t| t.trim().parse::<i64>()).collect::<std::result::Result<_, _>>().with_context(|| format!("--roi {s:?}: expected x,y,w,h integers"))?;
    if v.len() != 4 {
        bail!("--roi {s:?}: expected 4 numbers x,y,w,h, got {}", v.len());
    }
    Ok(Roi::new(v[0], v[1], v[2], v[3]))
}

/// `--disparities`: a positive multiple of 16.
fn disparities_arg(s: &str) -> std::result::Result<usize, String> {
    let n = crate::args::positive_usize(s)?;
    if n % 16 == 0 {
        Ok(n)
    } else {
        Err(format!("must be a positive multiple of 16, got {n}"))
    }
}

/// `--paths`: 8 or 4.
fn paths_arg(s: &str) -> std::result::Result<u8, String> {
    match s.trim() {
        "8" => Ok(8),
        "4" => Ok(4),
        _ => Err(format!("must be 8 or 4, got {s:?}")),
    }
}

/// `--roi`: `x,y,w,h` integers with `w, h > 0` (checked while parsing, kept as text).
fn roi_arg(s: &str) -> std::result::Result<String, String> {
    let v: Vec<i64> = s.split(',').map(|t| t.trim().parse::<i64>()).collect::<std::result::Result<_, _>>().map_err(|_| format!("{s:?}: expected x,y,w,h integers"))?;
    if v.len() != 4 {
        return Err(format!("{s:?}: expected 4 numbers x,y,w,h, got {}", v.len()));
    }
    if v[2] <= 0 || v[3] <= 0 {
        return Err(format!("{s:?}: width and height must be > 0"));
    }
    Ok(s.to_string())
}

/// Runs `tubeloc stereo`.
pub fn run(args: StereoArgs) -> Result<()> {
    let mut params = match &args.params {
        Some(p) => tubeloc_core::files::read_json::<SgmParams>(p).with_context(|| format!("SGM parameters {}", p.display()))?,
        None => SgmParams::default(),
    };
    params.num_disparities = args.disparities;
    params.min_disparity = args.min_disparity;
    params.paths = match args.paths {
        8 => Paths::Eight,
        4 => Paths::Four,
        n => bail!("--paths must be 8 or 4, got {n}"),
    };
    if let Some(set) = &args.set {
        return eval_set(set, &params, args.limit, &args.out);
    }
    let (Some(left_path), Some(right_path)) = (args.left.clone(), args.right.clone()) else { bail!("--left and --right are required without --set") };
    let rois = args.rois.iter().map(|s| parse_roi(s)).collect::<Result<Vec<_>>>()?;
    let (mut left, mut right) = (load_gray(&left_path)?, load_gray(&right_path)?);
    let mut header = serde_json::json!({
        "left": left_path, "right": right_path, "params": params,
        "disparity_convention": "d = x_left - x_right in (rectified) left pixels; PFM invalid = +inf; PNG16 = round(16 d), 0 invalid",
    });
    let mut rect = None;
    if let Some(rig_path) = &args.rig {
        let ((ln, rn), _, r) = rectification_from_rig(rig_path, args.pair.as_deref())?;
        let (rl, rr) = r.rectify_pair(&left, &right).with_context(|| format!("{} / {}", left_path.display(), right_path.display()))?;
        left = rl;
        right = rr;
        for (name, p) in [("rectified_left.png", &left), ("rectified_right.png", &right)] {
            let img = image::GrayImage::from_raw(p.width as u32, p.height as u32, p.data.clone()).context("image buffer")?;
            write_atomic(&args.out.join(name), &png_bytes(img)?)?;
        }
        header["rectification"] = serde_json::json!({
            "pair": [ln, rn], "rectified_camera": r.rectified, "baseline_m": r.baseline,
            "P1": r.p1.transpose().as_slice(), "P2": r.p2.transpose().as_slice(), "Q": r.q.transpose().as_slice(),
            "R1": r.r_left.transpose().as_slice(), "R2": r.r_right.transpose().as_slice(),
            "valid_left": r.valid_left, "valid_right": r.valid_right,
            "matrix_layout": "row-major",
        });
        rect = Some(r);
    }
    let disp = if rois.is_empty() {
        SgmMatcher::new(params.clone())?.compute(&left, &right).with_context(|| format!("matching {} / {}", left_path.display(), right_path.display()))?
    } else {
        header["regions"] = serde_json::to_value(&rois)?;
        header["margin"] = args.margin.into();
        disparity_regions(&left, &right, &params, &rois, args.margin).with_context(|| format!("matching {} / {}", left_path.display(), right_path.display()))?
    };
    let (w, h) = (disp.width as u32, disp.height as u32);
    write_atomic(&args.out.join("disparity.pfm"), &io::encode_pfm(&disp))?;
    let d16 = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_raw(w, h, io::to_u16_x16(&disp)).context("image buffer")?;
    write_atomic(&args.out.join("disparity16.png"), &png_bytes(d16)?)?;
    let lo = params.min_disparity as f32;
    let preview = image::RgbImage::from_raw(w, h, io::colorize(&disp, lo, lo + params.num_disparities as f32)).context("image buffer")?;
    write_atomic(&args.out.join("disparity_preview.png"), &png_bytes(preview)?)?;
    let valid = disp.data.iter().filter(|d| !d.is_nan()).count();
    header["width"] = w.into();
    header["height"] = h.into();
    header["valid_pixels"] = valid.into();
    if args.ply {
        let r = rect.as_ref().context("--ply needs --rig (the baseline and focal length come from the rig)")?;
        let pts = r.points_in_left_camera(&tubeloc_stereo::triangulate(&disp, &r.geometry(), args.sigma_d));
        let mut ply = format!("ply\nformat ascii 1.0\ncomment frame: original left camera (OpenCV axes), metres\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nproperty float sigma_z\nend_header\n", pts.len());
        for p in &pts {
            ply.push_str(&format!("{:.5} {:.5} {:.5} {:.5}\n", p.point.x, p.point.y, p.point.z, p.sigma_z));
        }
        write_atomic(&args.out.join("points.ply"), ply.as_bytes())?;
        header["points"] = pts.len().into();
    }
    tubeloc_core::files::write_json(&args.out.join("disparity.json"), &header)?;
    crate::out::outln!("{}: {}x{} disparity, {:.1}% valid", args.out.display(), w, h, 100.0 * valid as f64 / (w as f64 * h as f64).max(1.0));
    Ok(())
}

/// Reads a rig file and rectifies one of its pairs: `pair` is "LEFT,RIGHT" (camera names), by
/// default the rig's first stereo pair. Returns the pair's names, the left camera's model and the
/// rectification.
pub(crate) fn rectification_from_rig(rig_path: &Path, pair: Option<&str>) -> Result<((String, String), tubeloc_core::CameraModel, StereoRectification)> {
    let rig = tubeloc_calib::read_rig(rig_path)?;
    let (ln, rn) = match pair {
        Some(p) => {
            let (a, b) = p.split_once(',').with_context(|| format!("--pair {p:?}: expected LEFT,RIGHT"))?;
            (a.trim().to_string(), b.trim().to_string())
        }
        None => rig.stereo_pairs.first().cloned().with_context(|| format!("{}: no stereo_pairs; pass --pair LEFT,RIGHT", rig_path.display()))?,
    };
    let cam = |n: &str| rig.camera(n).with_context(|| format!("{}: no camera named {n:?}", rig_path.display()));
    let (lcam, rcam) = (&cam(&ln)?.model, &cam(&rn)?.model);
    let rect = StereoRectification::new(lcam, rcam, &rig.relative_pose(&ln, &rn)?).with_context(|| format!("rectifying pair {ln},{rn} of {}", rig_path.display()))?;
    Ok(((ln.clone(), rn.clone()), lcam.clone(), rect))
}

/// Matches every pair of a synthetic stereo set and scores it against the exact disparity.
fn eval_set(dir: &Path, params: &SgmParams, limit: Option<usize>, out: &Path) -> Result<()> {
    use tubeloc_core::{CameraModel, CocoDataset, Pose, Segmentation, TubeModel};
    use tubeloc_stereo::pair_eval::PairEval;
    let ann_path = dir.join("annotations.json");
    let ds = CocoDataset::load(&ann_path).with_context(|| format!("reading stereo set {}", ann_path.display()))?;
    let model = TubeModel::default();
    let mut matcher = SgmMatcher::new(params.clone())?;
    let (mut total, mut per_pair) = (PairEval::default(), Vec::new());
    let images: Vec<_> = ds.images.iter().take(limit.unwrap_or(usize::MAX)).collect();
    let bar = indicatif::ProgressBar::new(images.len() as u64);
    let mut ms = Vec::new();
    for img in images {
        let e = &img.extra;
        let field = |k: &str| e.get(k).with_context(|| format!("{}: image {} has no {k:?} (not a stereo set?)", ann_path.display(), img.id));
        let cam: CameraModel = serde_json::from_value(field("camera")?.clone()).with_context(|| format!("image {}: camera", img.id))?;
        let baseline = field("baseline_m")?.as_f64().context("baseline_m is not a number")?;
        let geom = tubeloc_stereo::RectifiedGeometry { f: cam.fx, cx: cam.cx, cy: cam.cy, baseline };
        let left = load_gray(&dir.join("images").join(&img.file_name))?;
        let right = load_gray(&dir.join("right").join(field("right_file_name")?.as_str().context("right_file_name")?))?;
        let gt_path = dir.join("disparity").join(field("disparity_file_name")?.as_str().context("disparity_file_name")?);
        let gt = io::decode_pfm(&std::fs::read(&gt_path).with_context(|| format!("reading {}", gt_path.display()))?).with_context(|| format!("decoding {}", gt_path.display()))?;
        let t0 = std::time::Instant::now();
        let est = matcher.compute(&left, &right).with_context(|| format!("matching {}", img.file_name))?;
        ms.push(t0.elapsed().as_secs_f64() * 1e3);
        let mut masks = Vec::new();
        for a in ds.annotations.iter().filter(|a| a.image_id == img.id) {
            let Some(Segmentation::CompressedRle { counts, size }) = &a.segmentation else { continue };
            let mask = tubeloc_core::Rle::from_compressed_string(counts, *size)?.to_mask()?;
            let pose: Pose = serde_json::from_value(a.extra.get("T_cam_tube").cloned().unwrap_or_default()).with_context(|| format!("annotation {}: T_cam_tube", a.id))?;
            masks.push((mask, pose));
        }
        let tubes: Vec<_> = masks.iter().map(|(m, p)| (m, *p)).collect();
        let mut one = PairEval::default();
        one.add(&est, &gt, &geom, &tubes, &model);
        total.add(&est, &gt, &geom, &tubes, &model);
        per_pair.push(serde_json::json!({"image_id": img.id, "file_name": img.file_name, "summary": one.summary()}));
        bar.inc(1);
    }
    bar.finish_and_clear();
    ms.sort_by(f64::total_cmp);
    let s = total.summary();
    let report = serde_json::json!({
        "set": dir, "pairs": per_pair.len(), "params": params, "total": s, "per_pair": per_pair,
        "median_match_ms": ms.get(ms.len() / 2),
        "definitions": "valid: finite exact disparity, inside the right image, not occluded; tube: valid pixels in the visible tube masks; bad-t: no estimate or |error| > t px; MAE over pixels with an estimate; distances: triangulated tube points to the true tube surface",
    });
    tubeloc_core::files::write_json(&out.join("stereo_eval.json"), &report)?;
    crate::out::outln!(
        "{} pairs: valid px bad-1 {:.4} bad-2 {:.4} MAE {:.3} px (density {:.3}); tube px bad-1 {:.4} bad-2 {:.4} MAE {:.3} px; tube points {} median {:.2} mm p90 {:.2} mm",
        per_pair.len(),
        s.valid.bad1,
        s.valid.bad2,
        s.valid.mae,
        s.valid.density,
        s.tube.bad1,
        s.tube.bad2,
        s.tube.mae,
        s.tube_points,
        s.tube_median_mm,
        s.tube_p90_mm
    );
    Ok(())
}
