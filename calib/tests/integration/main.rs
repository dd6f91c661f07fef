//! Integration tests of `tubeloc-calib`, one module per subject in one test binary
//! (built and linked once). One subject: `cargo test --release -p tubeloc-calib --test integration
//! <module>::`.

mod calib_synthetic;
mod detect_real;
mod fuzz_regressions;
mod interchange;
mod interchange_peer;
mod odd_sizes;
mod opencv_peer;
mod opencv_yaml;
mod pds_labels;
mod render_detect;
mod tag_pair;
mod uncertainty;
