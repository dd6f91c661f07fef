//! Integration tests of `tubeloc-refine`, one module per subject in one test binary
//! (built and linked once). One subject: `cargo test --release -p tubeloc-refine --test integration
//! <module>::`.

mod common;
mod photo;
mod refine;
mod settings;
mod two_view;
