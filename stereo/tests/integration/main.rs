//! Integration tests of `tubeloc-stereo`, one module per subject in one test binary
//! (built and linked once). One subject: `cargo test --release -p tubeloc-stereo --test integration
//! <module>::`.

mod middlebury;
mod rectify;
mod synth_pairs;
mod synthetic;
