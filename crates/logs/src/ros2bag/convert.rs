//! `lightpose convert --ros2`'s work: an intensity log (JSONL or MCAP) and
//! the POSE lines of its replay into a ROS 2 bag ([`super::Ros2Bag`]); an
//! MCAP recording without a POSE file gives the poses it holds itself.
//! The frames say when each pose was captured and that the poses belong
//! to this log: each POSE must name a frame of it by `seq` (with the same
//! `t`, for frames of counts), in order; a POSE that names none ends the
//! conversion with its line, since a bag of another log's poses would be
//! wrong without a sign. Only `ok` poses become messages, as on the node
//! ([`crate::ros2msg::solve`]). Stamp and log time: the POSE's `time` (the
//! daemon's wall-clock capture) when it has one, else its frame's `t` (a
//! simulated or replayed log's own epoch).

use super::{nanos, Ros2Bag, Ros2BagOptions};
use crate::convert::{ConvertError, PoseFeed};
use crate::lines::Carried;
use crate::ros2msg::{diagnostics, solve, LastEstimate, Solved, Time};
use crate::LogFile;
use lightpose_core::{FrameLog, LogError, PoseEstimate, Record, Status, StdDev};
use std::fs::File;
use std::io::BufWriter;
use std::path::Path;

/// What a conversion to a ROS 2 bag did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Ros2Summary {
    pub frames: u64,
    /// POSE lines read.
    pub poses: u64,
    /// Poses written (each as pose, odometry and `/tf`).
    pub written: u64,
    /// Poses not `ok` (or lacking a value or σ): not written.
    pub not_ok: u64,
    /// STATUS messages of an MCAP recording written as `/diagnostics`.
    pub diagnostics: u64,
    /// Frames and POSE lines refused and skipped (counted, as convert does).
    pub skipped: u64,
}

/// The fields of a POSE line a ROS 2 message needs.
#[derive(serde::Deserialize)]
struct PoseLine {
    seq: Option<u64>,
    t: Option<f64>,
    time: Option<f64>,
    status: Option<String>,
    x: Option<f64>,
    y: Option<f64>,
    z: Option<f64>,
    pitch: Option<f64>,
    yaw: Option<f64>,
    roll: Option<f64>,
    surge: Option<f64>,
    #[serde(default)]
    std: Option<StdLine>,
    /// A docking station's frame (spec v3), which the pose is in.
    frame: Option<String>,
}

#[derive(serde::Deserialize, Default)]
struct StdLine {
    x: Option<f64>,
    y: Option<f64>,
    z: Option<f64>,
    pitch: Option<f64>,
    yaw: Option<f64>,
    roll: Option<f64>,
    surge: Option<f64>,
}

impl PoseLine {
    /// The estimate it reports, as `ok` (only those are written).
    fn estimate(&self, seq: u64, t: f64) -> PoseEstimate {
        let mut e = PoseEstimate::empty(seq, t, Status::Ok, "");
        (e.x, e.y, e.z) = (self.x, self.y, self.z);
        (e.pitch_deg, e.yaw_deg, e.roll_deg) = (self.pitch, self.yaw, self.roll);
        e.surge = self.surge;
        let s = self.std.as_ref();
        e.std = StdDev {
            x: s.and_then(|s| s.x),
            y: s.and_then(|s| s.y),
            z: s.and_then(|s| s.z),
            pitch: s.and_then(|s| s.pitch),
            yaw: s.and_then(|s| s.yaw),
            surge: s.and_then(|s| s.surge),
            roll: s.and_then(|s| s.roll),
        };
        e
    }
}

/// Whether two `t` are one instant: the POSE carries its frame's `t`
/// (written with serde_json's round trip, so equal; 1e-9 relative for a
/// POSE file some other tool wrote).
fn same_t(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(1.0)
}

/// The bag being written, what it holds so far, and what `/diagnostics`
/// needs: the latest pose's status, and the clock its STATUS is put on.
struct Bagging<W: std::io::Write> {
    bag: Ros2Bag<W>,
    s: Ros2Summary,
    last: LastEstimate,
    /// The latest pose's log time `t` and its stamp (the wall clock when
    /// the POSE had one): a STATUS at log time t' is stamped
    /// stamp + (t' − t), as the recorder's bag does.
    clock: Option<(f64, f64)>,
}

impl<W: std::io::Write> Bagging<W> {
    /// The STATUS messages an MCAP reader carried up to here, as
    /// `/diagnostics` (the other carried channels have no ROS 2 type).
    fn carried(&mut self, log: &mut LogFile) -> Result<(), ConvertError> {
        let LogFile::Mcap(r) = log else { return Ok(()) };
        for c in r.take_carried() {
            let Carried::Message {
                channel,
                log_time,
                data,
                ..
            } = c
            else {
                continue;
            };
            let is_status = r
                .channel_decl(channel)
                .is_some_and(|d| d.topic == crate::schema::topic::STATUS);
            let Some((t0, wall0)) = self.clock.filter(|_| is_status) else {
                continue;
            };
            let wall = wall0 + (log_time as f64 * 1e-9 - t0);
            let d = diagnostics(&data, &self.last, Time::from_unix(wall));
            let at = nanos(&d.header.stamp);
            self.bag.write_diagnostics(&d, at)?;
            self.s.diagnostics += 1;
        }
        Ok(())
    }
}

