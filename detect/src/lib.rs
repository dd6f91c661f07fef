//! tubeloc-detect (see the README for what this crate owns).
#![warn(missing_docs)]

pub mod input;
pub mod learned;
pub mod line2d;
pub mod pds3_image;
pub mod scale;
