//! The replay source: a recorded intensity log as a [`FrameSource`], at its
//! recorded pace or as fast as possible, so that a recording goes through
//! exactly the path of live frames (estimator, POSE, STATUS, recording).
//! The container (JSON Lines or MCAP) is lightpose-logs' business: the
//! log is opened with `lightpose_logs::open` and read through core's
//! [`FrameLog`], so that a replay from MCAP gives the same frames, bit for
//! bit, as from JSONL.
//!
//! Frames come in the order core's `FrameOrder` admits (a frame out of
//! order is an error naming its line). At recorded pace, a forward step of
//! `t` larger than the plan's `max_gap_s` is not slept through: it is
//! counted, logged once, and the frame after it is due one period after
//! the one before (pacing re-anchors there). Every wait ends on the
//! [`Stop`].

use std::path::PathBuf;
use std::time::{Duration, Instant};

use lightpose_core::samples::{Burst, Record};
use lightpose_core::{Frame, FrameLog, LogError};

use crate::config::{Pace, ReplayPlan};
use crate::pace::Stop;

/// Open the log at `path` in its container; a forward step of `t` above
/// `max_gap_s` is flagged as a jump.
fn open_log(path: &std::path::Path, max_gap_s: f64) -> Result<Box<dyn FrameLog + Send>, LogError> {
    Ok(Box::new(
        lightpose_logs::LogFile::open(path)?.with_max_gap_s(max_gap_s),
    ))
}
use crate::text::Text;
use crate::{FrameSource, Sampling, SourceError, SourceHealth, Take};

/// Counters of the passes before the current one.
#[derive(Debug, Default, Clone, Copy)]
struct Done {
    skipped: u64,
    other: u64,
    glitches: u64,
    bad_readings: u64,
}

pub struct ReplaySource {
    path: PathBuf,
    pace: Pace,
    looping: bool,
    max_gap_s: f64,
    log: Box<dyn FrameLog + Send>,
    /// What the log gave first, read at open (see [`ReplaySource::open`]).
    first: Option<Option<Result<Rec, LogError>>>,
    /// The BURST read last (spec v3), its buffer swapped with the
    /// caller's: no copy, no allocation.
    held: Burst,
    /// How the log's BURSTs were sampled (its header's), when they are.
    sampling: Option<Sampling>,
    adc_bits: u8,
    rate_hz: f64,
    stop: Stop,
    /// (instant, t) that realtime pace keeps to: the first frame, or the
    /// frame after the last jump.
    anchor: Option<(Instant, f64)>,
    /// When the last frame was due.
    last_due: Option<Instant>,
    /// Added to seq and t of every frame of the current pass so that a
    /// looping replay keeps both increasing.
    seq_offset: u64,
    t_offset: f64,
    first_of_pass: Option<(u64, f64)>,
    last_out: Option<(u64, f64)>,
    passes: u64,
    done: Done,
    jumps: u64,
    other_logged: bool,
    /// A failed reopen for the next pass: retried at most once a second.
    reopen_failed: Option<Instant>,
}

impl ReplaySource {
    /// Open the log `plan` names; waits for a frame's time end early on
    /// `stop`. The first frame is read here: a log that breaks before it
    /// (an MCAP whose frame channel has another schema, a structure broken
    /// after the header) is refused now, with the error naming the file
    /// and the place, rather than ending the replay at its first frame.
    pub fn open(plan: &ReplayPlan, stop: &Stop) -> Result<ReplaySource, LogError> {
        let mut log = open_log(&plan.log, plan.max_gap_s)?;
        let mut held = Burst::new(log.header().samples_per_frame());
        let first = match read(log.as_mut(), &mut held) {
            Some(Err(e)) if !e.skippable() => return Err(e),
            first => first,
        };
        let h = log.header();
        let sampling = (h.samples_per_frame() > 1).then(|| Sampling {
            sample_hz: h.sample_hz.unwrap_or(h.rate_hz),
            samples_per_frame: h.samples_per_frame(),
            channel_skew_s: h.channel_skew_s.unwrap_or(0.0),
            beacons: h.beacons.clone(),
        });
        Ok(ReplaySource {
            held,
            sampling,
            adc_bits: h.adc_bits,
            rate_hz: h.rate_hz,
            path: plan.log.clone(),
            pace: plan.pace,
            looping: plan.looping,
            max_gap_s: plan.max_gap_s,
            log,
            first: Some(first),
            stop: stop.clone(),
            anchor: None,
            last_due: None,
            seq_offset: 0,
            t_offset: 0.0,
            first_of_pass: None,
            last_out: None,
            passes: 1,
            done: Done::default(),
            jumps: 0,
            other_logged: false,
            reopen_failed: None,
        })
    }

