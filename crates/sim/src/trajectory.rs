//! Trajectories: knots `t,x,y,z,pitch,yaw` (spec v3: optionally `,roll`)
//! from CSV, a natural cubic spline per column, sampled at t = t0 + k / rate
//! while t ≤ t_end. True surge is the spline's velocity along the vehicle's
//! forward axis. Past its knots a spline follows its end piece, extended
//! (a burst's first and last samples may fall there).

use crate::spline::Spline;
use lightpose_core::log::plausible_t;
use lightpose_core::textfile::{
    excerpt, read_line_bounded, strip_bom, LineRead, TextError, TextSource, EXCERPT_CHARS,
    MAX_LINE_BYTES,
};
use lightpose_core::{Angle, BeamVec, Pose};
use std::io::BufRead;
use std::path::Path;

#[derive(Debug, thiserror::Error)]
pub enum TrajectoryError {
    /// Unreadable or too large.
    #[error(transparent)]
    Text(#[from] TextError),
    #[error("{file}:{line}: {msg}")]
    Invalid {
        file: String,
        line: usize,
        msg: String,
    },
}

/// One knot: time (s), position (m) and attitude.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Knot {
    pub t: f64,
    pub pose: Pose,
}

/// Where the vehicle is and how it moves at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Kinematics {
    pub pose: Pose,
    /// Velocity over the ground in B, m/s.
    pub velocity: BeamVec,
}

impl Kinematics {
    /// Speed along the forward axis (MODEL.md's surge).
    pub fn surge(&self) -> f64 {
        let f = self.pose.attitude().forward();
        f.dot(&self.velocity)
    }
}

#[derive(Debug, Clone)]
pub struct Trajectory {
    knots: Vec<Knot>,
    /// x, y, z, pitch (rad), yaw (rad), roll (rad)
    cols: [Spline; 6],
    /// Whether the knots have a roll column (spec v3); without it roll is
    /// exactly 0.
    has_roll: bool,
}

const HEADER: [&str; 7] = ["t", "x", "y", "z", "pitch", "yaw", "roll"];

/// Most knots a trajectory may have: a knot every 0.1 s for almost three
/// hours; far more than any written by hand or by a planner.
pub const MAX_KNOTS: usize = 100_000;

/// Frames `lightpose simulate` writes at most unless told otherwise
/// (`--max-frames`): about 4 GB of log, 23 days at 5 Hz, 2.8 h at 1 kHz.
pub const DEFAULT_MAX_FRAMES: u64 = 10_000_000;

/// The lines of a CSV that are not blank or comments, read bounded.
struct CsvLines<'a, R> {
    src: R,
    buf: Vec<u8>,
    line: usize,
    file: &'a str,
}

impl<R: BufRead> CsvLines<'_, R> {
    fn err(&self, line: usize, msg: impl Into<String>) -> TrajectoryError {
        TrajectoryError::Invalid {
            file: self.file.to_string(),
            line,
            msg: msg.into(),
        }
    }

    /// The next line with content, trimmed, and its number.
    fn next(&mut self) -> Result<Option<(usize, &str)>, TrajectoryError> {
        let (start, end) = loop {
            self.line += 1;
            match read_line_bounded(&mut self.src, &mut self.buf, MAX_LINE_BYTES) {
                Err(source) => {
                    let file = self.file.to_string();
                    return Err(TextError::Io { file, source }.into());
                }
                Ok(LineRead::Eof) => return Ok(None),
                Ok(LineRead::TooLong) => {
                    let msg = format!("line longer than {MAX_LINE_BYTES} bytes: refused unread");
                    return Err(self.err(self.line, msg));
                }
                Ok(LineRead::Line) => {}
            }
            let text = std::str::from_utf8(&self.buf)
                .map_err(|_| self.err(self.line, "not valid UTF-8"))?;
            let text = if self.line == 1 {
                strip_bom(text)
            } else {
                text
            };
            let trimmed = text.trim();
            if !trimmed.is_empty() && !trimmed.starts_with('#') {
                let start = trimmed.as_ptr() as usize - self.buf.as_ptr() as usize;
                break (start, start + trimmed.len());
            }
        };
        let text = std::str::from_utf8(&self.buf[start..end])
            .map_err(|_| self.err(self.line, "not valid UTF-8"))?;
        Ok(Some((self.line, text)))
    }
}

