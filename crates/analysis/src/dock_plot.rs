//! A docking approach plotted (issue 41 item 5, `lightpose bench --case
//! dock-approach --plot DIR`): one realization flown through the station's
//! scene, frame by frame, its track seen from above (y against x) and from
//! the side (z against x) with the estimate's ±2σ band about it and the
//! truth; roll, which one beacon could not see, the same way; and per
//! frame which of the station's beacons the estimator saw and fused.
//!
//! Why one realization and not the ensemble's band (plot.rs): the band a
//! reader checks here is the estimator's own σ along a track it really
//! flew, and which beacons it saw is a per-frame fact of that run.

use crate::montecarlo::McError;
use crate::plot::{font, font_ready, plot_err};
use lightpose_core::{Estimator, PoseEstimate, Status, Truth};
use lightpose_sim::{EstimatorFrames, Scene, Simulator, Trajectory};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;

pub const WIDTH: u32 = 1200;
pub const HEIGHT: u32 = 1300;

const TRUTH: RGBColor = RGBColor(214, 39, 40);
const EST: RGBColor = RGBColor(31, 90, 180);
const BAND: RGBColor = RGBColor(120, 160, 220);

/// One frame of the approach: its time, the truth and the estimate.
#[derive(Debug, Clone, Copy)]
pub struct ApproachFrame {
    pub t: f64,
    pub truth: Truth,
    pub est: PoseEstimate,
}

/// Fly `est` along `traj` through `scene` (one realization, `seed`): each
/// frame simulated sample by sample and demodulated, as a log would be.
pub fn fly(
    scene: &Scene,
    traj: &Trajectory,
    est: &mut dyn Estimator,
    seed: u64,
) -> Result<Vec<ApproachFrame>, McError> {
    let mut sim = Simulator::new(scene.clone(), seed);
    sim.set_report_roll(traj.has_roll());
    let mut frames =
        EstimatorFrames::new(sim).map_err(|e| McError::Scene(format!("demodulator: {e}")))?;
    let (n, sample_hz) = (scene.adc.samples_per_frame(), scene.adc.sample_hz);
    let count = traj.burst_count(scene.adc.rate_hz, n, sample_hz) as usize;
    est.reset();
    let mut out = Vec::with_capacity(count);
    for (j, t) in traj.frame_times(scene.adc.rate_hz).take(count).enumerate() {
        let f = frames.frame(j as u64, t, |t| traj.kinematics(t));
        let e = est.estimate(&f);
        if let Some(truth) = f.truth {
            out.push(ApproachFrame {
                t: f.t,
                truth,
                est: e,
            });
        }
    }
    Ok(out)
}

/// Render the approach as an SVG at `path`; `beacons` names the
/// station's beacons in its order, `title` heads the figure.
pub fn render_svg(
    frames: &[ApproachFrame],
    beacons: &[String],
    title: &str,
    path: &Path,
) -> Result<(), McError> {
    font_ready().map_err(|m| plot_err(path, m))?;
    let root = SVGBackend::new(path, (WIDTH, HEIGHT)).into_drawing_area();
    finish(root, frames, beacons, title, path)
}

/// The same as a PNG at `path` (for a reader without an SVG viewer).
pub fn render_png(
    frames: &[ApproachFrame],
    beacons: &[String],
    title: &str,
    path: &Path,
) -> Result<(), McError> {
    font_ready().map_err(|m| plot_err(path, m))?;
    let root = BitMapBackend::new(path, (WIDTH, HEIGHT)).into_drawing_area();
    finish(root, frames, beacons, title, path)
}

/// Draw the figure on `root` (either backend) and write it to `path`.
fn finish<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    frames: &[ApproachFrame],
    beacons: &[String],
    title: &str,
    path: &Path,
) -> Result<(), McError> {
    draw(&root, frames, beacons, title).map_err(|m| plot_err(path, m))?;
    root.present().map_err(|e| plot_err(path, e))
}

/// Which track a panel shows.
#[derive(Clone, Copy)]
enum Track {
    Y,
    Z,
    Roll,
}

impl Track {
    /// (truth, estimate, 1σ) of this track at `f`; the estimate only when
    /// `ok` and with a σ.
    fn of(self, f: &ApproachFrame) -> (f64, Option<(f64, f64)>) {
        let (p, e) = (&f.truth.pose, &f.est);
        let (truth, v, s) = match self {
            Track::Y => (p.y, e.y, e.std.y),
            Track::Z => (p.z, e.z, e.std.z),
            Track::Roll => (p.roll.deg(), e.roll_deg, e.std.roll),
        };
        let est = v
            .zip(s)
            .filter(|(v, s)| e.status == Status::Ok && v.is_finite() && s.is_finite());
        (truth, est)
    }
    fn label(self) -> &'static str {
        match self {
            Track::Y => "y (m)",
            Track::Z => "z (m)",
            Track::Roll => "roll (°)",
        }
    }
}

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    frames: &[ApproachFrame],
    beacons: &[String],
    title: &str,
) -> Result<(), String> {
    let body = crate::plot::titled(root, title, 18.0)?;
    let rows = body.split_evenly((4, 1));
    let panels = [
        (Track::Y, "(a) from above: y against x, estimate ±2σ"),
        (Track::Z, "(b) from the side: z against x, estimate ±2σ"),
        (Track::Roll, "(c) roll against x, estimate ±2σ"),
    ];
    for (i, (track, caption)) in panels.into_iter().enumerate() {
        track_panel(&rows[i], frames, track, caption, i == 0)?;
    }
    seen_panel(&rows[3], frames, beacons)
}

