//! Integration tests of `tubeloc-eval`, one module per subject in one test binary
//! (built and linked once). One subject: `cargo test --release -p tubeloc-eval --test integration
//! <module>::`.

mod coco_eval;
mod coco_parity;
mod common;
mod plot_charts;
mod plot_report;
mod pose_evaluation;
mod pose_metrics;
