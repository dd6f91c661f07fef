//! tubeloc-calib (see the README for what this crate owns).