/// Where the poses come from.
enum Source {
    /// A file of POSE lines, read in step with the frames.
    Feed(PoseFeed),
    /// An MCAP recording's own `/lightpose/pose`, kept by its reader (a
    /// pose is read before the next frame: it is its previous frame's).
    Kept(Vec<u8>),
}

/// A frame poses are matched against: its seq and, for a FRAME of
/// counts, its t.
type At = (u64, Option<f64>);

/// Convert `input` (a log) and `poses` (its POSE lines; `None`: those of
/// an MCAP `input`) into the ROS 2 bag `output` (see the module docs).
/// Each refused frame or POSE line is handed to `on_skip` and skipped; a
/// POSE that matches no frame, a broken input or a write error ends it,
/// and the bag begun is removed (no half a bag that looks whole).
pub fn convert_ros2(
    input: &Path,
    output: &Path,
    poses: Option<&Path>,
    opts: &Ros2BagOptions,
    on_skip: impl FnMut(&LogError),
) -> Result<Ros2Summary, ConvertError> {
    check_paths(input, output, poses)?;
    let mut created = false;
    let r = write_bag(input, output, poses, opts, on_skip, &mut created);
    if r.is_err() && created {
        // This call created it: nothing else's is removed.
        let _ = std::fs::remove_file(output);
    }
    r
}

/// The log opened, where its poses come from, and the bag begun.
type Opened = (LogFile, Source, Bagging<BufWriter<File>>);

fn open_bag(
    input: &Path,
    output: &Path,
    poses: Option<&Path>,
    opts: &Ros2BagOptions,
    created: &mut bool,
) -> Result<Opened, ConvertError> {
    let mut log = LogFile::open(input)?;
    let src = match (poses, &mut log) {
        (Some(p), _) => Source::Feed(PoseFeed::open(p)?),
        (None, LogFile::Mcap(r)) => {
            r.keep_poses(true);
            Source::Kept(Vec::new())
        }
        (None, LogFile::Jsonl(_)) => {
            return Err(ConvertError::Usage(format!(
                "{}: convert --ros2 of a JSONL log needs --poses POSES.jsonl (the POSE lines of `lightpose replay --out`)",
                input.display()
            )))
        }
    };
    let f = File::create(output).map_err(|err| ConvertError::File {
        file: output.display().to_string(),
        err,
    })?;
    *created = true;
    let opts = Ros2BagOptions {
        file_name: output
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default(),
        ..opts.clone()
    };
    let bag = Ros2Bag::new(BufWriter::with_capacity(1 << 16, f), &opts)?;
    if let LogFile::Mcap(r) = &mut log {
        // Its STATUS becomes /diagnostics.
        r.keep_carried(true);
    }
    let out = Bagging {
        bag,
        s: Ros2Summary::default(),
        last: LastEstimate::default(),
        clock: None,
    };
    Ok((log, src, out))
}

fn write_bag(
    input: &Path,
    output: &Path,
    poses: Option<&Path>,
    opts: &Ros2BagOptions,
    mut on_skip: impl FnMut(&LogError),
    created: &mut bool,
) -> Result<Ros2Summary, ConvertError> {
    let (mut log, mut src, mut out) = open_bag(input, output, poses, opts, created)?;
    let name = input.display().to_string();
    let mut prev: Option<At> = None;
    while let Some(r) = log.next_record() {
        let at = match r {
            Ok(Record::Frame(f)) => (f.seq, Some(f.t)),
            Ok(r) => (r.seq(), None),
            Err(e) if e.skippable() => {
                out.s.skipped += 1;
                on_skip(&e);
                continue;
            }
            Err(e) => return Err(e.into()),
        };
        out.s.frames += 1;
        match &mut src {
            Source::Kept(buf) => kept(&mut log, buf, &name, prev, Some(at.0), &mut out)?,
            Source::Feed(feed) => {
                out.s.poses += feed.take_through(Some(at.0), |feed, pseq, text| {
                    let bad = |m: String| feed.bad(m);
                    if pseq != at.0 {
                        return Err(bad(no_frame(pseq, &name, prev.map(|p| p.0), Some(at.0))));
                    }
                    write_pose(&bad, text, at, &mut out)
                })?;
                for e in feed.refused.drain(..) {
                    out.s.skipped += 1;
                    on_skip(&e);
                }
            }
        }
        out.carried(&mut log)?;
        prev = Some(at);
    }
    match &mut src {
        Source::Kept(buf) => kept(&mut log, buf, &name, prev, None, &mut out)?,
        Source::Feed(feed) => {
            out.s.poses += feed.take_through(None, |feed, pseq, _| {
                Err(feed.bad(no_frame(pseq, &name, prev.map(|p| p.0), None)))
            })?;
        }
    }
    out.carried(&mut log)?;
    let Bagging { bag, s, .. } = out;
    if s.poses == 0 {
        let what = match poses {
            Some(p) => format!(
                "{}: no POSE line (the output of `lightpose replay --out`)",
                p.display()
            ),
            None => format!("{name}: no pose on /lightpose/pose: give its POSE lines with --poses"),
        };
        return Err(ConvertError::Usage(what));
    }
    bag.finish()?;
    Ok(s)
}

