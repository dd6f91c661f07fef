//! Integration tests of the `tubeloc` command line (most run the built binary), one module
//! per subject in one test binary (built and linked once). One subject:
//! `cargo test --release -p tubeloc --test integration <module>::`.

mod batch;
mod calib_interchange;
mod cli;
mod common;
mod fisheye_products;
mod fused_detection;
mod hardening;
mod install_anywhere;
mod locate_outputs;
mod pose_evidence;
mod pose_verified_line2d;
mod real_imagery;
mod refine_stereo;
