//! Markdown reports: a small builder ([`Report`], [`Table`]) and [`write_eval_report`], which
//! writes the report of a `tubeloc eval` run with its plots into one folder.
//!
//! Layout written by [`write_eval_report`] in `dir`:
//! `report.md`, `pr_curves.{png,svg}`, `breakdown_<attribute>.{png,svg}`,
//! `pose_<metric>.{png,svg}` and `pose_eval.json` (when pose evaluations are given).
//! The report links plots relatively, so the folder can be moved as a whole.

use crate::plot::{save_png_svg, PlotError};
use crate::plot_bar::BarChart;
use crate::plot_hist::{HistSeries, Histogram};
use crate::plot_pr::{curve_ap, PrCurves};
use crate::pose_summary::{PoseEvaluation, Summary};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Errors while writing a report.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// A plot failed (names the plot file).
    #[error("{path}: {source}")]
    Plot {
        /// Plot file stem.
        path: PathBuf,
        /// What failed.
        source: PlotError,
    },
    /// Writing a file failed.
    #[error(transparent)]
    Write(#[from] tubeloc_core::CoreError),
}

/// A markdown table; cells are escaped (`|` and newlines) when rendered.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Table {
    /// Column headers.
    pub headers: Vec<String>,
    /// Rows; short rows are padded with empty cells.
    pub rows: Vec<Vec<String>>,
}

fn escape(cell: &str) -> String {
    cell.replace('|', "\\|").replace(['\n', '\r'], " ")
}

impl Table {
    /// An empty table with these headers.
    pub fn new<S: Into<String>>(headers: impl IntoIterator<Item = S>) -> Self {
        Table { headers: headers.into_iter().map(Into::into).collect(), rows: Vec::new() }
    }

    /// Appends a row.
    pub fn row<S: Into<String>>(&mut self, cells: impl IntoIterator<Item = S>) -> &mut Self {
        self.rows.push(cells.into_iter().map(Into::into).collect());
        self
    }

    /// GitHub-flavoured markdown: header, `---` rule, rows (first column left, others right).
    pub fn to_markdown(&self) -> String {
        let n = self.headers.len().max(self.rows.iter().map(|r| r.len()).max().unwrap_or(0));
        let cell = |r: &Vec<String>, i: usize| escape(r.get(i).map(String::as_str).unwrap_or(""));
        let line = |r: &Vec<String>| format!("| {} |\n", (0..n).map(|i| cell(r, i)).collect::<Vec<_>>().join(" | "));
        let mut s = line(&self.headers);
        s += &format!("|{}\n", (0..n).map(|i| if i == 0 { " --- |" } else { " ---: |" }).collect::<String>());
        for r in &self.rows {
            s += &line(r);
        }
        s
    }
}

/// One block of a report.
#[derive(Clone, Debug, PartialEq)]
enum Block {
    Heading(usize, String),
    Paragraph(String),
    Table(Table),
    Image { alt: String, path: String, alt_link: Option<String> },
}

/// A markdown document built block by block.
#[derive(Clone, Debug, PartialEq)]
pub struct Report {
    title: String,
    blocks: Vec<Block>,
}

impl Report {
    /// A report with a level-1 title.
    pub fn new(title: impl Into<String>) -> Self {
        Report { title: title.into(), blocks: Vec::new() }
    }

    /// Adds a heading of `level` (2..=6; the title is level 1).
    pub fn heading(&mut self, level: usize, text: impl Into<String>) -> &mut Self {
        self.blocks.push(Block::Heading(level.clamp(2, 6), text.into()));
        self
    }

    /// Adds a paragraph of markdown text.
    pub fn paragraph(&mut self, text: impl Into<String>) -> &mut Self {
        self.blocks.push(Block::Paragraph(text.into()));
        self
    }

    /// Adds a table.
    pub fn table(&mut self, t: Table) -> &mut Self {
        self.blocks.push(Block::Table(t));
        self
    }

