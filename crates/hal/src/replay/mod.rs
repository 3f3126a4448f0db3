//! The replay source: a recorded intensity log as a [`FrameSource`], at its
//! recorded pace or as fast as possible, so that a recording goes through
//! exactly the path of live frames (estimator, POSE, STATUS, recording).
//! The container (JSON Lines or MCAP) is lightpose-logs' business: the
//! log is opened with `lightpose_logs::open` and read through core's
//! [`FrameLog`], so that a replay from MCAP gives the same frames, bit for
//! bit, as from JSONL.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use lightpose_core::{Frame, FrameLog, LogError};
use lightpose_logs::open as open_log;

use crate::config::{Pace, ReplayPlan};
use crate::pace::Stop;
use crate::{FrameSource, SourceError};

pub struct ReplaySource {
    path: PathBuf,
    pace: Pace,
    looping: bool,
    log: Box<dyn FrameLog + Send>,
    /// What the log gave first, read at open (see [`ReplaySource::open`]).
    first: Option<Option<Result<Frame, LogError>>>,
    adc_bits: u8,
    rate_hz: f64,
    stop: Stop,
    /// (instant, t) of the first frame: realtime pace keeps to it.
    anchor: Option<(Instant, f64)>,
    /// Added to seq and t of every frame of the current pass so that a
    /// looping replay keeps both increasing.
    seq_offset: u64,
    t_offset: f64,
    first_of_pass: Option<(u64, f64)>,
    last_out: Option<(u64, f64)>,
    passes: u64,
}

impl ReplaySource {
    /// Open the log `plan` names; waits for a frame's time end early on
    /// `stop`. The first frame is read here: a log that breaks before it
    /// (an MCAP whose frame channel has another schema, a structure broken
    /// after the header) is refused now, with the error naming the file
    /// and the place, rather than ending the replay at its first frame.
    pub fn open(plan: &ReplayPlan, stop: &Stop) -> Result<ReplaySource, LogError> {
        let mut log = open_log(&plan.log)?;
        let first = match log.next_frame() {
            Some(Err(e)) if !e.skippable() => return Err(e),
            first => first,
        };
        let h = log.header();
        Ok(ReplaySource {
            adc_bits: h.adc_bits,
            rate_hz: h.rate_hz,
            path: plan.log.clone(),
            pace: plan.pace,
            looping: plan.looping,
            log,
            first: Some(first),
            stop: stop.clone(),
            anchor: None,
            seq_offset: 0,
            t_offset: 0.0,
            first_of_pass: None,
            last_out: None,
            passes: 1,
        })
    }

    fn restart(&mut self) -> Result<(), SourceError> {
        self.log = open_log(&self.path).map_err(|e| SourceError::Unavailable {
            place: "replay".into(),
            msg: e.to_string(),
        })?;
        let period = 1.0 / self.rate_hz;
        if let (Some((s0, t0)), Some((sl, tl))) = (self.first_of_pass, self.last_out) {
            // Next pass starts one frame after this one ended, in seq and t.
            self.seq_offset = sl + 1 - s0;
            self.t_offset = tl + period - t0;
        }
        self.first_of_pass = None;
        self.passes += 1;
        Ok(())
    }

    /// Shift `f` into the current pass and, at recorded pace, wait for its
    /// time (or a stop).
    fn release(&mut self, mut f: Frame) -> Frame {
        if self.first_of_pass.is_none() {
            self.first_of_pass = Some((f.seq, f.t));
        }
        f.seq += self.seq_offset;
        f.t += self.t_offset;
        self.last_out = Some((f.seq, f.t));
        if self.pace == Pace::Realtime {
            let (i0, t0) = *self.anchor.get_or_insert((Instant::now(), f.t));
            let due = i0 + Duration::from_secs_f64((f.t - t0).clamp(0.0, 1e9));
            self.stop.sleep_until(due);
        }
        f
    }
}

impl FrameSource for ReplaySource {
    fn next_frame(&mut self) -> Result<Frame, SourceError> {
        loop {
            let next = match self.first.take() {
                Some(first) => first,
                None => self.log.next_frame(),
            };
            match next {
                Some(Ok(f)) => return Ok(self.release(f)),
                Some(Err(e)) => {
                    return Err(SourceError::BadData {
                        place: "replay".into(),
                        msg: e.to_string(),
                    })
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
            Pace::Realtime => Duration::try_from_secs_f64(1.0 / self.rate_hz).ok(),
            Pace::Fast => None,
        }
    }

    fn rate_hz(&self) -> Option<f64> {
        (self.rate_hz.is_finite() && self.rate_hz > 0.0).then_some(self.rate_hz)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use lightpose_core::{LogHeader, LogWriter, NDET};

    fn open(log: PathBuf, pace: Pace, looping: bool) -> Result<ReplaySource, LogError> {
        ReplaySource::open(&ReplayPlan { log, pace, looping }, &Stop::new())
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
}
