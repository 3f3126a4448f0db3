//! Offline replay: run an estimator over a recorded intensity log, write one
//! POSE line per frame, and (when the log carries truth) measure the error
//! of each axis. A library function so that the CLI, the regression tests
//! and anyone else replay exactly alike. The error statistics are running
//! ones ([`running`]): a long log with truth costs no more memory than a
//! short one.

mod running;

use lightpose_core::{
    Agreement, Cut, Estimator, FrameLog, LogError, PoseEstimate, ReadingUse, Refusal, Status,
    CHECKED, COLS, NDET, READINGS,
};
use std::fmt;
use std::io::Write;

#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// The log could not be read on (an I/O error, not a bad line).
    #[error(transparent)]
    Read(LogError),
    // The I/O error is in the message, not chained as a source, so that a
    // one-line `{:#}` report does not say it twice.
    #[error("writing poses: {0}")]
    Write(std::io::Error),
}

impl From<std::io::Error> for ReplayError {
    fn from(e: std::io::Error) -> Self {
        ReplayError::Write(e)
    }
}

/// Error statistics of one axis (estimate − truth), over the frames where
/// both are known.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisError {
    pub n: usize,
    /// Signed mean: the bias.
    pub mean: f64,
    pub rmse: f64,
    /// 95th percentile of |error|.
    pub p95: f64,
    /// Signed error at the last frame that had both.
    pub last: f64,
}

impl AxisError {
    /// Statistics of `errs` (signed errors in time order); `None` if empty.
    pub fn of(errs: &[f64]) -> Option<AxisError> {
        let n = errs.len();
        if n == 0 {
            return None;
        }
        let mean = errs.iter().sum::<f64>() / n as f64;
        let rmse = (errs.iter().map(|e| e * e).sum::<f64>() / n as f64).sqrt();
        let mut abs: Vec<f64> = errs.iter().map(|e| e.abs()).collect();
        abs.sort_by(f64::total_cmp);
        // Nearest-rank percentile: the smallest |e| with ≥ 95 % at or below.
        let rank = ((0.95 * n as f64).ceil() as usize).clamp(1, n);
        Some(AxisError {
            n,
            mean,
            rmse,
            p95: abs[rank - 1],
            last: errs[n - 1],
        })
    }
}

/// Axes of the report, with their units.
pub const AXES: [(&str, &str); 6] = [
    ("x", "m"),
    ("y", "m"),
    ("z", "m"),
    ("pitch", "deg"),
    ("yaw", "deg"),
    ("surge", "m/s"),
];

/// Per-axis error against the log's truth, in the order of [`AXES`].
#[derive(Debug, Clone, PartialEq)]
pub struct ErrorReport {
    pub axes: [Option<AxisError>; 6],
}

impl fmt::Display for ErrorReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "{:<6} {:>5} {:>5} {:>9} {:>9} {:>9} {:>9}",
            "axis", "unit", "n", "mean", "rmse", "p95", "final"
        )?;
        for ((name, unit), a) in AXES.iter().zip(&self.axes) {
            match a {
                Some(a) => writeln!(
                    f,
                    "{name:<6} {unit:>5} {:>5} {:>9.4} {:>9.4} {:>9.4} {:>9.4}",
                    a.n, a.mean, a.rmse, a.p95, a.last
                )?,
                None => writeln!(f, "{name:<6} {unit:>5} {:>5} {:>9}", 0, "no data")?,
            }
        }
        Ok(())
    }
}

/// Error statistics of each axis, kept running while replaying.
#[derive(Debug, Default)]
struct Errors {
    e: [running::RunningAxis; 6],
}

/// Wrap an angle difference in degrees to (−180, 180].
fn wrap_deg(d: f64) -> f64 {
    let w = d.rem_euclid(360.0);
    if w > 180.0 {
        w - 360.0
    } else {
        w
    }
}

impl Errors {
    fn add(&mut self, est: &PoseEstimate, truth: &lightpose_core::Truth) {
        let p = &truth.pose;
        let pairs = [
            (est.x, Some(p.x)),
            (est.y, Some(p.y)),
            (est.z, Some(p.z)),
            (est.pitch_deg, Some(p.pitch.deg())),
            (est.yaw_deg, Some(p.yaw.deg())),
            (est.surge, truth.surge),
        ];
        for (i, (e, t)) in pairs.into_iter().enumerate() {
            if let (Some(e), Some(t)) = (e, t) {
                let d = if i == 3 || i == 4 {
                    wrap_deg(e - t)
                } else {
                    e - t
                };
                if d.is_finite() {
                    self.e[i].push(d);
                }
            }
        }
    }

    fn report(&mut self) -> Option<ErrorReport> {
        let axes = [0, 1, 2, 3, 4, 5].map(|i| self.e[i].report());
        axes.iter()
            .any(Option::is_some)
            .then_some(ErrorReport { axes })
    }
}

