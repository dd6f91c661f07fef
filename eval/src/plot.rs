//! Plots as PNG and SVG, with text drawn from an embedded font (no system font needed).
//!
//! Each chart type ([`crate::plot_pr::PrCurves`], [`crate::plot_hist::Histogram`],
//! [`crate::plot_bar::BarChart`]) implements [`Chart`]; [`save`] renders one to a file whose
//! extension picks the format (`.png` or `.svg`), [`save_png_svg`] writes both. Files are
//! written atomically. Text uses DejaVu Sans (free licence, bytes from the `dejavu` crate),
//! registered with plotters' `ab_glyph` font table under the family name `sans-serif`.

use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// Errors while drawing or writing a plot.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// The plot data is unusable (names the problem).
    #[error("invalid plot data: {0}")]
    Data(String),
    /// Plotters failed while drawing.
    #[error("drawing failed: {0}")]
    Draw(String),
    /// The embedded font could not be registered.
    #[error("cannot register the embedded font")]
    Font,
    /// The file extension is neither `.png` nor `.svg`.
    #[error("{0}: unknown plot format (use .png or .svg)")]
    Format(PathBuf),
    /// Encoding or writing the file failed.
    #[error(transparent)]
    Write(#[from] tubeloc_core::CoreError),
}

/// Converts a plotters drawing error.
pub(crate) fn draw_err<E: std::error::Error + Send + Sync>(e: DrawingAreaErrorKind<E>) -> PlotError {
    PlotError::Draw(e.to_string())
}

/// The font family name every chart uses.
pub const FONT: &str = "sans-serif";

/// Registers DejaVu Sans (regular and bold) as [`FONT`]; idempotent and thread-safe.
pub fn register_fonts() -> Result<(), PlotError> {
    static DONE: OnceLock<bool> = OnceLock::new();
    let ok = *DONE.get_or_init(|| plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular()).is_ok() && plotters::style::register_font(FONT, FontStyle::Bold, dejavu::sans::bold()).is_ok());
    if ok {
        Ok(())
    } else {
        Err(PlotError::Font)
    }
}

/// Ten well-separated series colours (the "tab10" palette).
pub const PALETTE: [RGBColor; 10] =
    [RGBColor(31, 119, 180), RGBColor(255, 127, 14), RGBColor(44, 160, 44), RGBColor(214, 39, 40), RGBColor(148, 103, 189), RGBColor(140, 86, 75), RGBColor(227, 119, 194), RGBColor(127, 127, 127), RGBColor(188, 189, 34), RGBColor(23, 190, 207)];

/// Colour of series `i` (cycles through [`PALETTE`]).
pub fn series_color(i: usize) -> RGBColor {
    PALETTE[i % PALETTE.len()]
}

/// A chart that can draw itself on any plotters backend.
pub trait Chart {
    /// Draws the whole chart on `area` (already sized; the chart fills the background).
    fn draw<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> Result<(), PlotError>
    where
        DB::ErrorType: 'static;
}

/// Output format of a plot file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlotFormat {
    /// 8-bit RGB PNG.
    Png,
    /// SVG text (fonts named, not embedded).
    Svg,
}

impl PlotFormat {
    /// The format named by a path's extension (case-insensitive `png` / `svg`).
    pub fn from_path(path: &Path) -> Option<Self> {
        match path.extension()?.to_str()?.to_ascii_lowercase().as_str() {
            "png" => Some(PlotFormat::Png),
            "svg" => Some(PlotFormat::Svg),
            _ => None,
        }
    }
}

/// Renders `chart` to PNG bytes of `size` pixels (width, height).
pub fn render_png<C: Chart>(chart: &C, size: (u32, u32)) -> Result<Vec<u8>, PlotError> {
    register_fonts()?;
    if size.0 < 100 || size.1 < 100 {
        return Err(PlotError::Data(format!("plot size {}x{} is too small (at least 100x100)", size.0, size.1)));
    }
    let mut buf = vec![255u8; size.0 as usize * size.1 as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut buf, size).into_drawing_area();
        chart.draw(&root)?;
        root.present().map_err(draw_err)?;
    }
    let img = image::RgbImage::from_raw(size.0, size.1, buf).ok_or_else(|| PlotError::Draw("bitmap buffer size".into()))?;
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png).map_err(|e| PlotError::Draw(format!("PNG encoding: {e}")))?;
    Ok(out.into_inner())
}

/// Renders `chart` to an SVG document of `size` user units.
pub fn render_svg<C: Chart>(chart: &C, size: (u32, u32)) -> Result<String, PlotError> {
    register_fonts()?;
    let mut s = String::new();
    {
        let root = SVGBackend::with_string(&mut s, size).into_drawing_area();
        chart.draw(&root)?;
        root.present().map_err(draw_err)?;
    }
    Ok(s)
}

/// Renders `chart` to `path` (format from the extension), atomically.
pub fn save<C: Chart>(chart: &C, path: &Path, size: (u32, u32)) -> Result<(), PlotError> {
    let bytes = match PlotFormat::from_path(path).ok_or_else(|| PlotError::Format(path.to_path_buf()))? {
        PlotFormat::Png => render_png(chart, size)?,
        PlotFormat::Svg => render_svg(chart, size)?.into_bytes(),
    };
    tubeloc_core::files::write_atomic(path, &bytes)?;
    Ok(())
}

/// Writes `stem.png` and `stem.svg` (any extension of `stem` is replaced); returns both paths.
pub fn save_png_svg<C: Chart>(chart: &C, stem: &Path, size: (u32, u32)) -> Result<(PathBuf, PathBuf), PlotError> {
    let png = stem.with_extension("png");
    let svg = stem.with_extension("svg");
    save(chart, &png, size)?;
    save(chart, &svg, size)?;
    Ok((png, svg))
}

/// Title font (bold, 26 px).
pub(crate) fn title_font() -> TextStyle<'static> {
    (FONT, 26).into_font().style(FontStyle::Bold).color(&BLACK)
}

/// Axis description font (20 px).
pub(crate) fn label_font() -> TextStyle<'static> {
    (FONT, 20).into_font().color(&BLACK)
}

/// Tick label and legend font (16 px).
pub(crate) fn tick_font() -> TextStyle<'static> {
    (FONT, 16).into_font().color(&BLACK)
}
