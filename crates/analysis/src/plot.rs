//! Plots of a Monte Carlo ensemble in the style of the paper's Figures 6–8:
//! per axis, the truth as a red dashed line, the ensemble mean in blue and
//! the 95 % band (2.5–97.5 % percentiles) shaded grey; plus the path seen
//! from the side and from above. PNG for documents, SVG for print.
//!
//! Text is drawn with DejaVu Sans compiled into the binary (plotters'
//! `ab_glyph` feature), so that plots render on a machine without fonts
//! (CI, the vehicle's computer).

use crate::montecarlo::{Axis, McError, McResult};
use crate::stats::AxisStats;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::FontStyle;
use std::path::Path;
use std::sync::OnceLock;

/// DejaVu Sans (Bitstream Vera licence, see assets/DejaVuSans-LICENSE.txt).
static DEJAVU_SANS: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");
const FAMILY: &str = "sans-serif";

pub const WIDTH: u32 = 1100;
pub const HEIGHT: u32 = 1500;

const TRUTH: RGBColor = RGBColor(214, 39, 40);
const MEAN: RGBColor = RGBColor(31, 90, 180);
const BAND: RGBColor = RGBColor(150, 150, 150);

/// Register the bundled font once per process.
pub(crate) fn font_ready() -> Result<(), String> {
    static DONE: OnceLock<Result<(), String>> = OnceLock::new();
    DONE.get_or_init(|| {
        plotters::style::register_font(FAMILY, FontStyle::Normal, DEJAVU_SANS)
            .map_err(|_| "the bundled DejaVu Sans does not parse".to_string())
    })
    .clone()
}

pub(crate) fn plot_err(path: &Path, msg: impl ToString) -> McError {
    McError::Plot {
        path: path.display().to_string(),
        msg: msg.to_string(),
    }
}

/// Render `r` as a PNG at `path`.
pub fn render_png(r: &McResult, title: &str, path: &Path) -> Result<(), McError> {
    font_ready().map_err(|m| plot_err(path, m))?;
    let root = BitMapBackend::new(path, (WIDTH, HEIGHT)).into_drawing_area();
    draw(&root, r, title).map_err(|m| plot_err(path, m))?;
    root.present().map_err(|e| plot_err(path, e))
}

/// Render `r` as an SVG at `path`.
pub fn render_svg(r: &McResult, title: &str, path: &Path) -> Result<(), McError> {
    font_ready().map_err(|m| plot_err(path, m))?;
    let root = SVGBackend::new(path, (WIDTH, HEIGHT)).into_drawing_area();
    draw(&root, r, title).map_err(|m| plot_err(path, m))?;
    root.present().map_err(|e| plot_err(path, e))
}

pub(crate) fn font(size: f64) -> TextStyle<'static> {
    (FAMILY, size).into_font().into()
}

/// [lo, hi] of some values, widened so that a flat line is still visible.
fn span(values: impl Iterator<Item = f64>, min_width: f64) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    // No finite value at all: any range will do.
    if lo > hi {
        return (-1.0, 1.0);
    }
    let pad = ((hi - lo) * 0.08).max(0.5 * (min_width - (hi - lo)).max(0.0));
    (lo - pad, hi + pad)
}

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    r: &McResult,
    title: &str,
) -> Result<(), String> {
    let body = titled(root, title, 19.0)?;
    let panels = body.split_evenly((4, 2));
    path_panel(&panels[0], r, "(a) side view: z against x", Axis::Z)?;
    path_panel(&panels[1], r, "(b) top view: y against x", Axis::Y)?;
    let axes = [
        (Axis::X, "(c) x (m)"),
        (Axis::Y, "(d) y (m)"),
        (Axis::Z, "(e) z (m)"),
        (Axis::Yaw, "(f) yaw (°)"),
        (Axis::Pitch, "(g) pitch (°)"),
        (Axis::Surge, "(h) surge (m/s)"),
    ];
    for (i, (a, caption)) in axes.into_iter().enumerate() {
        series_panel(&panels[i + 2], r, a, caption, i == 0)?;
    }
    Ok(())
}