/// One knot's line, checked: `cols` (6, or 7 with roll) finite numbers, t
/// a time, angles in range.
fn knot(
    l: &str,
    cols: usize,
    err: impl Fn(String) -> TrajectoryError,
) -> Result<Knot, TrajectoryError> {
    let fields: Vec<&str> = l.split(',').map(str::trim).collect();
    if fields.len() != cols {
        return Err(err(format!(
            "expected {cols} values, found {}",
            fields.len()
        )));
    }
    let mut v = [0.0; 7];
    for (i, (f, slot)) in fields.iter().zip(v.iter_mut()).enumerate() {
        *slot = f
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| {
                let f = excerpt(f, 40);
                err(format!("{} = `{f}` is not a finite number", HEADER[i]))
            })?;
    }
    if !plausible_t(v[0]) {
        return Err(err(format!("t = {:e} is not a time in seconds", v[0])));
    }
    if v[4].abs() >= 90.0 || v[5].abs() >= 180.0 {
        return Err(err(
            "pitch must be strictly between −90° and 90°, and yaw within ±180°".into(),
        ));
    }
    if v[6].abs() >= 180.0 {
        return Err(err("roll must be within ±180°".into()));
    }
    let mut pose = Pose::new(
        v[1],
        v[2],
        v[3],
        Angle::from_deg(v[4]),
        Angle::from_deg(v[5]),
    );
    if cols == 7 {
        pose.roll = Angle::from_deg(v[6]);
    }
    Ok(Knot { t: v[0], pose })
}

impl Trajectory {
    pub fn load(path: &Path) -> Result<Self, TrajectoryError> {
        Self::from_source(&TextSource::File(path.to_path_buf()))
    }

    /// Read the trajectory a program names (a file, or text it holds).
    pub fn from_source(src: &TextSource) -> Result<Self, TrajectoryError> {
        Self::read(src.reader()?, &src.describe())
    }

    /// Parse CSV text with the header `t,x,y,z,pitch,yaw` or
    /// `t,x,y,z,pitch,yaw,roll` (angles in degrees).
    pub fn parse(text: &str, file: &str) -> Result<Self, TrajectoryError> {
        Self::read(text.as_bytes(), file)
    }

    /// Read CSV line by line: each line bounded ([`MAX_LINE_BYTES`]), at
    /// most [`MAX_KNOTS`] knots, a byte-order mark before the header
    /// accepted, quotes of the text cut to an excerpt.
    pub fn read(src: impl BufRead, file: &str) -> Result<Self, TrajectoryError> {
        let mut csv = CsvLines {
            src,
            buf: Vec::new(),
            line: 0,
            file,
        };
        let Some((hl, header)) = csv.next()? else {
            return Err(csv.err(1, "empty trajectory: no header"));
        };
        let names: Vec<&str> = header.split(',').map(str::trim).collect();
        let cols = match names.len() {
            6 | 7 if names == HEADER[..names.len()] => names.len(),
            _ => {
                let found = excerpt(header, EXCERPT_CHARS);
                let msg = format!(
                    "header must be `{}` (or with `,roll` after it), found `{found}`",
                    HEADER[..6].join(",")
                );
                return Err(csv.err(hl, msg));
            }
        };
        let mut knots: Vec<Knot> = Vec::new();
        let mut lines = Vec::new();
        let mut last_line = hl;
        while let Some((ln, l)) = csv.next()? {
            let err = |msg| TrajectoryError::Invalid {
                file: file.to_string(),
                line: ln,
                msg,
            };
            let k = knot(l, cols, err)?;
            if let Some(prev) = knots.last().map(|k| k.t) {
                if k.t <= prev {
                    let msg = format!("t = {} does not increase (previous {prev})", k.t);
                    return Err(csv.err(ln, msg));
                }
            }
            if knots.len() == MAX_KNOTS {
                return Err(csv.err(ln, format!("more than {MAX_KNOTS} knots")));
            }
            knots.push(k);
            lines.push(ln);
            last_line = ln;
        }
        if knots.len() < 2 {
            return Err(csv.err(
                last_line,
                format!("a trajectory needs at least 2 knots, found {}", knots.len()),
            ));
        }
        let mut tr = Self::from_knots(knots);
        tr.has_roll = cols == 7;
        if let Some((i, msg)) = tr.angles_beyond_range() {
            return Err(csv.err(lines[i + 1], msg));
        }
        Ok(tr)
    }

