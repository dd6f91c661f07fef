//! `tubeloc synth stereo`: render stereo pairs of benchmark scenes with exact disparity.

use anyhow::{bail, Context, Result};
use clap::Args;
use std::path::PathBuf;
use tubeloc_synth::stereo_set::{write_stereo_set, StereoSetSpec};

/// Arguments of `tubeloc synth stereo`.
#[derive(Args)]
pub struct SynthStereoArgs {
    /// Output folder: annotations.json, images/ (left), right/, disparity/*.pfm, rig.json.
    #[arg(long)]
    pub out: PathBuf,
    /// Scene preset (terrains, times, terrain size): `paper` or `tiny`.
    #[arg(long, default_value = "paper")]
    pub preset: String,
    /// Number of scenes (cycles through the preset's terrains and times).
    #[arg(long, value_parser = crate::args::positive_usize)]
    pub scenes: Option<usize>,
    /// Stereo pairs per scene.
    #[arg(long, default_value_t = 4, value_parser = crate::args::positive_usize)]
    pub pairs_per_scene: usize,
    /// Crop side in pixels (the preset's by default: 1024 for paper).
    #[arg(long, value_parser = crate::args::positive_u32)]
    pub resolution: Option<u32>,
    /// Render scale relative to the native 5472x3648 cameras (the preset's by default).
    #[arg(long, value_parser = crate::args::positive_f64)]
    pub scale: Option<f64>,
    /// Master seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Rig pair `LEFT,RIGHT`: `L20,R20` (20 cm baseline) or `L40,R40` (40 cm).
    #[arg(long, default_value = "L20,R20")]
    pub pair: String,
    /// Replace an existing output folder.
    #[arg(long)]
    pub force: bool,
}

/// Runs `tubeloc synth stereo`.
pub fn run(a: SynthStereoArgs) -> Result<()> {
    let Some((l, r)) = a.pair.split_once(',') else { bail!("--pair {:?}: expected LEFT,RIGHT, e.g. L20,R20", a.pair) };
    let base = crate::cmd_synth::preset_spec(&a.preset, a.seed, a.scenes, a.resolution, a.scale)?;
    let spec = StereoSetSpec { base, pair: (l.trim().to_string(), r.trim().to_string()), pairs_per_scene: a.pairs_per_scene };
    let total = spec.base.scenes.len() * spec.pairs_per_scene;
    let bar = indicatif::ProgressBar::new(total as u64);
    bar.set_style(indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} pairs  {elapsed_precise} (eta {eta})").unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()));
    let t0 = std::time::Instant::now();
    let summary = write_stereo_set(&spec, &a.out, a.force, &|done, _| bar.set_position(done as u64)).with_context(|| format!("writing stereo set {}", a.out.display()))?;
    bar.finish_and_clear();
    crate::out::outln!("{}: {} pairs, {} annotations in {:.1} s", summary.out.display(), summary.images, summary.annotations, t0.elapsed().as_secs_f64());
    Ok(())
}
