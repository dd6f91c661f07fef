//! Integration tests of `tubeloc-detect`, one module per subject in one test binary
//! (built and linked once). One subject: `cargo test --release -p tubeloc-detect --test integration
//! <module>::`.

mod learned;
mod library_estimate;
mod line2d;
mod model_bytes;
mod pds3_products;
