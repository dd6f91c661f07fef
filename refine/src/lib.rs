//! tubeloc-refine (see the README for what this crate owns).