    /// Embeds an image by a relative path (e.g. `pr_curves.png`), optionally with a link to
    /// another rendering of it (e.g. the SVG).
    pub fn image(&mut self, alt: impl Into<String>, path: impl Into<String>, alt_link: Option<String>) -> &mut Self {
        self.blocks.push(Block::Image { alt: alt.into(), path: path.into(), alt_link });
        self
    }

    /// The markdown text.
    pub fn to_markdown(&self) -> String {
        let mut s = format!("# {}\n", self.title);
        for b in &self.blocks {
            s.push('\n');
            match b {
                Block::Heading(l, t) => s += &format!("{} {}\n", "#".repeat(*l), t),
                Block::Paragraph(t) => s += &format!("{t}\n"),
                Block::Table(t) => s += &t.to_markdown(),
                Block::Image { alt, path, alt_link } => {
                    s += &format!("![{alt}]({path})\n");
                    if let Some(l) = alt_link {
                        s += &format!("\n[{alt} (SVG)]({l})\n");
                    }
                }
            }
        }
        s
    }

    /// Writes the markdown atomically to `path`.
    pub fn write(&self, path: &Path) -> Result<(), ReportError> {
        tubeloc_core::files::write_atomic(path, self.to_markdown().as_bytes())?;
        Ok(())
    }
}

/// Formats a metric: 3 decimals, `n/a` for undefined (negative such as COCO's -1, or non-finite).
pub fn fmt_metric(v: f64) -> String {
    if v.is_finite() && v >= 0.0 {
        format!("{v:.3}")
    } else {
        "n/a".into()
    }
}

/// Per-attribute-value breakdown of metrics (one row per value, one column per metric).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Breakdown {
    /// Attribute name, e.g. `terrain`.
    pub attribute: String,
    /// Metric names of the columns, e.g. `["AP50", "AR"]`.
    pub metrics: Vec<String>,
    /// `(attribute value, number of images, one value per metric)`; -1 = undefined.
    pub rows: Vec<(String, usize, Vec<f64>)>,
}

/// Everything [`write_eval_report`] reports; plain data, so any evaluator can fill it.
#[derive(Clone, Debug, Default)]
pub struct EvalReport {
    /// Report title.
    pub title: String,
    /// Inputs and settings as `(name, value)`, e.g. `("ground truth", "gt.json")`.
    pub inputs: Vec<(String, String)>,
    /// Summary metrics in order as `(name, value)`, e.g. the 12 COCO numbers; -1 = undefined.
    pub stats: Vec<(String, f64)>,
    /// PR curves `(IoU threshold, 101 precisions)`; empty for no chart.
    pub pr_curves: Vec<(f64, [f64; 101])>,
    /// Breakdown tables (each also drawn as a grouped bar chart).
    pub breakdowns: Vec<Breakdown>,
    /// Pose evaluations with a label each (e.g. `coarse`, `mono`, `stereo`), overlaid in the
    /// histograms.
    pub poses: Vec<(String, PoseEvaluation)>,
}

/// File-name-safe form of a label: lowercase alphanumerics, others as `_`.
pub fn slug(s: &str) -> String {
    let t: String = s.chars().map(|c| if c.is_ascii_alphanumeric() { c.to_ascii_lowercase() } else { '_' }).collect();
    if t.is_empty() {
        "x".into()
    } else {
        t
    }
}

fn plot<C: crate::plot::Chart>(chart: &C, dir: &Path, stem: &str, size: (u32, u32), r: &mut Report, alt: &str) -> Result<(), ReportError> {
    let path = dir.join(stem);
    save_png_svg(chart, &path, size).map_err(|source| ReportError::Plot { path, source })?;
    r.image(alt, format!("{stem}.png"), Some(format!("{stem}.svg")));
    Ok(())
}

fn opt(v: Option<f64>, unit: &str) -> String {
    v.map(|x| format!("{x:.2}{unit}")).unwrap_or_else(|| "n/a".into())
}

