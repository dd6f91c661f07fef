//! Helpers shared by the CLI test files: run the `tubeloc` binary and read its output.
#![allow(dead_code)] // each test file uses a part

use std::path::Path;
use std::process::{Command, Output};

/// Runs `tubeloc` with `args`, capturing its output.
pub fn tubeloc(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tubeloc")).args(args).output().expect("running tubeloc")
}

/// Runs `tubeloc` and asserts it succeeded (the message quotes its stderr).
pub fn ok(args: &[&str]) -> Output {
    let o = tubeloc(args);
    assert!(o.status.success(), "tubeloc {} failed: {}", args.join(" "), String::from_utf8_lossy(&o.stderr));
    o
}

/// The run's stderr as text.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A path as a command-line argument.
pub fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}
