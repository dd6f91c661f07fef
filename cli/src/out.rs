//! Printing to stdout without panicking when it is closed.
//!
//! `println!` panics ("failed printing to stdout: Broken pipe") when the reader of a pipe has
//! gone (`tubeloc eval ... | head -2`). [`outln!`] and [`out!`] write the same text but ignore
//! a broken pipe, so the command still finishes its work, writes its files and exits 0; any
//! other write error is reported once on stderr. Use them for every line a subcommand prints.

use std::io::Write;
use std::sync::atomic::{AtomicBool, Ordering};

static REPORTED: AtomicBool = AtomicBool::new(false);

/// Writes formatted text to stdout; a closed stdout is ignored (see the module doc).
pub fn write_stdout(args: std::fmt::Arguments) {
    let mut stdout = std::io::stdout().lock();
    if let Err(e) = stdout.write_fmt(args) {
        if e.kind() != std::io::ErrorKind::BrokenPipe && !REPORTED.swap(true, Ordering::Relaxed) {
            eprintln!("warning: cannot write to stdout: {e}");
        }
    }
}

/// `println!` that does not panic on a closed stdout.
macro_rules! outln {
    () => {
        $crate::out::write_stdout(format_args!("\n"))
    };
    ($($arg:tt)*) => {
        $crate::out::write_stdout(format_args!("{}\n", format_args!($($arg)*)))
    };
}

/// `print!` that does not panic on a closed stdout.
macro_rules! out {
    ($($arg:tt)*) => {
        $crate::out::write_stdout(format_args!($($arg)*))
    };
}

pub(crate) use {out, outln};
