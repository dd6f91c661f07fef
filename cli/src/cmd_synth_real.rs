//! `tubeloc synth real`: composites of rendered tubes on real rover frames, split by sol.
//!
//! Validation and test sets use the frames with PDS camera models (grey Navcam and MER
//! frames: the ground and the sun of the frame) plus the colour Mastcam frames of the same
//! split under the view `--assumed-view auto` takes for them (M-100 frames `m100`, the others
//! the documented `mast` view); training sets use every background of the
//! training split under random assumed views, with appearance randomization.

use anyhow::{bail, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use serde_json::json;
use std::path::PathBuf;
use std::sync::Arc;
use tubeloc_core::{files, TubeModel};
use tubeloc_synth::dataset::write_folder_atomically;
use tubeloc_synth::real_frames::{split_views, ChosenFrames, FrameChoice, GreyView, RealSplit, RealView};
use tubeloc_synth::real_set::{assemble, render_sample, RealSetConfig};
use tubeloc_synth::TubeShape;

/// Which frames go into the set.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum RealKind {
    /// Grey frames with PDS camera models (validation and test) or grey backgrounds (training).
    Grey,
    /// Colour frames under an assumed view.
    Colour,
    /// Both.
    All,
}

/// `--grey-view`: [`GreyView`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum GreyViewArg {
    /// Each frame's PDS camera and ground.
    Pds,
    /// The assumed Navcam view (a frame whose own camera model sees sky where that view puts
    /// tubes is left out).
    Assumed,
    /// Both.
    Both,
}

/// Arguments of `tubeloc synth real`.
#[derive(Args)]
pub struct RealArgs {
    /// The real data folder (holding MANIFEST.tsv, backgrounds/ and with_cameras/).
    #[arg(long, default_value = "../shared/data/real_mars")]
    pub data: PathBuf,
    /// Part of the data: `train` (backgrounds, random assumed views), `val`, `test`, or `all`
    /// (every frame whatever its sol, as validation and test frames are made).
    #[arg(long)]
    pub split: RealSplit,
    /// Grey, colour or all frames.
    #[arg(long, value_enum, default_value = "all")]
    pub kind: RealKind,
    /// Composites per frame.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub per_view: u32,
    /// Tubes per composite, "MIN:MAX" (0 gives negative frames).
    #[arg(long, default_value = "1:4", value_parser = tube_counts)]
    pub tubes: (usize, usize),
    /// Distance band of the tubes from the camera, metres, "NEAR:FAR".
    #[arg(long, default_value = "1.5:5", value_parser = crate::args::range_m)]
    pub range_m: (f64, f64),
    /// Geometry of the grey frames of `val` and `test`: `pds` (the frames with PDS camera
    /// models, each under its own camera and ground), `assumed` (the part's grey backgrounds
    /// under the assumed Navcam view: 45 degree field of view, 1.9 m high, 30 degrees down,
    /// as the bench judges real frames without a camera model; a frame whose own camera model
    /// sees sky where that view puts tubes is left out), or `both`.
    #[arg(long, value_enum, default_value = "pds")]
    pub grey_view: GreyViewArg,
    /// Horizontal field of view of the random training views, degrees, "LO:HI" (`--split
    /// train` only; validation and test frames take their own or the product's view). The
    /// named views span 6.15 (Mastcam-Z at 110 mm) to 96 (Perseverance Navcam).
    #[arg(long, default_value = "15:50", value_parser = hfov_range)]
    pub hfov_deg: (f64, f64),
    /// Smallest frame side used (the 256 px frames binned on board show tubes 1-3 px wide).
    #[arg(long, default_value_t = 500)]
    pub min_size: u32,
    /// Appearance randomization for training: dust 0-0.6, tube gain 0.6-1.4, JPEG quality
    /// 55-95 (default for `--split train`; validation and test sets are clean PNGs).
    #[arg(long)]
    pub randomize: Option<bool>,
    /// Composite on the colour frames as a monochrome 600-800 nm camera (Navcam) would see
    /// them: each frame's red channel, the tubes shaded in that band, saved grey (more grey
    /// training composites; `--kind colour` gives only these).
    #[arg(long)]
    pub colour_as_grey: bool,
    /// Keep at most this many frames (in file order), e.g. for a small CI set.
    #[arg(long)]
    pub limit: Option<usize>,
    /// Master seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Replace an existing output folder.
    #[arg(long)]
    pub force: bool,
    /// Output folder (images/, annotations.json).
    #[arg(long)]
    pub out: PathBuf,
}

/// A field-of-view range "LO:HI" in degrees, `0 < LO <= HI < 180`, checked when the command line
/// is parsed.
fn hfov_range(s: &str) -> std::result::Result<(f64, f64), String> {
    let (a, b) = s.split_once(':').ok_or_else(|| format!("{s:?}: expected LO:HI in degrees"))?;
    match (a.trim().parse::<f64>(), b.trim().parse::<f64>()) {
        (Ok(lo), Ok(hi)) => tubeloc_synth::real_frames::check_hfov_range((lo, hi)).map(|()| (lo, hi)).map_err(|m| format!("{s:?}: {m}")),
        _ => Err(format!("{s:?}: expected two numbers LO:HI in degrees")),
    }
}

/// Tubes per composite "MIN:MAX", `MIN <= MAX <= 20`, checked when the command line is parsed.
fn tube_counts(s: &str) -> std::result::Result<(usize, usize), String> {
    let (a, b) = s.split_once(':').ok_or_else(|| format!("{s:?}: expected MIN:MAX"))?;
    match (a.trim().parse::<usize>(), b.trim().parse::<usize>()) {
        (Ok(a), Ok(b)) if a <= b && b <= 20 => Ok((a, b)),
        (Ok(_), Ok(_)) => Err(format!("{s:?}: need MIN <= MAX <= 20")),
        _ => Err(format!("{s:?}: expected two whole numbers MIN:MAX")),
    }
}