    fn period_s(&self) -> f64 {
        1.0 / self.rate_hz
    }

    /// The log again from its start, for the next pass. A log that cannot
    /// be read any more is bad data (named at its place), tried again at
    /// most once a second.
    fn restart(&mut self) -> Result<(), SourceError> {
        let Some(offset) = self.next_seq_offset() else {
            return Err(self.refuse_loop());
        };
        if let Some(at) = self.reopen_failed {
            if !self.stop.sleep_until(at + Duration::from_secs(1)) {
                return Err(SourceError::Stopped);
            }
        }
        let log = open_log(&self.path, self.max_gap_s).map_err(|e| {
            self.reopen_failed = Some(Instant::now());
            SourceError::BadData {
                place: Text::from_static("replay"),
                msg: Text::format(format_args!("cannot start pass {}: {e}", self.passes + 1)),
            }
        })?;
        self.reopen_failed = None;
        let o = self.log.order();
        self.done.skipped += o.skipped();
        self.done.glitches += o.glitches();
        self.done.other += self.log.other_records();
        self.done.bad_readings += self.log.bad_readings().0;
        self.log = log;
        if let (Some((_, t0)), Some((_, tl))) = (self.first_of_pass, self.last_out) {
            // Next pass starts one frame after this one ended, in seq and t.
            self.seq_offset = offset;
            self.t_offset = tl + self.period_s() - t0;
        }
        self.first_of_pass = None;
        self.passes += 1;
        Ok(())
    }

    /// The seq offset of the next pass: it starts one frame after this
    /// one ended. `None` when its frames' seq would pass `u64::MAX` (a
    /// pass as long as this one, in seq, must fit after it).
    fn next_seq_offset(&self) -> Option<u64> {
        let (Some((s0, _)), Some((sl, _))) = (self.first_of_pass, self.last_out) else {
            return Some(self.seq_offset);
        };
        // seq increases within a pass (core's FrameOrder): sl ≥ s0 + offset.
        let span = sl.saturating_sub(self.seq_offset).saturating_sub(s0);
        let offset = sl.checked_add(1)?.saturating_sub(s0);
        sl.checked_add(1)?.checked_add(span)?;
        Some(offset)
    }

    /// No next pass: its seq would wrap past `u64::MAX` (and a daemon
    /// would count 2^64 frames lost). Said once; the replay ends there.
    fn refuse_loop(&mut self) -> SourceError {
        let last = self.last_out.map_or(0, |(s, _)| s);
        tracing::error!(
            "replay: {}: not looping: pass {} would number its frames past seq {} (the last seq was {last}); the replay ends",
            self.path.display(),
            self.passes + 1,
            u64::MAX
        );
        self.looping = false;
        SourceError::Ended
    }

    /// Shift `f` into the current pass and, at recorded pace, wait for its
    /// time (or a stop); a jump of `t` is counted and not waited for. A
    /// seq that the shift would take past `u64::MAX` (the log grew between
    /// passes) ends the replay, as [`ReplaySource::refuse_loop`] says.
    fn release(&mut self, f: &mut Frame) -> Result<(), SourceError> {
        (f.seq, f.t) = self.release_at(f.seq, f.t)?;
        Ok(())
    }

    /// [`ReplaySource::release`] of a frame or burst at (`seq`, `t`) as
    /// logged: its seq and t in the current pass.
    fn release_at(&mut self, seq0: u64, t0: f64) -> Result<(u64, f64), SourceError> {
        let Some(seq) = seq0.checked_add(self.seq_offset) else {
            return Err(self.refuse_loop());
        };
        if self.first_of_pass.is_none() {
            self.first_of_pass = Some((seq0, t0));
        }
        let f = At {
            seq,
            t: t0 + self.t_offset,
        };
        self.last_out = Some((f.seq, f.t));
        if let Some(dt) = self.log.order().last_jump() {
            self.jumps += 1;
            if self.jumps == 1 {
                tracing::warn!(
                    "replay: {}: t jumps forward by {dt} s before seq {} (more than max_gap_s = {} s): not waited for, counted in STATUS",
                    self.path.display(),
                    f.seq,
                    self.max_gap_s
                );
            }
            if let Some(last) = self.last_due {
                // A period beyond the clock's range: due at once.
                let next = self.period().and_then(|p| last.checked_add(p));
                self.anchor = Some((next.unwrap_or(last), f.t));
            }
        }
        if self.pace == Pace::Realtime {
            let (i0, t0) = *self.anchor.get_or_insert((Instant::now(), f.t));
            // t increases (core's FrameOrder) and jumps re-anchor: the
            // clamp only keeps the sum inside the clock's range.
            let after = Duration::try_from_secs_f64((f.t - t0).clamp(0.0, 1e9));
            let due = after.ok().and_then(|d| i0.checked_add(d)).unwrap_or(i0);
            self.last_due = Some(due);
            self.stop.sleep_until(due);
        }
        Ok((f.seq, f.t))
    }

