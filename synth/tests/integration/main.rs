//! Integration tests of `tubeloc-synth`, one module per subject in one test binary
//! (built and linked once). One subject: `cargo test --release -p tubeloc-synth --test integration
//! <module>::`.

mod dataset;
mod ground_truth;
mod nominal_ground;
mod stale_temporaries;
