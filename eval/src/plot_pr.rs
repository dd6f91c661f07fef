//! Precision-recall curves at several IoU thresholds on one chart, like the paper's figures.
//!
//! Input is plain data: for each IoU threshold, COCO's 101 interpolated precisions at recall
//! `r_i = i / 100`, `i = 0..=100`, with -1 meaning undefined (skipped). The legend gives each
//! curve's AP, the mean of its defined precisions (as pycocotools averages `precision > -1`).

use crate::plot::{draw_err, label_font, series_color, tick_font, title_font, Chart, PlotError};
use plotters::coord::Shift;
use plotters::prelude::*;

/// The PR-curve chart.
#[derive(Clone, Debug, PartialEq)]
pub struct PrCurves {
    /// Chart title.
    pub title: String,
    /// `(IoU threshold, precision at the 101 recall points)`; -1 = undefined.
    pub curves: Vec<(f64, [f64; 101])>,
}

/// AP of one curve: mean of the defined (`> -1`) precisions; `None` when none is defined.
pub fn curve_ap(precision: &[f64; 101]) -> Option<f64> {
    let v: Vec<f64> = precision.iter().copied().filter(|&p| p > -1.0 && p.is_finite()).collect();
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

/// Legend text of a curve: `IoU=0.50 (AP 0.812)` or `IoU=0.50 (AP n/a)`.
pub fn legend_label(iou: f64, precision: &[f64; 101]) -> String {
    match curve_ap(precision) {
        Some(ap) => format!("IoU={iou:.2} (AP {ap:.3})"),
        None => format!("IoU={iou:.2} (AP n/a)"),
    }
}

impl PrCurves {
    /// A chart from plain data, like `&[(0.5, precisions), ...]`.
    pub fn new(title: impl Into<String>, curves: &[(f64, [f64; 101])]) -> Self {
        PrCurves { title: title.into(), curves: curves.to_vec() }
    }
}

impl Chart for PrCurves {
    fn draw<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> Result<(), PlotError>
    where
        DB::ErrorType: 'static,
    {
        if self.curves.iter().any(|(t, p)| !t.is_finite() || p.iter().any(|v| !v.is_finite())) {
            return Err(PlotError::Data("PR curves: non-finite IoU threshold or precision".into()));
        }
        area.fill(&WHITE).map_err(draw_err)?;
        let mut chart = ChartBuilder::on(area).caption(&self.title, title_font()).margin(16).margin_right(32).x_label_area_size(50).y_label_area_size(64).build_cartesian_2d(0.0f64..1.0, 0.0f64..1.02).map_err(draw_err)?;
        chart
            .configure_mesh()
            .x_desc("Recall")
            .y_desc("Precision")
            .axis_desc_style(label_font())
            .label_style(tick_font())
            .x_labels(11)
            .y_labels(11)
            .x_label_formatter(&|x| format!("{x:.1}"))
            .y_label_formatter(&|y| format!("{y:.1}"))
            .light_line_style(RGBColor(235, 235, 235))
            .draw()
            .map_err(draw_err)?;
        for (i, (iou, prec)) in self.curves.iter().enumerate() {
            let color = series_color(i);
            let pts: Vec<(f64, f64)> = prec.iter().enumerate().filter(|(_, &p)| p > -1.0).map(|(k, &p)| (k as f64 / 100.0, p)).collect();
            chart.draw_series(LineSeries::new(pts, color.stroke_width(2))).map_err(draw_err)?.label(legend_label(*iou, prec)).legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], color.stroke_width(3)));
        }
        chart.configure_series_labels().position(SeriesLabelPosition::LowerLeft).label_font(tick_font()).background_style(WHITE.mix(0.85)).border_style(BLACK).draw().map_err(draw_err)?;
        Ok(())
    }
}