fn within(s: &Summary) -> String {
    s.within.iter().map(|w| format!("{:.0}%", w.fraction * 100.0)).collect::<Vec<_>>().join(" / ")
}

/// Writes the report of an evaluation run into `dir` (created when missing) and returns the
/// path of `report.md`. Layout in the module documentation.
pub fn write_eval_report(dir: &Path, e: &EvalReport) -> Result<PathBuf, ReportError> {
    let mut r = Report::new(if e.title.is_empty() { "Evaluation" } else { &e.title });
    if !e.inputs.is_empty() {
        let mut t = Table::new(["input", "value"]);
        for (k, v) in &e.inputs {
            t.row([k.clone(), format!("`{v}`")]);
        }
        r.heading(2, "Inputs").table(t);
    }
    if !e.stats.is_empty() {
        let mut t = Table::new(["metric", "value"]);
        for (k, v) in &e.stats {
            t.row([k.clone(), fmt_metric(*v)]);
        }
        r.heading(2, "Summary").table(t);
    }
    if !e.pr_curves.is_empty() {
        r.heading(2, "Precision-recall curves");
        r.paragraph("COCO 101-point interpolated precision at each IoU threshold (legend: AP at that threshold).");
        let mut t = Table::new(["IoU", "AP"]);
        for (iou, p) in &e.pr_curves {
            t.row([format!("{iou:.2}"), curve_ap(p).map(fmt_metric).unwrap_or_else(|| "n/a".into())]);
        }
        plot(&PrCurves::new(format!("{} - PR curves", r.title), &e.pr_curves), dir, "pr_curves", (900, 700), &mut r, "PR curves")?;
        r.table(t);
    }
    for b in &e.breakdowns {
        r.heading(2, format!("By {}", b.attribute));
        let mut t = Table::new(std::iter::once(b.attribute.clone()).chain(std::iter::once("images".to_string())).chain(b.metrics.iter().cloned()));
        for (v, n, vals) in &b.rows {
            t.row(std::iter::once(v.clone()).chain(std::iter::once(n.to_string())).chain(vals.iter().map(|x| fmt_metric(*x))));
        }
        r.table(t);
        let cats: Vec<String> = b.rows.iter().map(|(v, _, _)| v.clone()).collect();
        if !cats.is_empty() && !b.metrics.is_empty() {
            let series = b.metrics.iter().enumerate().map(|(i, m)| (m.clone(), b.rows.iter().map(|(_, _, v)| v.get(i).copied().unwrap_or(-1.0)).collect())).collect();
            let mut chart = BarChart::new(format!("by {}", b.attribute), "value", cats, series);
            chart.y_range = Some((0.0, 1.05));
            let width = (200 + 110 * b.rows.len() as u32).clamp(700, 1600);
            plot(&chart, dir, &format!("breakdown_{}", slug(&b.attribute)), (width, 500), &mut r, &format!("by {}", b.attribute))?;
        }
    }
    if !e.poses.is_empty() {
        write_pose_section(dir, e, &mut r)?;
    }
    let path = dir.join("report.md");
    r.write(&path)?;
    Ok(path)
}