    /// The first span between knots (its index) where the spline takes
    /// pitch to ±90° or yaw past ±180°, with what it reaches. The knots are
    /// checked, but a natural cubic overshoots them: pitch 0 → 89.9 → 89.9
    /// → 0 one second apart reached 123.6°, a truth no vehicle has and
    /// attitude readings the estimators refuse.
    fn angles_beyond_range(&self) -> Option<(usize, String)> {
        const SAMPLES: usize = 64;
        for i in 0..self.knots.len() - 1 {
            let (t0, t1) = (self.knots[i].t, self.knots[i + 1].t);
            for k in 1..SAMPLES {
                let t = t0 + (t1 - t0) * k as f64 / SAMPLES as f64;
                for (col, name, limit) in
                    [(3, "pitch", 90.0), (4, "yaw", 180.0), (5, "roll", 180.0)]
                {
                    let deg = self.cols[col].eval(t).0.to_degrees();
                    if deg.abs() >= limit {
                        return Some((
                            i,
                            format!(
                                "between t = {t0} and {t1} s the spline through the knots (MODEL.md) takes {name} to {deg:.1}°, beyond ±{limit}°: add a knot or ease the turn"
                            ),
                        ));
                    }
                }
            }
        }
        None
    }

    /// Build from knots already checked: at least two, `t` increasing. It
    /// has a roll column when a knot rolls.
    pub fn from_knots(knots: Vec<Knot>) -> Self {
        let t: Vec<f64> = knots.iter().map(|k| k.t).collect();
        let col = |f: fn(&Pose) -> f64| {
            let y: Vec<f64> = knots.iter().map(|k| f(&k.pose)).collect();
            Spline::new(&t, &y)
        };
        let cols = [
            col(|p| p.x),
            col(|p| p.y),
            col(|p| p.z),
            col(|p| p.pitch.rad()),
            col(|p| p.yaw.rad()),
            col(|p| p.roll.rad()),
        ];
        let has_roll = knots.iter().any(|k| k.pose.roll != Angle::ZERO);
        Trajectory {
            knots,
            cols,
            has_roll,
        }
    }

    /// Whether the trajectory gives roll (a `roll` column): the vehicle's
    /// attitude sensor then reports it (MODEL.md).
    pub fn has_roll(&self) -> bool {
        self.has_roll
    }

    pub fn knots(&self) -> &[Knot] {
        &self.knots
    }
    pub fn t0(&self) -> f64 {
        self.knots[0].t
    }
    pub fn t_end(&self) -> f64 {
        self.knots[self.knots.len() - 1].t
    }

    /// The same trajectory moved by a constant lateral offset (`dy`, `dz`,
    /// m) and attitude offset: the vehicle flies the same course beside it,
    /// pointed off it (so with a sideslip). For measuring estimators off the
    /// runs' axis (the Monte Carlo diagnostics, the off-axis coverage test).
    pub fn moved(&self, dy: f64, dz: f64, dpitch: Angle, dyaw: Angle) -> Trajectory {
        let knots = self
            .knots
            .iter()
            .map(|k| {
                let p = k.pose;
                let pose = Pose::new(p.x, p.y + dy, p.z + dz, p.pitch + dpitch, p.yaw + dyaw)
                    .with_roll(p.roll);
                Knot { t: k.t, pose }
            })
            .collect();
        let mut tr = Self::from_knots(knots);
        tr.has_roll = self.has_roll;
        tr
    }

