//! `tubeloc synth`: render a synthetic Mars-yard benchmark (COCO ground truth, poses, rig), or
//! with a nested subcommand a composite on a real photo or a calibration set.

use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand};
use std::path::PathBuf;
use std::sync::Arc;
use tubeloc_core::TubeMesh;
use tubeloc_synth::{write_dataset, DatasetSpec, TubeShape};

/// Arguments of `tubeloc synth`.
#[derive(Args)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct SynthArgs {
    /// Other synthetic outputs.
    #[command(subcommand)]
    pub command: Option<SynthCommand>,
    /// Dataset options (when no subcommand is given).
    #[command(flatten)]
    pub dataset: DatasetArgs,
}

/// Nested `tubeloc synth` subcommands.
#[derive(Subcommand)]
pub enum SynthCommand {
    /// Render synthetic tubes with shadows onto a real photograph of known camera and ground plane.
    Composite(crate::cmd_synth_composite::CompositeArgs),
    /// Composites of rendered tubes on the real rover frames of one split (by sol), as a COCO set.
    Real(crate::cmd_synth_real::RealArgs),
    /// Hard negatives for training: crops of the real backgrounds of one split (no tube in
    /// any) around a learned model's own confident detections, at each frame's working scale.
    Negatives(crate::cmd_synth_negatives::NegativesArgs),
    /// Render a calibration set: a tag board seen by a rig's cameras, with exact corners.
    Calib(crate::cmd_synth_calib::SynthCalibArgs),
    /// Render stereo pairs (both cameras of a rig pair, same crop) with exact disparity maps.
    Stereo(crate::cmd_synth_stereo::SynthStereoArgs),
}

/// Options of the benchmark dataset.
#[derive(Args)]
pub struct DatasetArgs {
    /// Preset: `paper` (824 images at half resolution, 1024x1024 crops) or `tiny` (tests).
    #[arg(long, default_value = "paper")]
    pub preset: String,
    /// Output folder (written atomically: <out>.tmp-<pid>, renamed at the end).
    #[arg(long, required = true)]
    pub out: Option<PathBuf>,
    /// Number of scenes (cycles through the preset's terrains and times).
    #[arg(long, value_parser = crate::args::positive_usize)]
    pub scenes: Option<usize>,
    /// Crop side in pixels (the preset's by default: 1024 for paper).
    #[arg(long, value_parser = crate::args::positive_u32)]
    pub resolution: Option<u32>,
    /// Render scale relative to the native 5472x3648 cameras (0.5 for paper).
    #[arg(long, value_parser = crate::args::positive_f64)]
    pub scale: Option<f64>,
    /// Master seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Tube geometry from an OBJ mesh (metres, axis +z, material groups) instead of data/tube.toml.
    #[arg(long)]
    pub tube_mesh: Option<PathBuf>,
    /// Render only shard I of N (scenes s with s % N == I), e.g. `--shard 0/4`.
    #[arg(long, default_value = "0/1", value_parser = crate::args::shard)]
    pub shard: (usize, usize),
    /// Replace an existing output folder.
    #[arg(long)]
    pub force: bool,
}

/// Runs `tubeloc synth`.
pub fn run(a: SynthArgs) -> Result<()> {
    match a.command {
        Some(SynthCommand::Composite(c)) => crate::cmd_synth_composite::run(c),
        Some(SynthCommand::Real(c)) => crate::cmd_synth_real::run(c),
        Some(SynthCommand::Negatives(c)) => crate::cmd_synth_negatives::run(c),
        Some(SynthCommand::Calib(c)) => crate::cmd_synth_calib::run(c),
        Some(SynthCommand::Stereo(c)) => crate::cmd_synth_stereo::run(c),
        None => run_dataset(a.dataset),
    }
}

/// A preset's dataset spec with the command line's overrides: scene count, crop side (px) and
/// render scale.
pub(crate) fn preset_spec(preset: &str, seed: u64, scenes: Option<usize>, crop: Option<u32>, scale: Option<f64>) -> Result<DatasetSpec> {
    let mut spec = DatasetSpec::preset(preset, seed)?;
    if let Some(n) = scenes {
        spec = spec.with_scenes(n)?;
    }
    if let Some(r) = crop {
        spec.crop = r;
    }
    if let Some(s) = scale {
        spec.scale = s;
    }
    Ok(spec)
}

/// Renders the dataset described by `a` (`tubeloc synth` without a subcommand).
pub(crate) fn run_dataset(a: DatasetArgs) -> Result<()> {
    let Some(out) = a.out.clone() else { bail!("--out DIR is required") };
    let shard = a.shard;
    let mut spec = preset_spec(&a.preset, a.seed, a.scenes, a.resolution, a.scale)?;
    if let Some(p) = &a.tube_mesh {
        let mesh = TubeMesh::load_obj(p).with_context(|| format!("reading tube mesh {}", p.display()))?;
        spec.tube_shape = Arc::new(TubeShape::from_mesh(&mesh));
        spec.tube_source = format!("mesh {}", p.display());
    }
    spec.validate()?;
    let total: usize = (0..spec.scenes.len()).filter(|s| s % shard.1 == shard.0).map(|s| spec.scenes[s].images).sum();
    let bar = indicatif::ProgressBar::new(total as u64);
    bar.set_style(indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} images  {elapsed_precise} (eta {eta})").unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()));
    let t0 = std::time::Instant::now();
    let summary = write_dataset(&spec, &out, shard, a.force, &|done, _| bar.set_position(done as u64)).with_context(|| format!("writing dataset {}", out.display()))?;
    bar.finish_and_clear();
    crate::out::outln!("{}: {} images, {} annotations in {:.1} s", summary.out.display(), summary.images, summary.annotations, t0.elapsed().as_secs_f64());
    Ok(())
}
