//! The open sea's plot (`lightpose bench --plot DIR`): per judged axis,
//! each estimator's p95 of |error| over its `ok` poses for the four cases
//! side by side (blinking at night and by day, steady at night and by
//! day), so that what daylight costs each beacon reads off one figure.
//!
//! Why bars and not the Monte Carlo's bands (plot.rs): the question is a
//! comparison across cases at one summary figure, not a path in time.
//! Logarithmic: the estimators differ by an order of magnitude.

use crate::montecarlo::McError;
use crate::plot::{font, font_ready, plot_err};
use crate::sea::{SeaSection, JUDGED};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;

pub const WIDTH: u32 = 1400;
pub const HEIGHT: u32 = 900;

/// Blinking in blues, steady in oranges; night dark, day light.
fn colour(s: &SeaSection) -> RGBColor {
    match (s.blinking, s.day) {
        (true, false) => RGBColor(31, 90, 180),
        (true, true) => RGBColor(120, 170, 230),
        (false, false) => RGBColor(200, 90, 20),
        (false, true) => RGBColor(245, 170, 90),
    }
}

fn label(s: &SeaSection) -> String {
    format!(
        "{}, {}",
        if s.blinking { "blinking" } else { "steady" },
        if s.day { "day" } else { "night" }
    )
}

/// Render the p95 bars of `secs` as a PNG at `path`.
pub fn plot_png(secs: &[SeaSection], path: &Path) -> Result<(), McError> {
    font_ready().map_err(|m| plot_err(path, m))?;
    let root = BitMapBackend::new(path, (WIDTH, HEIGHT)).into_drawing_area();
    draw(&root, secs).map_err(|m| plot_err(path, m))?;
    root.present().map_err(|e| plot_err(path, e))
}

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    secs: &[SeaSection],
) -> Result<(), String> {
    let runs = secs.first().map_or(0, |s| s.runs);
    let body = crate::plot::titled(
        root,
        &format!(
            "Open sea, harbour approach: p95 of |error| of the ok poses after 1 s ({runs} runs)"
        ),
        19.0,
    )?;
    // The estimators in the order the first case ran them.
    let names: Vec<&str> = secs
        .iter()
        .flat_map(|s| s.rows.iter().map(|r| r.name.as_str()))
        .fold(Vec::new(), |mut v, n| {
            if !v.contains(&n) {
                v.push(n);
            }
            v
        });
    let panels = body.split_evenly((2, 3));
    for (i, a) in JUDGED.into_iter().enumerate() {
        let caption = format!("{} ({}), p95 |error|", a.name(), a.unit());
        let p95 = |s: &SeaSection, n: &str| {
            row_of(s, n)
                .and_then(|r| r.judged.p95[i])
                .filter(|v| v.is_finite() && *v > 0.0)
        };
        panel(&panels[i], secs, &names, &p95, Scale::Log, &caption, i == 0)?;
    }
    let ok = |s: &SeaSection, n: &str| {
        row_of(s, n)
            .filter(|r| r.judged.frames > 0)
            .map(|r| r.judged.ok as f64 / r.judged.frames as f64)
    };
    panel(
        &panels[5],
        secs,
        &names,
        &ok,
        Scale::Share,
        "share of frames ok after 1 s",
        false,
    )
}

fn row_of<'a>(s: &'a SeaSection, name: &str) -> Option<&'a crate::sea::SeaRow> {
    s.rows.iter().find(|r| r.name == name)
}

/// A panel's value axis.
#[derive(Clone, Copy, PartialEq)]
enum Scale {
    /// Logarithmic, about the values.
    Log,
    /// 0 to 1, linear.
    Share,
}

