//! tubeloc-eval (see the README for what this crate owns).
pub mod coco_eval;
pub mod pose;
pub mod pose_bop;
pub mod pose_match;
pub mod pose_summary;
pub mod plot;
pub mod plot_pr;
pub mod plot_hist;
pub mod plot_bar;
pub mod report;