    /// Pose and true surge (m/s along the forward axis) at time `t`.
    pub fn sample(&self, t: f64) -> (Pose, f64) {
        let k = self.kinematics(t);
        (k.pose, k.surge())
    }

    /// Pose and velocity in B at time `t` (the splines and their slopes).
    pub fn kinematics(&self, t: f64) -> Kinematics {
        let (x, vx) = self.cols[0].eval(t);
        let (y, vy) = self.cols[1].eval(t);
        let (z, vz) = self.cols[2].eval(t);
        let (pitch, _) = self.cols[3].eval(t);
        let (yaw, _) = self.cols[4].eval(t);
        let mut pose = Pose::new(x, y, z, Angle::from_rad(pitch), Angle::from_rad(yaw));
        if self.has_roll {
            pose.roll = Angle::from_rad(self.cols[5].eval(t).0);
        }
        Kinematics {
            pose,
            velocity: BeamVec([vx, vy, vz]),
        }
    }

    /// How many frames [`Self::frame_times`] gives at `rate_hz`, known
    /// without counting (saturating for absurd spans).
    pub fn frame_count(&self, rate_hz: f64) -> u64 {
        let n = ((self.t_end() - self.t0()) * rate_hz + 1e-9).floor();
        (n as u64).saturating_add(1)
    }

    /// How many frames of `n` samples at `sample_hz` give while their
    /// middle, t0 + k / rate + (n − 1) / (2 · sample_hz), is ≤ t_end
    /// (MODEL.md); [`Self::frame_count`] for n = 1.
    pub fn burst_count(&self, rate_hz: f64, n: usize, sample_hz: f64) -> u64 {
        let half = (n.saturating_sub(1)) as f64 / (2.0 * sample_hz);
        let span = self.t_end() - self.t0() - half;
        if span < 0.0 {
            return 0;
        }
        let k = (span * rate_hz + 1e-9).floor();
        (k as u64).saturating_add(1)
    }

    /// The frame times t0 + k / rate, k = 0, 1, … while t ≤ t_end.
    pub fn frame_times(&self, rate_hz: f64) -> impl Iterator<Item = f64> + '_ {
        let (t0, t_end) = (self.t0(), self.t_end());
        // Tolerance so that t_end itself is sampled despite rounding.
        let n = ((t_end - t0) * rate_hz + 1e-9).floor() as u64;
        (0..=n).map(move |k| t0 + k as f64 / rate_hz)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DIVE: &str = "t,x,y,z,pitch,yaw\n0,8.5,0,0,10,0\n2.6,7.22,0,0.22,8.7,0\n5.2,5.93,0,0.38,5.2,0\n8,4.53,0,0.45,0,0\n";

    #[test]
    fn moved_keeps_the_course_beside_the_original() {
        let tr = Trajectory::parse(DIVE, "dive.csv").unwrap();
        let (dp, dw) = (Angle::from_deg(3.0), Angle::from_deg(-4.0));
        let m = tr.moved(0.5, -0.2, dp, dw);
        for t in [0.0, 1.3, 2.6, 7.9] {
            let (a, b) = (tr.kinematics(t), m.kinematics(t));
            assert!((b.pose.x - a.pose.x).abs() < 1e-12);
            assert!((b.pose.y - a.pose.y - 0.5).abs() < 1e-12);
            assert!((b.pose.z - a.pose.z + 0.2).abs() < 1e-12);
            assert!((b.pose.pitch.deg() - a.pose.pitch.deg() - 3.0).abs() < 1e-9);
            assert!((b.pose.yaw.deg() - a.pose.yaw.deg() + 4.0).abs() < 1e-9);
            // The same velocity over the ground: a course beside it.
            let (vb, va) = (b.velocity.0, a.velocity.0);
            assert!(
                (0..3).all(|i| (vb[i] - va[i]).abs() < 1e-9),
                "{vb:?} vs {va:?}"
            );
        }
    }

