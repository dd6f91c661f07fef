//! `tubeloc synth calib`: render a synthetic calibration set (tag board seen by a rig).

use anyhow::{Context, Result};
use clap::Args;
use std::path::PathBuf;
use tubeloc_synth::calib_set::{default_rig, generate, write_calib_set, BoardLayout, CalibSetConfig};

/// Arguments of `tubeloc synth calib`.
#[derive(Args)]
pub struct SynthCalibArgs {
    /// Rig file to simulate (tubeloc JSON, OpenCV YAML or kalibr camchain).
    #[arg(long, conflicts_with = "default_rig")]
    pub rig: Option<PathBuf>,
    /// Use the shipped default rig (data/rig_default.json: paper geometry, mild distortion).
    #[arg(long)]
    pub default_rig: bool,
    /// Number of board poses.
    #[arg(long, default_value_t = 30, value_parser = crate::args::positive_usize)]
    pub views: usize,
    /// Output folder.
    #[arg(long)]
    pub out: PathBuf,
    /// Seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Gaussian noise added to each corner coordinate of the `noisy` corners, pixels.
    #[arg(long, default_value_t = 0.2, value_parser = crate::args::non_negative_f64)]
    pub noise: f64,
    /// Grey-level noise of the rendered images.
    #[arg(long, default_value_t = 2.0, value_parser = crate::args::non_negative_f64)]
    pub image_noise: f64,
    /// Image scale relative to the rig's native size.
    #[arg(long, default_value_t = 0.25, value_parser = crate::args::positive_f64)]
    pub scale: f64,
    /// Write corners only (no images).
    #[arg(long)]
    pub no_images: bool,
}

/// Runs `tubeloc synth calib`.
pub fn run(a: SynthCalibArgs) -> Result<()> {
    let rig = match &a.rig {
        Some(p) => tubeloc_calib::read_rig(p)?,
        None => default_rig(),
    };
    let cfg = CalibSetConfig { views: a.views, seed: a.seed, corner_noise_px: a.noise, image_noise: a.image_noise, scale: a.scale, render: !a.no_images, ..Default::default() };
    let set = generate(&rig, &BoardLayout::default_board(), &cfg)?;
    let n: usize = set.views.iter().map(|v| v.observations.len()).sum();
    let bar = indicatif::ProgressBar::new(if cfg.render { n as u64 } else { 0 });
    write_calib_set(&a.out, &set, || bar.inc(1)).with_context(|| format!("writing {}", a.out.display()))?;
    bar.finish_and_clear();
    crate::out::outln!("{}: {} views, {n} images/observations", a.out.display(), set.views.len());
    Ok(())
}
