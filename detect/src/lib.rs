//! tubeloc-detect (see the README for what this crate owns).

pub mod input;
pub mod learned;
pub mod line2d;
pub mod scale;