    #[test]
    fn dive_has_41_frames_at_5_hz_and_positive_surge() {
        let tr = Trajectory::parse(DIVE, "dive.csv").unwrap();
        let times: Vec<f64> = tr.frame_times(5.0).collect();
        assert_eq!(times.len(), 41);
        assert!((times[40] - 8.0).abs() < 1e-12);
        let (p, surge) = tr.sample(2.6);
        assert!((p.x - 7.22).abs() < 1e-12 && (p.pitch.deg() - 8.7).abs() < 1e-9);
        // approaching at about 0.5 m/s, bow towards the beacon
        assert!(surge > 0.4 && surge < 0.6, "{surge}");
    }

    /// Spec v3: a roll column is splined as the others; without one roll is
    /// exactly 0 and everything else as before.
    #[test]
    fn a_roll_column_is_splined_and_its_absence_is_zero() {
        let rolled = "t,x,y,z,pitch,yaw,roll\n0,8.5,0,0,10,0,0\n2.6,7.22,0,0.22,8.7,0,5\n5.2,5.93,0,0.38,5.2,0,-3\n8,4.53,0,0.45,0,0,2\n";
        let (a, b) = (
            Trajectory::parse(DIVE, "dive.csv").unwrap(),
            Trajectory::parse(rolled, "rolled.csv").unwrap(),
        );
        assert!(!a.has_roll() && b.has_roll());
        for t in [0.0, 1.3, 2.6, 6.0, 8.0] {
            let (ka, kb) = (a.kinematics(t), b.kinematics(t));
            assert_eq!(ka.pose.roll.rad().to_bits(), 0);
            assert_eq!(ka.pose.with_roll(kb.pose.roll), kb.pose);
            assert_eq!(ka.velocity, kb.velocity);
        }
        assert!((b.kinematics(2.6).pose.roll.deg() - 5.0).abs() < 1e-9);
        assert!((b.kinematics(5.2).pose.roll.deg() + 3.0).abs() < 1e-9);
        // The end piece, extended past the last knot.
        let past = b.kinematics(8.1).pose.roll.deg();
        assert!(past.is_finite() && past != 2.0, "{past}");
    }

    #[test]
    fn bursts_count_frames_by_their_middle() {
        let tr = Trajectory::parse(DIVE, "dive.csv").unwrap();
        assert_eq!(tr.burst_count(5.0, 1, 5.0), 41);
        // 400 samples at 2 kHz: the middle is 0.09975 s after each frame's
        // start, so the frame at 8.0 s would end past t_end.
        assert_eq!(tr.burst_count(5.0, 400, 2000.0), 40);
    }

    #[test]
    fn bad_csv_is_named() {
        for (text, want) in [
            ("", "dive.csv:1: empty"),
            ("t,x,y\n", "dive.csv:1: header"),
            ("t,x,y,z,pitch,yaw\n0,1,2,3,4\n", "dive.csv:2: expected 6"),
            ("t,x,y,z,pitch,yaw,roll\n0,1,2,3,4,5\n", "dive.csv:2: expected 7"),
            ("t,x,y,z,pitch,yaw,roll\n0,1,0,0,0,0,180\n", "dive.csv:2: roll must be within"),
            ("t,x,y,z,pitch,roll\n0,1,0,0,0,0\n", "dive.csv:1: header"),
            (
                "t,x,y,z,pitch,yaw\n0,1,0,0,0,0\n1,1,0,0,zz,0\n",
                "dive.csv:3: pitch = `zz`",
            ),
            (
                "t,x,y,z,pitch,yaw\n0,1,0,0,0,0\n0,1,0,0,0,0\n",
                "dive.csv:3: t = 0 does not increase",
            ),
            ("t,x,y,z,pitch,yaw\n0,1,0,0,0,0\n", "at least 2 knots"),
            (
                "t,x,y,z,pitch,yaw\n0,8,0,0,0,0\n1,7,0,0,89.9,0\n3,6,0,0,89.9,0\n4,5,0,0,0,0\n",
                "dive.csv:4: between t = 1 and 3 s the spline through the knots (MODEL.md) takes pitch to",
            ),
            (
                "t,x,y,z,pitch,yaw\n0,8,0,0,0,0\n1,7,0,0,0,170\n2,6,0,0,0,170\n3,5,0,0,0,0\n",
                "dive.csv:4: between t = 1 and 2 s the spline through the knots (MODEL.md) takes yaw to",
            ),
        ] {
            let e = Trajectory::parse(text, "dive.csv").unwrap_err().to_string();
            assert!(e.contains(want), "{e} lacks {want}");
        }
    }
}