    /// Say once where the first line of another class was.
    fn note_other(&mut self) {
        if self.other_logged {
            return;
        }
        if let Some(first) = self.log.first_other() {
            tracing::warn!(
                "replay: {first}: not a FRAME, passed over (all such lines are counted in STATUS)"
            );
            self.other_logged = true;
        }
    }
}

/// The next frame of `log` of any kind (FORMATS.md): counts as they are,
/// a demodulated frame as a frame with its amplitudes, a BURST into `held`.
fn read(log: &mut (dyn FrameLog + Send), held: &mut Burst) -> Option<Result<Rec, LogError>> {
    Some(match log.next_record()? {
        Err(e) => Err(e),
        Ok(Record::Frame(f)) => Ok(Rec::Frame(f)),
        Ok(Record::Demodulated(d)) => Ok(Rec::Frame(d.to_frame())),
        Ok(Record::Burst(b)) => {
            held.copy_from(b);
            Ok(Rec::Burst)
        }
    })
}

/// A frame's place as released.
struct At {
    seq: u64,
    t: f64,
}

/// A record read: a frame, or a BURST in `held`.
// A frame is held by value, as everywhere (fixed size, never on the heap).
#[allow(clippy::large_enum_variant)]
enum Rec {
    Frame(Frame),
    Burst,
}

impl ReplaySource {
    /// The next record, shifted into its pass and released at its time.
    fn next_rec(&mut self) -> Result<Rec, SourceError> {
        loop {
            let next = match self.first.take() {
                Some(first) => first,
                None => read(self.log.as_mut(), &mut self.held),
            };
            self.note_other();
            match next {
                Some(Ok(Rec::Frame(mut f))) => {
                    self.release(&mut f)?;
                    return Ok(Rec::Frame(f));
                }
                Some(Ok(Rec::Burst)) => {
                    let (seq, t) = self.release_at(self.held.seq, self.held.t)?;
                    (self.held.seq, self.held.t) = (seq, t);
                    return Ok(Rec::Burst);
                }
                Some(Err(e)) => {
                    // The reader's error was built for this line (its
                    // number, its fault); its words are kept inline when
                    // short.
                    return Err(SourceError::BadData {
                        place: Text::from_static("replay"),
                        msg: Text::format(format_args!("{e}")),
                    });
                }
                None => {
                    if let Some(cut) = self.log.cut() {
                        tracing::warn!("{}: {cut}", self.path.display());
                    }
                    // A loop over a log with no frame at all would spin.
                    if self.looping && self.first_of_pass.is_some() {
                        self.restart()?;
                    } else {
                        return Err(SourceError::Ended);
                    }
                }
            }
        }
    }
}

impl FrameSource for ReplaySource {
    fn next_frame(&mut self) -> Result<Frame, SourceError> {
        match self.next_rec()? {
            Rec::Frame(f) => Ok(f),
            Rec::Burst => Err(crate::bursts_only("replay")),
        }
    }

    fn sampling(&self) -> Option<Sampling> {
        self.sampling.clone()
    }

    fn next_take(&mut self, burst: &mut Burst) -> Result<Take, SourceError> {
        match self.next_rec()? {
            Rec::Frame(f) => Ok(Take::Frame(f)),
            Rec::Burst => {
                std::mem::swap(&mut self.held, burst);
                Ok(Take::Burst)
            }
        }
    }

    fn adc_bits(&self) -> u8 {
        self.adc_bits
    }

    fn describe(&self) -> String {
        format!(
            "replay of {} ({}{}, pass {})",
            self.path.display(),
            match self.pace {
                Pace::Realtime => "recorded pace",
                Pace::Fast => "as fast as possible",
            },
            if self.looping { ", looping" } else { "" },
            self.passes
        )
    }

