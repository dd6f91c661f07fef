//! tubeloc-synth (see the README for what this crate owns).
