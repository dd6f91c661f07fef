//! tubeloc-stereo (see the README for what this crate owns).