#[cfg(test)]
mod hardening_tests {
    //! Issue 16: bounded quotes and lines, the byte-order mark, and a frame
    //! count known without counting.
    use super::*;
    use lightpose_core::textfile::MAX_LINE_BYTES;

    #[test]
    fn a_long_header_or_value_is_quoted_as_an_excerpt() {
        let long = "q".repeat(50_000);
        let e = Trajectory::parse(&format!("{long}\n0,1,0,0,0,0\n"), "d.csv")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("d.csv:1: header"), "{}", &e[..100]);
        assert!(e.chars().count() < 300, "{} chars", e.len());
        let text = format!("t,x,y,z,pitch,yaw\n0,1,0,0,0,0\n1,{long},0,0,0,0\n");
        let e = Trajectory::parse(&text, "d.csv").unwrap_err().to_string();
        assert!(e.starts_with("d.csv:3: x = `qqq"), "{}", &e[..100]);
        assert!(e.chars().count() < 300, "{} chars", e.len());
    }

    #[test]
    fn control_characters_are_quoted_escaped_and_still_bounded() {
        // Found by the fuzz target once excerpts escaped control
        // characters: a header of NULs, each five characters escaped.
        let mut data = b"t7.2.\x00\x005,0,0\t".to_vec();
        data.extend([0u8; 67]);
        data.extend(b",10,053,0,0.\x004\x00\t\x1e\x15\x00\x00\x00\x00\x00,0,0\n");
        let e = Trajectory::read(&data[..], "fuzz.csv")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("fuzz.csv:") && !e.contains('\n'), "{e}");
        assert!(e.chars().count() < 400, "{} chars: {e}", e.chars().count());
        assert!(e.contains(r"\u{0}"), "{e}");
    }

    #[test]
    fn a_byte_order_mark_before_the_header_is_accepted() {
        let text = "\u{feff}t,x,y,z,pitch,yaw\n0,1,0,0,0,0\n1,2,0,0,0,0\n";
        let tr = Trajectory::parse(text, "bom.csv").expect("BOM accepted");
        assert_eq!(tr.knots().len(), 2);
    }

    #[test]
    fn a_line_past_the_bound_is_refused_by_its_number_unread() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("long.csv");
        let mut text = "t,x,y,z,pitch,yaw\n0,1,0,0,0,0\n".to_string();
        text.push_str(&"9".repeat(MAX_LINE_BYTES * 4));
        text.push_str(",0,0,0,0,0\n");
        std::fs::write(&p, text).unwrap();
        let e = Trajectory::load(&p).unwrap_err().to_string();
        assert!(
            e.contains("long.csv:3: line longer than"),
            "{}",
            &e[..e.len().min(200)]
        );
        assert!(e.chars().count() < 300);
    }

    #[test]
    fn the_frame_count_is_known_at_once_even_for_absurd_spans() {
        let tr = Trajectory::parse("t,x,y,z,pitch,yaw\n0,8,0,0,0,0\n1e9,4,0,0,0,0\n", "far.csv")
            .unwrap();
        assert_eq!(tr.frame_count(5.0), 5_000_000_001);
        assert_eq!(tr.frame_count(1e300), u64::MAX);
        let dive = Trajectory::parse(
            "t,x,y,z,pitch,yaw\n0,8.5,0,0,10,0\n8,4.53,0,0.45,0,0\n",
            "dive.csv",
        )
        .unwrap();
        assert_eq!(dive.frame_count(5.0), dive.frame_times(5.0).count() as u64);
        let huge = Trajectory::parse(
            "t,x,y,z,pitch,yaw\n-1e300,8,0,0,0,0\n1e300,4,0,0,0,0\n",
            "h.csv",
        );
        // t beyond ±1e10 s is not a time.
        assert!(huge.unwrap_err().to_string().contains("h.csv:2: t"));
    }
}
