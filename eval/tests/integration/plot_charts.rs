//! Plots: PNGs decode with the right size and visible content, SVGs carry the legend text.
//! Set `TUBELOC_PLOT_OUT=/some/dir` to keep the files for a look.

use std::path::{Path, PathBuf};
use tubeloc_eval::plot::{save, save_png_svg, Chart, PlotError};
use tubeloc_eval::plot_bar::BarChart;
use tubeloc_eval::plot_hist::{HistSeries, Histogram};
use tubeloc_eval::plot_pr::{curve_ap, legend_label, PrCurves};

fn out_dir(tmp: &Path) -> PathBuf {
    std::env::var_os("TUBELOC_PLOT_OUT").map(PathBuf::from).unwrap_or_else(|| tmp.to_path_buf())
}

/// Checks a PNG: decodes, has `size`, and its plot area (inner 60%) has inked (lines, bars) and
/// light (background) pixels;
/// returns the number of distinct colours.
fn check_png(path: &Path, size: (u32, u32)) -> usize {
    let img = image::open(path).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), size);
    let (w, h) = size;
    let (mut dark, mut light) = (0, 0);
    let mut colours = std::collections::HashSet::new();
    for y in h / 5..h * 4 / 5 {
        for x in w / 5..w * 4 / 5 {
            let p = img.get_pixel(x, y).0;
            let l = (p[0] as u32 + p[1] as u32 + p[2] as u32) / 3;
            dark += (l < 170) as u32;
            light += (l > 200) as u32;
            colours.insert(p);
        }
    }
    assert!(dark > 50 && light > 1000, "{}: dark {dark}, light {light}", path.display());
    colours.len()
}

fn pr_data() -> Vec<(f64, [f64; 101])> {
    (0..10)
        .map(|k| {
            let iou = 0.5 + 0.05 * k as f64;
            let mut p = [0.0; 101];
            let reach = 1.0 - 0.08 * k as f64; // higher IoU reaches less recall
            for (i, v) in p.iter_mut().enumerate() {
                let r = i as f64 / 100.0;
                *v = if r <= reach { 1.0 - 0.3 * (r / reach).powi(3) } else { 0.0 };
            }
            (iou, p)
        })
        .collect()
}

#[test]
fn pr_curves_png_and_svg() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = out_dir(tmp.path());
    let mut data = pr_data();
    data[9].1 = [-1.0; 101]; // undefined curve: skipped, legend says n/a
    let chart = PrCurves::new("Line2D, no-tags", &data);
    let (png, svg) = save_png_svg(&chart, &dir.join("pr_curves"), (900, 700)).unwrap();
    let colours = check_png(&png, (900, 700));
    assert!(colours > 10, "only {colours} colours: curves missing?");
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.starts_with("<svg") || text.contains("<svg"));
    assert!(text.contains(&legend_label(data[0].0, &data[0].1)), "legend of the first curve missing");
    assert!(text.contains("IoU=0.95 (AP n/a)"));
    assert!(text.contains("Recall") && text.contains("Precision"));
}

#[test]
fn curve_ap_skips_undefined_points() {
    let mut p = [0.5; 101];
    assert_eq!(curve_ap(&p), Some(0.5));
    p[..51].fill(1.0);
    p[51..].fill(-1.0);
    assert_eq!(curve_ap(&p), Some(1.0));
    assert_eq!(legend_label(0.5, &p), "IoU=0.50 (AP 1.000)");
    assert_eq!(curve_ap(&[-1.0; 101]), None);
}

#[test]
fn overlaid_histograms() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = out_dir(tmp.path());
    let series = |label: &str, scale: f64, n: usize| HistSeries { label: label.into(), values: (0..n).map(|i| scale * ((i * 7919 % 101) as f64 / 100.0).powi(2) * 10.0).collect() };
    let h = Histogram::new("Axis angle error", "axis angle error (deg)", vec![series("coarse", 1.0, 300), series("mono", 0.4, 300), series("stereo", 0.2, 300)]);
    // Bin counts: every finite value is counted once, outliers in the last bin.
    assert_eq!(h.counts(&h.series[0].values).iter().sum::<u64>(), 300);
    let mut h2 = h.clone();
    h2.range = Some((0.0, 2.0));
    let c = h2.counts(&[0.0, 0.05, 1.99, 5.0, -1.0, f64::NAN]);
    assert_eq!((c[0], c[19], c.iter().sum::<u64>()), (2, 2, 4));
    let (png, svg) = save_png_svg(&h, &dir.join("hist_axis"), (800, 600)).unwrap();
    check_png(&png, (800, 600));
    let text = std::fs::read_to_string(svg).unwrap();
    assert!(text.contains("stereo (n=300)") && text.contains("axis angle error (deg)"));
}

#[test]
fn grouped_bar_chart() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = out_dir(tmp.path());
    let cats: Vec<String> = ["flat", "bedrock", "sand", "rocks"].iter().map(|s| s.to_string()).collect();
    let b = BarChart::new("AP50 and AR by terrain", "score", cats, vec![("AP50".into(), vec![0.8, 0.6, 0.7, -1.0]), ("AR".into(), vec![0.5, 0.45, 0.52, 0.3])]);
    let (png, svg) = save_png_svg(&b, &dir.join("bars_terrain"), (800, 500)).unwrap();
    check_png(&png, (800, 500));
    let text = std::fs::read_to_string(svg).unwrap();
    assert!(text.contains("bedrock") && text.contains("AP50") && text.contains("AR"));
    // Mismatched series length and a bad extension give clear errors.
    let bad = BarChart::new("t", "y", vec!["a".into()], vec![("s".into(), vec![1.0, 2.0])]);
    let err = save(&bad, &dir.join("bad.png"), (400, 300)).unwrap_err().to_string();
    assert!(err.contains("\"s\" has 2 values for 1 categories"), "{err}");
    assert!(matches!(save(&b, &dir.join("x.jpg"), (400, 300)), Err(PlotError::Format(_))));
}

#[test]
fn charts_render_to_memory_deterministically() {
    let chart = PrCurves::new("t", &pr_data());
    let a = tubeloc_eval::plot::render_png(&chart, (400, 300)).unwrap();
    let b = tubeloc_eval::plot::render_png(&chart, (400, 300)).unwrap();
    assert_eq!(a, b);
    fn _is_chart<C: Chart>(_: &C) {}
    _is_chart(&chart);
}