/// The x range of the approach (the vehicle flies right to left, to the
/// cone at x 0).
fn x_range(frames: &[ApproachFrame]) -> (f64, f64) {
    let xs = frames.iter().map(|f| f.truth.pose.x);
    let lo = xs.clone().fold(f64::INFINITY, f64::min);
    let hi = xs.fold(f64::NEG_INFINITY, f64::max);
    if lo.is_finite() && hi > lo {
        (lo - 0.1, hi + 0.1)
    } else {
        (0.0, 1.0)
    }
}

/// A frame's point of a track: x, the truth, and the `ok` estimate with
/// its 1σ.
type TrackPt = (f64, f64, Option<(f64, f64)>);

/// One track against x: the ±2σ band, the estimate and the truth.
fn track_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    frames: &[ApproachFrame],
    track: Track,
    caption: &str,
    legend: bool,
) -> Result<(), String> {
    let pts: Vec<TrackPt> = frames
        .iter()
        .map(|f| {
            let (truth, est) = track.of(f);
            (f.truth.pose.x, truth, est)
        })
        .collect();
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for (_, t, e) in &pts {
        lo = lo.min(*t);
        hi = hi.max(*t);
        if let Some((v, s)) = e {
            // A σ of the far end's prior would flatten the near track.
            let s = s.min(0.5 * (hi - lo).abs().max(0.2));
            lo = lo.min(v - 2.0 * s);
            hi = hi.max(v + 2.0 * s);
        }
    }
    if !lo.is_finite() || !hi.is_finite() || lo >= hi {
        (lo, hi) = (-1.0, 1.0);
    }
    let pad = 0.08 * (hi - lo);
    let (x0, x1) = x_range(frames);
    let mut chart = ChartBuilder::on(area)
        .caption(caption, font(15.0))
        .margin(8)
        .x_label_area_size(34)
        .y_label_area_size(60)
        .build_cartesian_2d(x0..x1, lo - pad..hi + pad)
        .map_err(|e| e.to_string())?;
    chart
        .configure_mesh()
        .x_desc("x (m), distance out of the cone")
        .y_desc(track.label())
        .label_style(font(12.0))
        .axis_desc_style(font(13.0))
        .max_light_lines(1)
        .light_line_style(RGBColor(240, 240, 240))
        .draw()
        .map_err(|e| e.to_string())?;
    // The band of each stretch of consecutive ok frames, as one polygon.
    let ok: Vec<(f64, f64, f64)> = pts
        .iter()
        .filter_map(|(x, _, e)| e.map(|(v, s)| (*x, v, s)))
        .collect();
    let band: Vec<(f64, f64)> = ok
        .iter()
        .map(|(x, v, s)| (*x, v + 2.0 * s))
        .chain(ok.iter().rev().map(|(x, v, s)| (*x, v - 2.0 * s)))
        .collect();
    chart
        .draw_series(std::iter::once(Polygon::new(band, BAND.mix(0.35).filled())))
        .map_err(|e| e.to_string())?
        .label("estimate ±2σ")
        .legend(|(x, y)| Rectangle::new([(x, y - 5), (x + 18, y + 5)], BAND.mix(0.35).filled()));
    chart
        .draw_series(LineSeries::new(
            ok.iter().map(|(x, v, _)| (*x, *v)),
            EST.stroke_width(2),
        ))
        .map_err(|e| e.to_string())?
        .label("estimate (ok frames)")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 18, y)], EST.stroke_width(2)));
    chart
        .draw_series(DashedLineSeries::new(
            pts.iter().map(|(x, t, _)| (*x, *t)),
            7,
            5,
            TRUTH.stroke_width(2),
        ))
        .map_err(|e| e.to_string())?
        .label("truth")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 18, y)], TRUTH.stroke_width(2)));
    if legend {
        crate::plot::legend(&mut chart)?;
    }
    Ok(())
}

/// Per frame, a mark on each beacon's row where the estimator saw it.
fn seen_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    frames: &[ApproachFrame],
    beacons: &[String],
) -> Result<(), String> {
    let (x0, x1) = x_range(frames);
    // A segmented range of 0..n - 1 has n rows, one per beacon.
    let n = beacons.len().max(1);
    let mut chart = ChartBuilder::on(area)
        .caption("(d) beacons seen and fused, per frame", font(15.0))
        .margin(8)
        .x_label_area_size(34)
        .y_label_area_size(90)
        .build_cartesian_2d(x0..x1, (0..n - 1).into_segmented())
        .map_err(|e| e.to_string())?;
    let names: Vec<String> = beacons.to_vec();
    chart
        .configure_mesh()
        .x_desc("x (m), distance out of the cone")
        .y_label_formatter(&|v: &SegmentValue<usize>| match v {
            SegmentValue::CenterOf(i) => names.get(*i).cloned().unwrap_or_default(),
            _ => String::new(),
        })
        .y_labels(n)
        .label_style(font(12.0))
        .axis_desc_style(font(13.0))
        .disable_y_mesh()
        .max_light_lines(1)
        .light_line_style(RGBColor(240, 240, 240))
        .draw()
        .map_err(|e| e.to_string())?;
    // A frame's width in x, so that consecutive seen frames read as a bar.
    let dx = frames
        .windows(2)
        .map(|w| (w[0].truth.pose.x - w[1].truth.pose.x).abs())
        .fold(0.0, f64::max)
        .max(1e-3);
    for b in 0..n {
        let marks = frames.iter().filter(|f| f.est.station.seen & (1 << b) != 0);
        chart
            .draw_series(marks.map(|f| {
                let x = f.truth.pose.x;
                Rectangle::new(
                    [
                        (x - 0.5 * dx, SegmentValue::Exact(b)),
                        (x + 0.5 * dx, SegmentValue::Exact(b + 1)),
                    ],
                    EST.mix(0.75).filled(),
                )
            }))
            .map_err(|e| e.to_string())?;
    }
    Ok(())
}