    /// The log's own rate at recorded pace; none when fast.
    fn period(&self) -> Option<Duration> {
        match self.pace {
            Pace::Realtime => Duration::try_from_secs_f64(self.period_s()).ok(),
            Pace::Fast => None,
        }
    }

    fn rate_hz(&self) -> Option<f64> {
        (self.rate_hz.is_finite() && self.rate_hz > 0.0).then_some(self.rate_hz)
    }

    fn health(&self) -> SourceHealth {
        let (bad_readings, last_bad_reading) = self.log.bad_readings();
        SourceHealth {
            skipped_frames: self.done.skipped + self.log.order().skipped(),
            time_jumps: self.jumps,
            glitches: self.done.glitches + self.log.order().glitches(),
            other_lines: self.done.other + self.log.other_records(),
            bad_readings: self.done.bad_readings + bad_readings,
            last_bad_reading: last_bad_reading.map(str::to_string),
            ..SourceHealth::default()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use lightpose_core::{LogHeader, LogWriter, NDET};

    fn open(log: PathBuf, pace: Pace, looping: bool) -> Result<ReplaySource, LogError> {
        let plan = ReplayPlan {
            log,
            pace,
            looping,
            max_gap_s: lightpose_core::log::DEFAULT_MAX_GAP_S,
        };
        ReplaySource::open(&plan, &Stop::new())
    }

    fn write_log(dir: &std::path::Path, n: u64, rate: f64) -> PathBuf {
        let p = dir.join("r.jsonl");
        let mut w = LogWriter::create(&p, &LogHeader::new(10, rate)).unwrap();
        for s in 0..n {
            w.write_frame(&Frame {
                seq: 10 + s,
                t: s as f64 / rate,
                adc_bits: 10,
                counts: [s as u16; NDET],
                temp_c: None,
                truth: None,
                attitude: None,
                depth: None,
                velocity: None,
                amplitudes: None,
            })
            .unwrap();
        }
        w.flush().unwrap();
        p
    }

    #[test]
    fn fast_replay_ends_and_loop_keeps_seq_increasing() {
        let d = tempfile::tempdir().unwrap();
        let log = write_log(d.path(), 3, 10.0);
        let mut s = open(log.clone(), Pace::Fast, false).unwrap();
        let seqs: Vec<u64> = (0..3).map(|_| s.next_frame().unwrap().seq).collect();
        assert_eq!(seqs, vec![10, 11, 12]);
        assert!(matches!(s.next_frame(), Err(SourceError::Ended)));

        let mut s = open(log, Pace::Fast, true).unwrap();
        let fr: Vec<Frame> = (0..7).map(|_| s.next_frame().unwrap()).collect();
        let seqs: Vec<u64> = fr.iter().map(|f| f.seq).collect();
        assert_eq!(seqs, (10..17).collect::<Vec<_>>());
        for w in fr.windows(2) {
            assert!(
                (w[1].t - w[0].t - 0.1).abs() < 1e-9,
                "{} {}",
                w[0].t,
                w[1].t
            );
        }
        assert_eq!(fr[3].counts, fr[0].counts);
    }

    #[test]
    fn recorded_pace_takes_the_logs_time() {
        let d = tempfile::tempdir().unwrap();
        let log = write_log(d.path(), 6, 50.0); // 5 intervals of 20 ms
        let mut s = open(log, Pace::Realtime, false).unwrap();
        let t0 = Instant::now();
        while s.next_frame().is_ok() {}
        let el = t0.elapsed();
        assert!(
            el >= Duration::from_millis(95) && el < Duration::from_millis(600),
            "{el:?}"
        );
    }

    #[test]
    fn bad_lines_are_named_and_missing_file_refused() {
        let d = tempfile::tempdir().unwrap();
        let log = write_log(d.path(), 1, 10.0);
        let mut text = std::fs::read_to_string(&log).unwrap();
        text.push_str("garbage\n");
        std::fs::write(&log, text).unwrap();
        let mut s = open(log.clone(), Pace::Fast, false).unwrap();
        assert!(s.next_frame().is_ok());
        let e = s.next_frame().unwrap_err().to_string();
        assert!(e.contains("r.jsonl:3"), "{e}");
        let e = open(d.path().join("none"), Pace::Fast, false)
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("none"), "{e}");
    }

    /// The same log as JSONL and as MCAP: the same frames, bit for bit.
    #[test]
    fn mcap_replays_as_jsonl() {
        let d = tempfile::tempdir().unwrap();
        let jsonl = write_log(d.path(), 7, 10.0);
        let mcap = d.path().join("r.mcap");
        let opts = lightpose_logs::McapOptions {
            chunk_bytes: 512,
            ..Default::default()
        };
        lightpose_logs::convert(&jsonl, &mcap, None, &opts, |e| panic!("{e}")).unwrap();
        let all = |p: PathBuf| {
            let mut s = open(p, Pace::Fast, false).unwrap();
            let mut v = Vec::new();
            while let Ok(f) = s.next_frame() {
                v.push(f);
            }
            (v, s.adc_bits(), s.rate_hz())
        };
        let (a, b) = (all(jsonl), all(mcap));
        assert_eq!(a.0.len(), 7);
        assert_eq!(a, b);
    }

    #[test]
    fn bad_mcap_is_named_with_its_offset() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("g.mcap");
        let mut bytes = b"\x89MCAP0\r\n".to_vec();
        bytes.extend_from_slice(b"garbage garbage garbage");
        std::fs::write(&p, bytes).unwrap();
        let e = open(p, Pace::Fast, false).err().unwrap().to_string();
        assert!(
            e.starts_with(&format!("{}: byte 8: ", d.path().join("g.mcap").display())),
            "{e}"
        );
        assert!(!e.contains('\n'), "{e}");
    }

