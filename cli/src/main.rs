//! `tubeloc`: the command-line program. It wires the library crates together, reads and writes
//! files and draws progress bars; all computation lives in the libraries.

use clap::{Parser, Subcommand};
use std::process::ExitCode;

// One module per subcommand: `cmd_<name>.rs` holds its clap arguments and `run`.
pub(crate) mod args;
mod bench_grasp;
mod bench_intervals;
mod bench_negatives;
mod bench_sols;
mod bench_widths;
mod cmd_bench;
mod cmd_bench_real;
mod cmd_calib;
mod cmd_demo;
mod cmd_detect;
mod cmd_detect_learned;
mod cmd_detect_line2d;
mod cmd_eval;
mod cmd_line2d_verifier;
mod cmd_locate;
mod cmd_refine;
mod cmd_stereo;
mod cmd_synth;
mod cmd_synth_calib;
mod cmd_synth_composite;
mod cmd_synth_negatives;
mod cmd_synth_real;
mod cmd_synth_stereo;
mod cmd_templates;
mod cmd_train;
mod detect_dataset;
mod figures;
mod memory;
pub(crate) mod out;

/// tubeloc: find Mars sample tubes in rover camera images and return grasp-ready 6D tube poses.
#[derive(Parser)]
#[command(name = "tubeloc", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
#[allow(clippy::large_enum_variant)] // parsed once; boxing the arguments buys nothing
enum Command {
    // Subcommands are registered here, one variant each.
    /// AprilTag detection, tag-pair ground-truth tube poses, and camera-rig calibration.
    #[command(subcommand)]
    Calib(cmd_calib::CalibCommand),
    /// Detect tubes in images (line2d, learned or external results) and write COCO results with seeds.
    Detect(cmd_detect::DetectArgs),
    /// Build or inspect Line2D template libraries rendered from the tube model.
    Templates(cmd_templates::TemplatesArgs),
    /// Evaluate COCO results against ground truth (AP/AR exactly as pycocotools), with breakdowns.
    Eval(cmd_eval::EvalArgs),
    /// Train the learned tube segmenter on COCO dataset directories.
    Train(cmd_train::TrainArgs),
    /// Render the synthetic Mars-yard benchmark (COCO ground truth, poses, rig), composites or calibration sets.
    Synth(cmd_synth::SynthArgs),
    /// Stereo disparity (semi-global matching), optional rectification with a rig and point cloud.
    Stereo(cmd_stereo::StereoArgs),
    /// Refine detections into grasp-ready tube poses (cylinder contour fit, optional stereo and ground plane).
    Refine(cmd_refine::RefineArgs),
    /// Run the whole pipeline on a small generated with-tags scene and write a report (no arguments needed).
    Demo(cmd_demo::DemoArgs),
    /// The main job: detect, (stereo,) refine and write grasp-ready tube poses for one image or pair, or a sharded batch of frames.
    Locate(cmd_locate::LocateArgs),
    /// Reproduce the paper's experiments on the paper preset and write a markdown report with plots.
    Bench(cmd_bench::BenchArgs),
}

/// Runs one parsed subcommand; returns the process exit code of a successful run.
fn dispatch(command: Command) -> anyhow::Result<u8> {
    let done = match command {
        // Dispatch: one arm per subcommand.
        Command::Calib(c) => cmd_calib::run(c),
        Command::Detect(a) => cmd_detect::run(a),
        Command::Templates(a) => cmd_templates::run(a),
        Command::Eval(a) => cmd_eval::run(a),
        Command::Train(a) => cmd_train::run(a),
        Command::Synth(a) => cmd_synth::run(a),
        Command::Stereo(a) => cmd_stereo::run(a),
        Command::Refine(a) => cmd_refine::run(a),
        Command::Demo(a) => cmd_demo::run(a),
        Command::Locate(a) => return cmd_locate::run(a),
        Command::Bench(a) => cmd_bench::run(a),
    };
    done.map(|()| 0)
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    // Per-tube buffers are reused rather than mapped and returned to the kernel each time.
    tubeloc_core::heap::keep_freed_memory();
    let result = dispatch(cli.command);
    match result {
        Ok(code) => ExitCode::from(code),
        Err(e) => match e.downcast_ref::<clap::Error>() {
            // A command-line error found after parsing (`args::usage`): exit 2, as clap's own.
            Some(usage) => {
                let _ = usage.print();
                ExitCode::from(2)
            }
            None => {
                eprintln!("error: {e:#}");
                ExitCode::from(1)
            }
        },
    }
}

#[cfg(test)]
mod tests {
    use clap::CommandFactory;

    /// Every argument's relations (conflicts, requirements, groups) name arguments that exist,
    /// whatever the build profile (clap checks them itself only in debug builds).
    #[test]
    fn the_command_line_definition_is_consistent() {
        super::Cli::command().debug_assert();
    }
}
