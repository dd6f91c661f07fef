//! Integration tests of `tubeloc-core`, one module per subject in one test binary
//! (built and linked once). One subject: `cargo test --release -p tubeloc-core --test integration
//! <module>::`.

mod coco_io;
mod fuzz_regressions;
mod mask_rle;
mod output_paths;
