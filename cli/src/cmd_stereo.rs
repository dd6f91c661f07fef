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

use anyhow::{bail, Context, Result};
use clap::Args;
use std::path::{Path, PathBuf};
use tubeloc_core::{files::write_atomic, Plane, Rig};
use tubeloc_stereo::{disparity_regions, io, Paths, Roi, SgmMatcher, SgmParams, StereoRectification};

/// Arguments of `tubeloc stereo`.
#[derive(Args, Debug)]
pub struct StereoArgs {
    /// Left image (any format the image crate reads; converted to grey).
    #[arg(long)]
    left: PathBuf,
    /// Right image.
    #[arg(long)]
    right: PathBuf,
    /// Rig JSON file: the pair is rectified with it before matching.
    #[arg(long)]
    rig: Option<PathBuf>,
    /// Camera names of the pair in the rig, "LEFT,RIGHT" (default: the rig's first stereo pair).
    #[arg(long)]
    pair: Option<String>,
    /// Number of disparities searched (multiple of 16).
    #[arg(long, default_value_t = 128)]
    disparities: usize,
    /// Smallest disparity searched, pixels.
    #[arg(long, default_value_t = 0, allow_hyphen_values = true)]
    min_disparity: i32,
    /// Aggregation paths: 8 or 4.
    #[arg(long, default_value_t = 8)]
    paths: u8,
    /// Region of interest "x,y,w,h" in (rectified) left pixels; repeatable. Without it the whole image is matched.
    #[arg(long = "roi")]
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
    #[arg(long, default_value_t = 0.25)]
    sigma_d: f64,
    /// Output folder.
    #[arg(long)]
    out: PathBuf,
}

/// Reads an image as 8-bit grey, naming the file on error.
pub(crate) fn load_gray(path: &Path) -> Result<Plane<u8>> {
    let img = image::open(path).with_context(|| format!("cannot read image {}", path.display()))?.to_luma8();
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
    let rois = args.rois.iter().map(|s| parse_roi(s)).collect::<Result<Vec<_>>>()?;
    let (mut left, mut right) = (load_gray(&args.left)?, load_gray(&args.right)?);
    let mut header = serde_json::json!({
        "left": args.left, "right": args.right, "params": params,
        "disparity_convention": "d = x_left - x_right in (rectified) left pixels; PFM invalid = +inf; PNG16 = round(16 d), 0 invalid",
    });
    let mut rect = None;
    if let Some(rig_path) = &args.rig {
        let ((ln, rn), _, r) = rectification_from_rig(rig_path, args.pair.as_deref())?;
        let (rl, rr) = r.rectify_pair(&left, &right).with_context(|| format!("{} / {}", args.left.display(), args.right.display()))?;
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
        SgmMatcher::new(params.clone())?.compute(&left, &right).with_context(|| format!("matching {} / {}", args.left.display(), args.right.display()))?
    } else {
        header["regions"] = serde_json::to_value(&rois)?;
        header["margin"] = args.margin.into();
        disparity_regions(&left, &right, &params, &rois, args.margin).with_context(|| format!("matching {} / {}", args.left.display(), args.right.display()))?
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
    println!("{}: {}x{} disparity, {:.1}% valid", args.out.display(), w, h, 100.0 * valid as f64 / (w as f64 * h as f64).max(1.0));
    Ok(())
}

/// Reads a rig file and rectifies one of its pairs: `pair` is "LEFT,RIGHT" (camera names), by
/// default the rig's first stereo pair. Returns the pair's names, the left camera's model and the
/// rectification.
pub(crate) fn rectification_from_rig(rig_path: &Path, pair: Option<&str>) -> Result<((String, String), tubeloc_core::CameraModel, StereoRectification)> {
    let rig = Rig::load_json(rig_path)?;
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