/// What a replay did.
#[derive(Debug, Clone, PartialEq)]
pub struct ReplaySummary {
    /// Frames estimated (= POSE lines written).
    pub frames: u64,
    /// Lines of the log that were refused and skipped.
    pub bad_lines: u64,
    /// Estimates by status, in the order of [`Status::ALL`].
    pub status: [u64; Status::ALL.len()],
    /// Error against truth, when the log carried any and an estimate had
    /// a value to compare.
    pub report: Option<ErrorReport>,
    /// Frames that carried truth.
    pub truth_frames: u64,
    /// Where the log was cut short, if it ended so.
    pub cut: Option<Cut>,
    /// Gaps in `seq` and the frames they lost.
    pub seq_gaps: (u64, u64),
    /// What became of the frames' own-sensor readings: per reading
    /// (attitude, depth, velocity, as [`READINGS`]), frames per outcome in
    /// [`ReadingUse::index`] order (absent, used, ignored, refused by
    /// reason).
    pub readings: [[u64; ReadingUse::COUNT]; 3],
    /// Readings the log reader dropped as malformed (the frame was kept).
    pub bad_readings: u64,
    /// The first of them, "name:line: why" (FORMATS.md: a reader names the
    /// line of anything it cannot accept).
    pub first_bad_reading: Option<String>,
    /// The water's K_D as the estimator learned it by the log's end
    /// (`Estimator::water_k_d`), m⁻¹, if it learns it.
    pub water_k_d: Option<f64>,
    /// The depth sensor's offset and its 1σ as the estimator left them
    /// (`Estimator::depth_offset`), m, if it estimates one.
    pub depth_offset: Option<(f64, f64)>,
    /// The attitude sensor's pitch offset and its 1σ (°), likewise.
    pub pitch_offset_deg: Option<(f64, f64)>,
    /// Frames on which the estimator left each channel out as stuck
    /// (`PoseEstimate::excluded_channels`), by detector 5·row + col.
    pub excluded: [u64; NDET],
    /// The reading check (`PoseEstimate::agreement`), per component in
    /// [`CHECKED`] order: frames on which it disagreed with the light, and
    /// the window mean of its normalized innovation farthest from 0.
    pub disagreed: [u64; 6],
    pub agreement_extreme: [Option<f64>; 6],
    /// The checks against the light on the last frame the DVL stood
    /// refused by them (what they judged: `Agreement::dvl_said`).
    pub dvl_refused_last: Option<Agreement>,
}

impl ReplaySummary {
    /// "attitude 40 used, 1 refused_gate; depth 41 absent; ..." for the
    /// readings some frame carried, or `None` when no frame carried any.
    pub fn readings_line(&self) -> Option<String> {
        let mut parts = Vec::new();
        for (name, counts) in READINGS.iter().zip(&self.readings) {
            if counts[1..].iter().all(|n| *n == 0) {
                continue;
            }
            let words: Vec<String> = counts
                .iter()
                .enumerate()
                .filter(|(i, n)| *i > 0 && **n > 0)
                .filter_map(|(i, n)| {
                    ReadingUse::from_index(i).map(|u| format!("{n} {}", u.as_str()))
                })
                .collect();
            parts.push(format!("{name} {}", words.join(", ")));
        }
        (!parts.is_empty()).then(|| parts.join("; "))
    }

    /// "(0,0) on 41 frames, (2,2) on 3" for the channels the estimator
    /// left out as stuck, or `None`.
    pub fn excluded_line(&self) -> Option<String> {
        let parts: Vec<String> = (0..NDET)
            .filter(|&k| self.excluded[k] > 0)
            .map(|k| format!("({},{}) on {} frames", k / COLS, k % COLS, self.excluded[k]))
            .collect();
        (!parts.is_empty()).then(|| parts.join(", "))
    }

    /// "depth on 30 frames (window mean ν/√S up to +1.92)" for the reading
    /// components that disagreed with the light, or `None`.
    pub fn disagreed_line(&self) -> Option<String> {
        let parts: Vec<String> = (0..CHECKED.len())
            .filter(|&i| self.disagreed[i] > 0)
            .map(|i| {
                let m = self.agreement_extreme[i].unwrap_or(f64::NAN);
                format!(
                    "{} on {} frames (window mean ν/√S up to {m:+.2})",
                    CHECKED[i], self.disagreed[i]
                )
            })
            .collect();
        (!parts.is_empty()).then(|| parts.join(", "))
    }

    /// "on 287 frames (range over 5 s: light -1.20 m, DVL +1.05 m; ...)"
    /// when the DVL checks refused the DVL, or `None`.
    pub fn dvl_refused_line(&self) -> Option<String> {
        let n = self.readings[2][ReadingUse::Refused(Refusal::Light).index()];
        (n > 0).then(|| match self.dvl_refused_last.map(|a| a.dvl_said()) {
            Some(said) if !said.is_empty() => format!("on {n} frames ({said})"),
            _ => format!("on {n} frames"),
        })
    }

