//! tubeloc-detect (see the README for what this crate owns).

pub mod learned;
pub mod input;
pub mod line2d;
pub mod scale;