fn write_pose_section(dir: &Path, e: &EvalReport, r: &mut Report) -> Result<(), ReportError> {
    r.heading(2, "Tube poses");
    for (label, p) in &e.poses {
        r.paragraph(format!("`{label}`: {} of {} truths matched by {} ({} estimates).", p.n_matched, p.n_truths, p.method, p.n_estimates));
    }
    let mut t = Table::new(["poses", "axis angle median / p90", "≤1/2/5°", "perp. median / p90", "≤2/5/10 mm", "|along| median / p90", "ends right", "AR MSSD", "AR MSSD flip", "AR MSPD", "AR MSPD flip"]);
    for (label, p) in &e.poses {
        let s = &p.summaries;
        t.row([
            label.clone(),
            format!("{} / {}", opt(s.axis_angle_deg.median, "°"), opt(s.axis_angle_deg.p90, "°")),
            within(&s.axis_angle_deg),
            format!("{} / {}", opt(s.perpendicular_mm.median, " mm"), opt(s.perpendicular_mm.p90, " mm")),
            within(&s.perpendicular_mm),
            format!("{} / {}", opt(s.along_axis_abs_mm.median, " mm"), opt(s.along_axis_abs_mm.p90, " mm")),
            format!("{:.0}%", p.end_correct_fraction * 100.0),
            fmt_metric(p.bop.ar_mssd),
            fmt_metric(p.bop.ar_mssd_flip),
            p.bop.ar_mspd.map(fmt_metric).unwrap_or_else(|| "n/a".into()),
            p.bop.ar_mspd_flip.map(fmt_metric).unwrap_or_else(|| "n/a".into()),
        ]);
    }
    r.table(t);
    if let Some((_, p)) = e.poses.first() {
        r.paragraph(format!(
            "BOP average recalls over all truths; MSSD thresholds 0.05..0.50 of the {:.1} mm diameter, MSPD thresholds 5..50 px × width/640, axial symmetry every {:.1}°; \"flip\" also allows the two ends swapped.",
            p.bop.diameter_mm, p.bop.symmetry_step_deg
        ));
    }
    if e.poses.iter().any(|(_, p)| p.summaries.axis_error_over_std.count > 0) {
        r.heading(3, "Covariance consistency");
        let mut t = Table::new(["poses", "pairs with σ", "axis error / σ median / p90", "≤1/2/3 σ", "centre error / σ median / p90", "≤1/2/3 σ"]);
        let ratio = |s: &crate::pose_summary::Summary| format!("{} / {}", opt(s.median, ""), opt(s.p90, ""));
        for (label, p) in &e.poses {
            let s = &p.summaries;
            t.row([label.clone(), s.axis_error_over_std.count.to_string(), ratio(&s.axis_error_over_std), within(&s.axis_error_over_std), ratio(&s.centre_error_over_std), within(&s.centre_error_over_std)]);
        }
        r.table(t);
        r.paragraph("σ is the square root of the trace of the estimate's covariance block (axis tangent, centre). A consistent Gaussian covariance puts about 61-68 % of the errors within 1 σ and 95 % or more within 2 σ; fewer means the covariance is overconfident (seeds carry none).");
    }
    type Col = fn(&crate::pose_summary::PairErrors) -> Option<f64>;
    let metrics: [(&str, &str, &str, Col); 4] = [
        ("pose_axis_angle", "Axis angle error", "axis angle error (deg)", |p| Some(p.axis.axis_angle_deg)),
        ("pose_perpendicular", "Centre distance to the true axis", "perpendicular distance (mm)", |p| Some(p.axis.perpendicular_mm)),
        ("pose_along_axis", "Centre offset along the axis", "|along-axis offset| (mm)", |p| Some(p.axis.along_axis_mm.abs())),
        ("pose_mssd", "MSSD (axial symmetry)", "MSSD (mm)", |p| Some(p.mssd_mm)),
    ];
    for (stem, title, xl, f) in metrics {
        let series: Vec<HistSeries> = e.poses.iter().map(|(l, p)| HistSeries { label: l.clone(), values: p.pairs.iter().filter_map(f).collect() }).collect();
        if series.iter().all(|s| s.values.is_empty()) {
            continue;
        }
        plot(&Histogram::new(title, xl, series), dir, stem, (800, 560), r, title)?;
    }
    let json: Vec<serde_json::Value> = e.poses.iter().map(|(l, p)| serde_json::json!({ "label": l, "evaluation": p })).collect();
    tubeloc_core::files::write_json(&dir.join("pose_eval.json"), &json)?;
    r.paragraph("Per-pair errors: [`pose_eval.json`](pose_eval.json).");
    Ok(())
}