/// Runs `tubeloc synth real`.
pub fn run(a: RealArgs) -> Result<()> {
    if a.colour_as_grey && a.kind == RealKind::Grey {
        bail!("--colour-as-grey turns colour frames grey, and --kind grey takes none: use --kind colour or all");
    }
    let views = frames(&a)?;
    if views.is_empty() {
        bail!(
            "{}: no {} frames of the {} part (a frame's part comes from its sol, and frames of unknown sol are training frames; `--split all` takes every frame)",
            a.data.display(),
            match a.kind {
                RealKind::Grey => "grey",
                RealKind::Colour => "colour",
                RealKind::All => "grey or colour",
            },
            a.split.name()
        );
    }
    write_set(&a, &views).map(|_| ())
}

/// The frames `a` composites on, with their views (at most `--limit`).
pub fn frames(a: &RealArgs) -> Result<Vec<RealView>> {
    let grey_view = match a.grey_view {
        GreyViewArg::Pds => GreyView::Pds,
        GreyViewArg::Assumed => GreyView::Assumed,
        GreyViewArg::Both => GreyView::Both,
    };
    let choice = FrameChoice { split: a.split, grey: (a.kind != RealKind::Colour).then_some(grey_view), colour: a.kind != RealKind::Grey, min_size: a.min_size, training_hfov_deg: a.hfov_deg, far_m: a.range_m.1, seed: a.seed };
    let ChosenFrames { mut views, sky_dropped } = split_views(&a.data, &choice)?;
    if !sky_dropped.is_empty() {
        eprintln!(
            "{} grey frame(s) left out of the assumed Navcam view: their own camera models ({}) see no ground where it puts tubes up to {} m: {}",
            sky_dropped.len(),
            a.data.join("with_cameras").join("cameras.json").display(),
            a.range_m.1,
            sky_dropped.join(", ")
        );
    }
    if let Some(n) = a.limit {
        views.truncate(n);
    }
    Ok(views)
}

/// Writes the composite set of `a` on `views` (from [`frames`]) to `a.out`, atomically;
/// returns its composites and tubes.
pub fn write_set(a: &RealArgs, views: &[RealView]) -> Result<(usize, usize)> {
    let (tubes, range) = (a.tubes, a.range_m);
    let randomize = a.randomize.unwrap_or(a.split == RealSplit::Train);
    let cfg = RealSetConfig {
        tubes,
        per_view: a.per_view as usize,
        range_m: range,
        dust: if randomize { (0.0, 0.6) } else { (0.0, 0.2) },
        tube_gain: if randomize { (0.6, 1.4) } else { (1.0, 1.0) },
        jpeg_quality: randomize.then_some((55, 95)),
        seed: a.seed,
        tube_shape: Arc::new(TubeShape::from_model(&TubeModel::default())),
        colour_as_grey: a.colour_as_grey,
    };
    let jobs: Vec<(usize, usize)> = (0..views.len()).flat_map(|v| (0..cfg.per_view).map(move |k| (v, k))).collect();
    let pb = ProgressBar::new(jobs.len() as u64);
    pb.set_style(ProgressStyle::with_template("composite {bar:30} {pos}/{len} {elapsed}<{eta}").expect("template"));
    let mut spread = None;
    let summary = write_folder_atomically(&a.out, a.force, |tmp| {
        std::fs::create_dir_all(tmp.join("images")).map_err(|e| tubeloc_core::CoreError::io(tmp, e))?;
        let samples: Vec<_> = jobs
            .par_iter()
            .enumerate()
            .map(|(i, &(v, k))| {
                let s = render_sample(&views[v], k, i as u64 + 1, &cfg)?;
                if let Some(s) = &s {
                    files::write_atomic(&tmp.join("images").join(&s.file_name), &s.bytes)?;
                }
                pb.inc(1);
                Ok(s.map(|s| (s.image, s.annotations)))
            })
            .collect::<Result<Vec<_>, tubeloc_synth::SynthError>>()?;
        let samples: Vec<_> = samples.into_iter().flatten().collect();
        let mut info = json!({"description": "tubeloc composites on real rover frames", "split": a.split.name(), "seed": a.seed, "range_m": [range.0, range.1]});
        if a.colour_as_grey {
            info["colour_as_grey"] = json!("red channel, tubes in 600-800 nm");
        }
        if a.split == RealSplit::Train {
            info["hfov_deg"] = json!([a.hfov_deg.0, a.hfov_deg.1]);
        }
        let ds = assemble(samples, info);
        files::write_json(&tmp.join("annotations.json"), &ds)?;
        spread = tubeloc_synth::real_set::tube_spread(&ds);
        Ok((ds.images.len(), ds.annotations.len()))
    })?;
    pb.finish_and_clear();
    eprintln!("{} composites, {} tubes ({} frames, {} skipped where the range band is not in view) -> {}", summary.images, summary.annotations, views.len(), jobs.len() - summary.images, summary.out.display());
    if let Some(t) = spread {
        let [r, w] = [t.range_m, t.width_px];
        eprintln!("tubes at {:.1} / {:.1} / {:.1} m from the camera, {:.1} / {:.1} / {:.1} px wide (p10 / median / p90)", r[0], r[1], r[2], w[0], w[1], w[2]);
    }
    Ok((summary.images, summary.annotations))
}