    /// "pitch +0.31, yaw -0.18, depth +0.25" : each checked component's
    /// window mean farthest from 0, or `None` when no window filled.
    pub fn agreement_line(&self) -> Option<String> {
        let parts: Vec<String> = (0..CHECKED.len())
            .filter_map(|i| self.agreement_extreme[i].map(|m| format!("{} {m:+.2}", CHECKED[i])))
            .collect();
        (!parts.is_empty()).then(|| parts.join(", "))
    }
}

/// Replay `log` through `est`, writing one POSE line per frame to `out`.
/// Each refused log line is handed to `on_bad_line` (to be named to the
/// operator) and skipped; an I/O error ends the replay with an error.
pub fn replay<W: Write>(
    est: &mut dyn Estimator,
    log: &mut dyn FrameLog,
    out: &mut W,
    mut on_bad_line: impl FnMut(&LogError),
) -> Result<ReplaySummary, ReplayError> {
    let mut buf = Vec::with_capacity(256);
    let mut errors = Errors::default();
    let mut s = ReplaySummary {
        frames: 0,
        bad_lines: 0,
        status: [0; Status::ALL.len()],
        report: None,
        truth_frames: 0,
        cut: None,
        seq_gaps: (0, 0),
        readings: [[0; ReadingUse::COUNT]; 3],
        bad_readings: 0,
        first_bad_reading: None,
        water_k_d: None,
        depth_offset: None,
        pitch_offset_deg: None,
        excluded: [0; NDET],
        disagreed: [0; 6],
        agreement_extreme: [None; 6],
        dvl_refused_last: None,
    };
    while let Some(item) = log.next_frame() {
        // The reader keeps only the last bad reading's text: taken as soon
        // as there is one, it is the first line's.
        if s.first_bad_reading.is_none() {
            if let (1.., Some(m)) = log.bad_readings() {
                s.first_bad_reading = Some(m.to_string());
            }
        }
        let frame = match item {
            Ok(f) => f,
            Err(e) if e.skippable() => {
                s.bad_lines += 1;
                on_bad_line(&e);
                continue;
            }
            Err(e) => return Err(ReplayError::Read(e)),
        };
        let pose = est.estimate(&frame);
        pose.write_json(None, &mut buf);
        buf.push(b'\n');
        out.write_all(&buf)?;
        s.frames += 1;
        if let Some(i) = Status::ALL.iter().position(|st| *st == pose.status) {
            s.status[i] += 1;
        }
        for (row, u) in s
            .readings
            .iter_mut()
            .zip(pose.readings.settled(&frame).all())
        {
            row[u.index()] += 1;
        }
        for (k, n) in s.excluded.iter_mut().enumerate() {
            *n += u64::from(pose.excluded_channels >> k & 1);
        }
        let a = &pose.agreement;
        for i in 0..CHECKED.len() {
            s.disagreed[i] += u64::from(a.suspect >> i & 1);
            if let Some(m) = a.mean[i] {
                let far = s.agreement_extreme[i].is_none_or(|e: f64| m.abs() > e.abs());
                if far {
                    s.agreement_extreme[i] = Some(m);
                }
            }
        }
        if a.dvl_refused {
            s.dvl_refused_last = Some(*a);
        }
        if let Some(t) = &frame.truth {
            s.truth_frames += 1;
            errors.add(&pose, t);
        }
    }
    out.flush()?;
    s.report = errors.report();
    s.cut = log.cut();
    s.seq_gaps = log.seq_gaps();
    s.bad_readings = log.bad_readings().0;
    s.water_k_d = est.water_k_d();
    s.depth_offset = est.depth_offset();
    s.pitch_offset_deg = est.pitch_offset_deg();
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axis_statistics() {
        let a = AxisError::of(&[1.0, -1.0, 2.0, -2.0]).unwrap();
        assert_eq!(a.n, 4);
        assert_eq!(a.mean, 0.0);
        assert!((a.rmse - 2.5f64.sqrt()).abs() < 1e-15);
        assert_eq!(a.p95, 2.0);
        assert_eq!(a.last, -2.0);
        let errs: Vec<f64> = (1..=100).map(|i| i as f64).collect();
        assert_eq!(AxisError::of(&errs).unwrap().p95, 95.0);
        assert!(AxisError::of(&[]).is_none());
    }

    #[test]
    fn yaw_errors_wrap() {
        assert_eq!(wrap_deg(359.0), -1.0);
        assert_eq!(wrap_deg(-181.0), 179.0);
        assert_eq!(wrap_deg(5.0), 5.0);
    }
}