/// Where the vehicle went and where the ensemble mean says it went.
fn path_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    r: &McResult,
    caption: &str,
    across: Axis,
) -> Result<(), String> {
    let k = across.index();
    let truth: Vec<(f64, f64)> = r.truth.iter().map(|t| (t[0], t[k])).collect();
    let mean: Vec<(f64, f64)> = r
        .steps
        .iter()
        .filter_map(|s| Some((s.axes[0]?.mean, s.axes[k]?.mean)))
        .collect();
    let (x0, x1) = span(truth.iter().chain(&mean).map(|p| p.0), 1.0);
    let (y0, y1) = span(truth.iter().chain(&mean).map(|p| p.1), 0.4);
    let mut chart = ChartBuilder::on(area)
        .caption(caption, font(16.0))
        .margin(10)
        .x_label_area_size(36)
        .y_label_area_size(56)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(|e| e.to_string())?;
    chart
        .configure_mesh()
        .x_desc("x (m)")
        .y_desc(format!("{} (m)", across.name()))
        .label_style(font(12.0))
        .axis_desc_style(font(13.0))
        .max_light_lines(1)
        .light_line_style(RGBColor(240, 240, 240))
        .draw()
        .map_err(|e| e.to_string())?;
    chart
        .draw_series(LineSeries::new(mean, MEAN.stroke_width(2)))
        .map_err(|e| e.to_string())?;
    chart
        .draw_series(DashedLineSeries::new(truth, 7, 5, TRUTH.stroke_width(2)))
        .map_err(|e| e.to_string())?;
    Ok(())
}

/// One axis against time: band, mean, truth.
fn series_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    r: &McResult,
    a: Axis,
    caption: &str,
    legend: bool,
) -> Result<(), String> {
    let k = a.index();
    let st: Vec<(f64, AxisStats)> = r
        .steps
        .iter()
        .filter_map(|s| Some((s.t, s.axes[k]?)))
        .collect();
    let truth: Vec<(f64, f64)> = r
        .times
        .iter()
        .zip(&r.truth)
        .map(|(t, v)| (*t, v[k]))
        .collect();
    let (t0, t1) = (
        r.times.first().copied().unwrap_or(0.0),
        r.times.last().copied().unwrap_or(1.0),
    );
    let min_width = match a {
        Axis::Pitch | Axis::Yaw => 2.0,
        _ => 0.2,
    };
    let (lo, hi) = span(
        st.iter()
            .flat_map(|(_, s)| [s.p025, s.p975, s.mean])
            .chain(truth.iter().map(|p| p.1)),
        min_width,
    );
    let mut chart = ChartBuilder::on(area)
        .caption(caption, font(16.0))
        .margin(10)
        .x_label_area_size(36)
        .y_label_area_size(56)
        .build_cartesian_2d(t0..t1.max(t0 + 1e-6), lo..hi)
        .map_err(|e| e.to_string())?;
    chart
        .configure_mesh()
        .x_desc("t (s)")
        .y_desc(format!("{} ({})", a.name(), a.unit()))
        .label_style(font(12.0))
        .axis_desc_style(font(13.0))
        .max_light_lines(1)
        .light_line_style(RGBColor(240, 240, 240))
        .draw()
        .map_err(|e| e.to_string())?;
    if st.is_empty() {
        area.draw(&Text::new(
            "no estimate",
            (80, 80),
            font(16.0).color(&BLACK),
        ))
        .map_err(|e| e.to_string())?;
    } else {
        let band: Vec<(f64, f64)> = st
            .iter()
            .map(|(t, s)| (*t, s.p975))
            .chain(st.iter().rev().map(|(t, s)| (*t, s.p025)))
            .collect();
        chart
            .draw_series(std::iter::once(Polygon::new(band, BAND.mix(0.45).filled())))
            .map_err(|e| e.to_string())?
            .label("95 % band")
            .legend(|(x, y)| {
                Rectangle::new([(x, y - 5), (x + 18, y + 5)], BAND.mix(0.45).filled())
            });
        chart
            .draw_series(LineSeries::new(
                st.iter().map(|(t, s)| (*t, s.mean)),
                MEAN.stroke_width(2),
            ))
            .map_err(|e| e.to_string())?
            .label("ensemble mean")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 18, y)], MEAN.stroke_width(2)));
    }
    chart
        .draw_series(DashedLineSeries::new(truth, 7, 5, TRUTH.stroke_width(2)))
        .map_err(|e| e.to_string())?
        .label("truth")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 18, y)], TRUTH.stroke_width(2)));
    if legend {
        crate::plot::legend(&mut chart)?;
    }
    Ok(())
}

/// The series' labels, top right, on a pale box (every panel's legend).
pub(crate) fn legend<'a, DB, CT>(chart: &mut ChartContext<'a, DB, CT>) -> Result<(), String>
where
    DB: DrawingBackend + 'a,
    CT: CoordTranslate,
{
    chart
        .configure_series_labels()
        .label_font(font(12.0))
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(180, 180, 180))
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(|e| e.to_string())
}

/// A figure begun: white, `title` across its top in `size` points; the
/// area below it, for the panels.
pub(crate) fn titled<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    title: &str,
    size: f64,
) -> Result<DrawingArea<DB, Shift>, String> {
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let (head, body) = root.split_vertically(44);
    head.draw(&Text::new(
        title.to_string(),
        (16, 12),
        font(size).color(&BLACK),
    ))
    .map_err(|e| e.to_string())?;
    Ok(body)
}
