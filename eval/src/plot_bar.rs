//! Grouped bar charts: one group per category (e.g. terrain type), one bar per series
//! (e.g. AP50 and AR), with category names under the groups.
//!
//! Category `i` is centred at x = i; the group spans 0.8 of the unit width, split evenly among
//! the series. Undefined values (non-finite or negative, such as COCO's -1) draw no bar.

use crate::plot::{draw_err, label_font, series_color, tick_font, title_font, Chart, PlotError};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

/// A grouped bar chart.
#[derive(Clone, Debug, PartialEq)]
pub struct BarChart {
    /// Chart title.
    pub title: String,
    /// Y axis description with its unit.
    pub y_label: String,
    /// Category names along x.
    pub categories: Vec<String>,
    /// `(series label, one value per category)`.
    pub series: Vec<(String, Vec<f64>)>,
    /// Y range; `None` for `0 ..= 1.1 × max` (at least 1).
    pub y_range: Option<(f64, f64)>,
}

impl BarChart {
    /// A chart of `series` over `categories`, automatic y range.
    pub fn new(title: impl Into<String>, y_label: impl Into<String>, categories: Vec<String>, series: Vec<(String, Vec<f64>)>) -> Self {
        BarChart { title: title.into(), y_label: y_label.into(), categories, series, y_range: None }
    }
}

fn defined(v: f64) -> bool {
    v.is_finite() && v >= 0.0
}

impl Chart for BarChart {
    fn draw<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> Result<(), PlotError>
    where
        DB::ErrorType: 'static,
    {
        let n = self.categories.len();
        if n == 0 {
            return Err(PlotError::Data("bar chart without categories".into()));
        }
        if let Some((label, v)) = self.series.iter().find(|(_, v)| v.len() != n) {
            return Err(PlotError::Data(format!("bar series {label:?} has {} values for {n} categories", v.len())));
        }
        let max = self.series.iter().flat_map(|(_, v)| v.iter()).copied().filter(|&v| defined(v)).fold(0.0, f64::max);
        let (y0, y1) = self.y_range.unwrap_or((0.0, if max > 0.0 { max * 1.1 } else { 1.0 }));
        if !(y0.is_finite() && y1.is_finite() && y1 > y0) {
            return Err(PlotError::Data(format!("bar chart y range ({y0}, {y1}) is empty or not finite")));
        }
        area.fill(&WHITE).map_err(draw_err)?;
        let mut chart = ChartBuilder::on(area).caption(&self.title, title_font()).margin(16).margin_right(32).x_label_area_size(40).y_label_area_size(64).build_cartesian_2d(-0.5f64..(n as f64 - 0.5), y0..y1).map_err(draw_err)?;
        chart.configure_mesh().disable_x_mesh().x_labels(0).x_label_formatter(&|_| String::new()).y_desc(&self.y_label).axis_desc_style(label_font()).label_style(tick_font()).light_line_style(RGBColor(235, 235, 235)).draw().map_err(draw_err)?;
        let k = self.series.len().max(1) as f64;
        let bw = 0.8 / k;
        for (s, (label, values)) in self.series.iter().enumerate() {
            let color = series_color(s);
            chart
                .draw_series(values.iter().enumerate().filter(|(_, &v)| defined(v)).map(|(i, &v)| {
                    let x0 = i as f64 - 0.4 + s as f64 * bw;
                    Rectangle::new([(x0, y0), (x0 + bw * 0.95, v.min(y1))], color.filled())
                }))
                .map_err(draw_err)?
                .label(label.as_str())
                .legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 20, y + 6)], color.filled()));
        }
        // Category names under the groups, on the whole drawing area (the plot area clips).
        let style = tick_font().pos(Pos::new(HPos::Center, VPos::Top));
        let (bx, by) = area.get_base_pixel();
        for (i, name) in self.categories.iter().enumerate() {
            let (px, py) = chart.backend_coord(&(i as f64, y0));
            area.draw(&Text::new(name.as_str(), (px - bx, py - by + 8), style.clone())).map_err(draw_err)?;
        }
        if !self.series.is_empty() {
            chart.configure_series_labels().position(SeriesLabelPosition::UpperRight).label_font(tick_font()).background_style(WHITE.mix(0.85)).border_style(BLACK).draw().map_err(draw_err)?;
        }
        Ok(())
    }
}