/// The poses an MCAP reader kept while reading up to the frame `next`
/// (`None`: to the end): each must be of the frame before, `prev`.
fn kept<W: std::io::Write>(
    log: &mut LogFile,
    buf: &mut Vec<u8>,
    name: &str,
    prev: Option<At>,
    next: Option<u64>,
    out: &mut Bagging<W>,
) -> Result<(), ConvertError> {
    let LogFile::Mcap(r) = log else { return Ok(()) };
    buf.clear();
    r.take_poses(buf).map_err(|err| ConvertError::File {
        file: name.to_string(),
        err,
    })?;
    let bad = |m: String| ConvertError::Usage(format!("{name}: /lightpose/pose: {m}"));
    for line in buf.split(|&b| b == b'\n').filter(|l| !l.is_empty()) {
        out.s.poses += 1;
        let seq = serde_json::from_slice::<PoseLine>(line)
            .ok()
            .and_then(|p| p.seq)
            .ok_or_else(|| bad("a POSE without an integer seq".into()))?;
        match prev {
            Some(at) if at.0 == seq => write_pose(&bad, line, at, out)?,
            _ => return Err(bad(no_frame(seq, name, prev.map(|p| p.0), next))),
        }
    }
    Ok(())
}

fn check_paths(input: &Path, output: &Path, poses: Option<&Path>) -> Result<(), ConvertError> {
    if output.extension().and_then(|e| e.to_str()) != Some("mcap") {
        return Err(ConvertError::Usage(format!(
            "{}: a ROS 2 bag is an MCAP: name it .mcap",
            output.display()
        )));
    }
    let pairs = [
        (Some(input), "--in and --out"),
        (poses, "--poses and --out"),
    ];
    for (a, what) in pairs {
        let Some(a) = a else { continue };
        let b = output;
        if crate::same_file(a, b) || crate::same_place(a, b) {
            return Err(ConvertError::Usage(format!(
                "{}: {what} are the same file",
                a.display()
            )));
        }
    }
    Ok(())
}

fn no_frame(seq: u64, log: &str, prev: Option<u64>, next: Option<u64>) -> String {
    let around = match (prev, next) {
        (Some(p), Some(n)) => format!("between its frames {p} and {n}"),
        (None, Some(n)) => format!("before its first frame {n}"),
        (Some(p), None) => format!("after its last frame {p}"),
        (None, None) => "which has no frames".to_string(),
    };
    format!(
        "POSE seq {seq} names no frame of {log} ({around}): are these the poses of another log?"
    )
}

/// One POSE line of the frame `at` into the bag.
fn write_pose<W: std::io::Write>(
    bad: &dyn Fn(String) -> ConvertError,
    text: &[u8],
    at: At,
    out: &mut Bagging<W>,
) -> Result<(), ConvertError> {
    let (seq, t) = at;
    let p: PoseLine = serde_json::from_slice(crate::encode::trim_newline(text))
        .map_err(|e| bad(format!("POSE seq {seq}: {e}")))?;
    let pt =
        p.t.ok_or_else(|| bad(format!("POSE seq {seq}: no number t")))?;
    if let Some(ft) = t.filter(|ft| !same_t(*ft, pt)) {
        return Err(bad(format!(
            "POSE seq {seq} has t = {pt} where the log's frame {seq} has t = {ft}: are these the poses of another log?"
        )));
    }
    let stamp = p.time.filter(|w| w.is_finite()).unwrap_or(pt);
    let status = p.status.as_deref().and_then(Status::parse);
    if status.is_some() {
        (out.last.status, out.last.seq) = (status, seq);
    }
    out.clock = Some((pt, stamp));
    let ok = status == Some(Status::Ok);
    let Some(solved) = solve(&p.estimate(seq, pt), stamp).filter(|_| ok) else {
        out.s.not_ok += 1;
        return Ok(());
    };
    // Spec v3: a station's pose is in its frame D.
    let mut solved: Solved<'_> = solved;
    solved.station = p.frame.as_deref();
    out.bag.write_estimate(&solved, nanos(&solved.stamp))?;
    out.s.written += 1;
    Ok(())
}
