//! Memory use of this process, for the figures `tubeloc locate` and `tubeloc bench` report.

/// Peak resident memory of this process so far, MiB (Linux `/proc/self/status` VmHWM).
pub fn peak_rss_mb() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}
