//! `tubeloc`: the command-line program. It wires the library crates together, reads and writes
//! files and draws progress bars; all computation lives in the libraries.

use clap::{Parser, Subcommand};
use std::process::ExitCode;

// One module per subcommand: `cmd_<name>.rs` holds its clap arguments and `run`.
mod cmd_eval;
mod cmd_stereo;
mod cmd_refine;
mod cmd_synth;
mod cmd_synth_calib;
mod cmd_synth_composite;

/// tubeloc: find Mars sample tubes in rover camera images and return grasp-ready 6D tube poses.
#[derive(Parser)]
#[command(name = "tubeloc", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    // Subcommands are registered here, one variant each.
    /// Stereo disparity (semi-global matching), optional rectification with a rig and point cloud.
    Stereo(cmd_stereo::StereoArgs),
    /// Refine detections into grasp-ready tube poses (cylinder contour fit, optional stereo and ground plane).
    Refine(cmd_refine::RefineArgs),
    /// Evaluate COCO results against ground truth (AP/AR exactly as pycocotools), with breakdowns.
    Eval(cmd_eval::EvalArgs),
    /// Render the synthetic Mars-yard benchmark (COCO ground truth, poses, rig), composites or calibration sets.
    Synth(cmd_synth::SynthArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result: anyhow::Result<()> = match cli.command {
        // Dispatch: one arm per subcommand.
        Command::Stereo(a) => cmd_stereo::run(a),
        Command::Refine(a) => cmd_refine::run(a),
        Command::Eval(a) => cmd_eval::run(a),
        Command::Synth(a) => cmd_synth::run(a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(1)
        }
    }
}