    #[test]
    fn a_stop_ends_the_wait_for_a_far_frame() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("gap.jsonl");
        let mut w = LogWriter::create(&p, &LogHeader::new(10, 10.0)).unwrap();
        for (seq, t) in [(0, 0.0), (1, 60.0)] {
            let mut f = Frame {
                seq,
                t,
                adc_bits: 10,
                counts: [1; NDET],
                temp_c: None,
                truth: None,
                attitude: None,
                depth: None,
                velocity: None,
                amplitudes: None,
            };
            f.counts[0] = seq as u16;
            w.write_frame(&f).unwrap();
        }
        w.flush().unwrap();
        let stop = Stop::new();
        let plan = ReplayPlan {
            log: p,
            pace: Pace::Realtime,
            looping: false,
            max_gap_s: 3600.0,
        };
        let mut s = ReplaySource::open(&plan, &stop).unwrap();
        assert_eq!(s.next_frame().unwrap().seq, 0);
        let raiser = {
            let stop = stop.clone();
            std::thread::spawn(move || {
                std::thread::sleep(Duration::from_millis(50));
                stop.raise();
            })
        };
        let t0 = Instant::now();
        assert_eq!(s.next_frame().unwrap().seq, 1);
        raiser.join().unwrap();
        assert!(t0.elapsed() < Duration::from_secs(5), "{:?}", t0.elapsed());
    }

    fn write_frames(p: &std::path::Path, rate: f64, frames: &[(u64, f64)]) {
        let mut w = LogWriter::create(p, &LogHeader::new(10, rate)).unwrap();
        for &(seq, t) in frames {
            w.write_frame(&Frame {
                seq,
                t,
                adc_bits: 10,
                counts: [(seq % 1000) as u16; NDET],
                temp_c: None,
                truth: None,
                attitude: None,
                depth: None,
                velocity: None,
                amplitudes: None,
            })
            .unwrap();
        }
        w.flush().unwrap();
    }

    /// Issue 16: a forward jump of t past the gap bound is counted and not
    /// slept through: the frame after it comes one period after the one
    /// before.
    #[test]
    fn a_jump_past_the_gap_bound_is_cut_to_one_period_and_counted() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("jump.jsonl");
        write_frames(&p, 50.0, &[(0, 0.0), (1, 0.02), (2, 60.02), (3, 60.04)]);
        let plan = ReplayPlan {
            log: p,
            pace: Pace::Realtime,
            looping: false,
            max_gap_s: 1.0,
        };
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let mut s = ReplaySource::open(&plan, &Stop::new()).unwrap();
            let t0 = Instant::now();
            let mut seqs = Vec::new();
            while let Ok(f) = s.next_frame() {
                seqs.push(f.seq);
            }
            let _ = tx.send((seqs, t0.elapsed(), s.health().time_jumps));
        });
        let (seqs, took, jumps) = rx
            .recv_timeout(Duration::from_secs(5))
            .expect("the jump is not slept through");
        assert_eq!(seqs, vec![0, 1, 2, 3]);
        assert_eq!(jumps, 1);
        assert!(took < Duration::from_secs(2), "{took:?}");
    }

    /// Issue 16: frames out of order are skipped (each an error naming its
    /// line), so a looping replay keeps seq and t increasing and a step back
    /// is never a jump forward by 2^64.
    #[test]
    fn frames_out_of_order_are_named_and_a_loop_stays_increasing() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("back.jsonl");
        write_frames(&p, 10.0, &[(5, 0.0), (6, 0.1), (7, 0.2), (3, 0.3)]);
        let mut s = open(p, Pace::Fast, true).unwrap();
        let mut seqs = Vec::new();
        let mut errs = Vec::new();
        while seqs.len() < 6 {
            match s.next_frame() {
                Ok(f) => seqs.push(f.seq),
                Err(e) => errs.push(e.to_string()),
            }
        }
        assert_eq!(seqs, vec![5, 6, 7, 8, 9, 10]);
        assert!(
            errs[0].contains("back.jsonl:5: seq 3 after seq 7"),
            "{errs:?}"
        );
        assert!(s.health().skipped_frames >= 1);
    }

    /// Audit: a looping replay of a log whose last seq is `u64::MAX`
    /// overflowed `seq` (a panic in debug; in release a wrap, and 2^64
    /// frames counted lost). The loop is refused, once, and the replay
    /// ends; a log that fits a few passes loops until the next would not.
    #[test]
    fn a_loop_whose_seq_would_pass_u64_max_ends_instead() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("top.jsonl");
        write_frames(
            &p,
            10.0,
            &[(u64::MAX - 2, 0.0), (u64::MAX - 1, 0.1), (u64::MAX, 0.2)],
        );
        let mut s = open(p, Pace::Fast, true).unwrap();
        let seqs: Vec<u64> = (0..3).map(|_| s.next_frame().unwrap().seq).collect();
        assert_eq!(seqs, vec![u64::MAX - 2, u64::MAX - 1, u64::MAX]);
        assert!(matches!(s.next_frame(), Err(SourceError::Ended)));
        assert!(
            matches!(s.next_frame(), Err(SourceError::Ended)),
            "stays ended"
        );

        let p = d.path().join("wide.jsonl");
        write_frames(&p, 10.0, &[(0, 0.0), (1, 0.1), (1 << 62, 0.2)]);
        let mut s = open(p, Pace::Fast, true).unwrap();
        let mut seqs = Vec::new();
        while let Ok(f) = s.next_frame() {
            seqs.push(f.seq);
        }
        // Passes end at 2^62, 2^63 + 1 and 3·2^62 + 2; a fourth would
        // end past u64::MAX.
        assert_eq!(seqs.len(), 9, "{seqs:?}");
        assert!(seqs.windows(2).all(|w| w[0] < w[1]), "{seqs:?}");
        assert_eq!(seqs[8], 3 * (1 << 62) + 2);
    }

    /// Audit: at a jump of `t` the next due time added a period made from
    /// the log's rate with `Duration::from_secs_f64`, which panics on a
    /// period beyond `Duration`'s range. Such a frame is due at once.
    #[test]
    fn a_jump_with_a_period_beyond_the_clock_does_not_panic() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("jump.jsonl");
        write_frames(&p, 50.0, &[(0, 0.0), (1, 0.02), (2, 60.02), (3, 60.04)]);
        let plan = ReplayPlan {
            log: p,
            pace: Pace::Realtime,
            looping: false,
            max_gap_s: 1.0,
        };
        let mut s = ReplaySource::open(&plan, &Stop::new()).unwrap();
        // What a header's rate no longer may be: a period of 1e300 s.
        s.rate_hz = 1e-300;
        let t0 = Instant::now();
        let mut seqs = Vec::new();
        while let Ok(f) = s.next_frame() {
            seqs.push(f.seq);
        }
        assert_eq!(seqs, vec![0, 1, 2, 3]);
        assert!(t0.elapsed() < Duration::from_secs(2), "{:?}", t0.elapsed());
    }

    /// Issue 16: a log whose header went bad between passes is said to be
    /// bad data at its line, not "device unavailable".
    #[test]
    fn a_bad_header_at_the_next_pass_is_named_as_such() {
        let d = tempfile::tempdir().unwrap();
        let log = write_log(d.path(), 2, 10.0);
        let mut s = open(log.clone(), Pace::Fast, true).unwrap();
        assert!(s.next_frame().is_ok() && s.next_frame().is_ok());
        std::fs::write(&log, "{\"class\":\"FRAME\"}\n").unwrap();
        let e = s.next_frame().unwrap_err().to_string();
        assert!(!e.contains("unavailable"), "{e}");
        assert!(
            e.contains("r.jsonl:1: first line must be class HEADER"),
            "{e}"
        );
    }
}
