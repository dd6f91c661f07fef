//! Error histograms with several series overlaid (e.g. coarse / mono / stereo poses).
//!
//! Bins are `bins` equal intervals over `[lo, hi)`; `hi` defaults to the largest value of all
//! series (or 1 when there is none) and `lo` to 0. A value `>= hi` is counted in the last bin
//! (so outliers stay visible); values below `lo` or non-finite are dropped. Each series is
//! drawn as translucent bars with an opaque outline, bar heights are counts.

use crate::plot::{draw_err, label_font, series_color, tick_font, title_font, Chart, PlotError};
use plotters::coord::Shift;
use plotters::prelude::*;

/// One data series of a histogram.
#[derive(Clone, Debug, PartialEq)]
pub struct HistSeries {
    /// Legend label.
    pub label: String,
    /// Values, in the unit of the x axis.
    pub values: Vec<f64>,
}

/// Overlaid histograms.
#[derive(Clone, Debug, PartialEq)]
pub struct Histogram {
    /// Chart title.
    pub title: String,
    /// X axis description with its unit, e.g. `axis angle error (deg)`.
    pub x_label: String,
    /// Series to overlay.
    pub series: Vec<HistSeries>,
    /// Number of bins (at least 1).
    pub bins: usize,
    /// Bin range `(lo, hi)`; `None` for `(0, max)`.
    pub range: Option<(f64, f64)>,
}

impl Histogram {
    /// A histogram of `series` with 20 bins over `(0, max)`.
    pub fn new(title: impl Into<String>, x_label: impl Into<String>, series: Vec<HistSeries>) -> Self {
        Histogram { title: title.into(), x_label: x_label.into(), series, bins: 20, range: None }
    }

    /// The bin range actually used.
    pub fn bin_range(&self) -> (f64, f64) {
        if let Some(r) = self.range {
            return r;
        }
        let max = self.series.iter().flat_map(|s| s.values.iter()).copied().filter(|v| v.is_finite()).fold(f64::NEG_INFINITY, f64::max);
        let hi = if max.is_finite() && max > 0.0 { max * 1.0001 } else { 1.0 };
        (0.0, hi)
    }

    /// Counts per bin of one series (rule in the module documentation).
    pub fn counts(&self, values: &[f64]) -> Vec<u64> {
        let (lo, hi) = self.bin_range();
        let n = self.bins.max(1);
        let mut c = vec![0u64; n];
        for &v in values {
            if !v.is_finite() || v < lo {
                continue;
            }
            let k = (((v - lo) / (hi - lo)) * n as f64).floor() as usize;
            c[k.min(n - 1)] += 1;
        }
        c
    }
}

impl Chart for Histogram {
    fn draw<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> Result<(), PlotError>
    where
        DB::ErrorType: 'static,
    {
        let (lo, hi) = self.bin_range();
        if !(lo.is_finite() && hi.is_finite() && hi > lo) {
            return Err(PlotError::Data(format!("histogram range ({lo}, {hi}) is empty or not finite")));
        }
        let n = self.bins.max(1);
        let counts: Vec<Vec<u64>> = self.series.iter().map(|s| self.counts(&s.values)).collect();
        let ymax = counts.iter().flatten().copied().max().unwrap_or(0).max(1) as f64 * 1.1;
        area.fill(&WHITE).map_err(draw_err)?;
        let mut chart = ChartBuilder::on(area).caption(&self.title, title_font()).margin(16).margin_right(32).x_label_area_size(50).y_label_area_size(64).build_cartesian_2d(lo..hi, 0.0..ymax).map_err(draw_err)?;
        chart.configure_mesh().x_desc(&self.x_label).y_desc("count").axis_desc_style(label_font()).label_style(tick_font()).y_label_formatter(&|y| format!("{y:.0}")).light_line_style(RGBColor(235, 235, 235)).draw().map_err(draw_err)?;
        let w = (hi - lo) / n as f64;
        for (i, (s, c)) in self.series.iter().zip(&counts).enumerate() {
            let color = series_color(i);
            chart
                .draw_series(c.iter().enumerate().filter(|(_, &k)| k > 0).map(|(b, &k)| {
                    let x0 = lo + b as f64 * w;
                    Rectangle::new([(x0, 0.0), (x0 + w, k as f64)], color.mix(0.35).filled())
                }))
                .map_err(draw_err)?;
            // Outline as a step line over all bins.
            let mut step = vec![(lo, 0.0)];
            for (b, &k) in c.iter().enumerate() {
                let x0 = lo + b as f64 * w;
                step.push((x0, k as f64));
                step.push((x0 + w, k as f64));
            }
            step.push((hi, 0.0));
            chart
                .draw_series(LineSeries::new(step, color.stroke_width(2)))
                .map_err(draw_err)?
                .label(format!("{} (n={})", s.label, s.values.iter().filter(|v| v.is_finite()).count()))
                .legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 20, y + 6)], color.mix(0.6).filled()));
        }
        if !self.series.is_empty() {
            chart.configure_series_labels().position(SeriesLabelPosition::UpperRight).label_font(tick_font()).background_style(WHITE.mix(0.85)).border_style(BLACK).draw().map_err(draw_err)?;
        }
        Ok(())
    }
}