/// One axis: a group of bars per estimator, one bar per case.
fn panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    secs: &[SeaSection],
    names: &[&str],
    value: &dyn Fn(&SeaSection, &str) -> Option<f64>,
    scale: Scale,
    caption: &str,
    legend: bool,
) -> Result<(), String> {
    if scale == Scale::Share {
        return share_panel(area, secs, names, value, caption);
    }
    let all: Vec<f64> = secs
        .iter()
        .flat_map(|s| names.iter().filter_map(move |n| value(s, n)))
        .collect();
    let lo = all.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = all.iter().copied().fold(0.0, f64::max);
    let (lo, hi) = if lo.is_finite() && hi > 0.0 {
        (lo / 2.0, hi * 2.0)
    } else {
        (1e-3, 1.0)
    };
    let ngroups = names.len().max(1) as f64;
    let mut chart = ChartBuilder::on(area)
        .caption(caption, font(16.0))
        .margin(10)
        .x_label_area_size(36)
        .y_label_area_size(64)
        .build_cartesian_2d(-0.5..ngroups - 0.5, (lo..hi).log_scale())
        .map_err(|e| e.to_string())?;
    chart
        .configure_mesh()
        .x_labels(names.len().max(1))
        .x_label_formatter(&|x| {
            let i = x.round();
            if (x - i).abs() < 1e-6 && i >= 0.0 {
                names
                    .get(i as usize)
                    .map_or(String::new(), |n| n.to_string())
            } else {
                String::new()
            }
        })
        // A log axis' own labels print 0.7000000000000001 and crowd.
        .y_labels(6)
        .y_label_formatter(&|v| {
            format!("{v:.3}")
                .trim_end_matches('0')
                .trim_end_matches('.')
                .to_string()
        })
        .label_style(font(13.0))
        .axis_desc_style(font(13.0))
        .disable_x_mesh()
        .light_line_style(RGBColor(240, 240, 240))
        .draw()
        .map_err(|e| e.to_string())?;
    let width = 0.8 / secs.len().max(1) as f64;
    for (c, s) in secs.iter().enumerate() {
        let col = colour(s);
        let bars: Vec<Rectangle<(f64, f64)>> = names
            .iter()
            .enumerate()
            .filter_map(|(g, n)| {
                let v = value(s, n)?;
                let x0 = g as f64 - 0.4 + c as f64 * width;
                Some(Rectangle::new(
                    [(x0, lo), (x0 + width * 0.9, v)],
                    col.filled(),
                ))
            })
            .collect();
        chart
            .draw_series(bars)
            .map_err(|e| e.to_string())?
            .label(label(s))
            .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 18, y + 5)], col.filled()));
        // A case with no ok pose for an estimator: said where its bar
        // would stand.
        let none: Vec<Text<'_, (f64, f64), String>> = names
            .iter()
            .enumerate()
            .filter(|(_, n)| row_of(s, n).is_some() && value(s, n).is_none())
            .map(|(g, _)| {
                let x0 = g as f64 - 0.4 + c as f64 * width;
                Text::new(
                    "none ok".to_string(),
                    (x0, lo * 1.3),
                    font(11.0).color(&col),
                )
            })
            .collect();
        chart.draw_series(none).map_err(|e| e.to_string())?;
    }
    if legend {
        crate::plot::legend(&mut chart)?;
    }
    Ok(())
}

/// The share of frames `ok`: bars from 0 on a linear axis to 1.
fn share_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    secs: &[SeaSection],
    names: &[&str],
    value: &dyn Fn(&SeaSection, &str) -> Option<f64>,
    caption: &str,
) -> Result<(), String> {
    let ngroups = names.len().max(1) as f64;
    let mut chart = ChartBuilder::on(area)
        .caption(caption, font(16.0))
        .margin(10)
        .x_label_area_size(36)
        .y_label_area_size(64)
        .build_cartesian_2d(-0.5..ngroups - 0.5, 0.0..1.05)
        .map_err(|e| e.to_string())?;
    chart
        .configure_mesh()
        .x_labels(names.len().max(1))
        .x_label_formatter(&|x| {
            let i = x.round();
            if (x - i).abs() < 1e-6 && i >= 0.0 {
                names
                    .get(i as usize)
                    .map_or(String::new(), |n| n.to_string())
            } else {
                String::new()
            }
        })
        .label_style(font(13.0))
        .disable_x_mesh()
        .light_line_style(RGBColor(240, 240, 240))
        .draw()
        .map_err(|e| e.to_string())?;
    let width = 0.8 / secs.len().max(1) as f64;
    for (c, s) in secs.iter().enumerate() {
        let col = colour(s);
        let bars: Vec<Rectangle<(f64, f64)>> = names
            .iter()
            .enumerate()
            .filter_map(|(g, n)| {
                let v = value(s, n)?;
                let x0 = g as f64 - 0.4 + c as f64 * width;
                Some(Rectangle::new(
                    [(x0, 0.0), (x0 + width * 0.9, v)],
                    col.filled(),
                ))
            })
            .collect();
        chart.draw_series(bars).map_err(|e| e.to_string())?;
    }
    Ok(())
}
