//! tubeloc-eval (see the README for what this crate owns).
