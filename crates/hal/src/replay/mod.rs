//! The replay backend: a recorded intensity log as a FrameSource, at its
//! recorded pace or as fast as possible, so that a recording goes through
//! exactly the path of live frames (estimator, POSE, STATUS, recording).
//! It lives here because lightpose-hal has no log-backed source.

use crate::config::{Pace, ReplayBackend};
use lightpose_core::{Frame, LogReader};
use lightpose_hal::{FrameSource, SourceError};
use std::fs::File;
use std::io::BufReader;
use std::path::PathBuf;
use std::time::{Duration, Instant};

pub struct ReplaySource {
    path: PathBuf,
    pace: Pace,
    looping: bool,
    reader: LogReader<BufReader<File>>,
    adc_bits: u8,
    rate_hz: f64,
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
    pub fn open(cfg: &ReplayBackend) -> Result<ReplaySource, SourceError> {
        let reader = LogReader::open(&cfg.log).map_err(|e| SourceError::Unavailable {
            place: "replay".into(),
            msg: e.to_string(),
        })?;
        let h = reader.header();
        Ok(ReplaySource {
            adc_bits: h.adc_bits,
            rate_hz: h.rate_hz,
            path: cfg.log.clone(),
            pace: cfg.pace,
            looping: cfg.looping,
            reader,
            anchor: None,
            seq_offset: 0,
            t_offset: 0.0,
            first_of_pass: None,
            last_out: None,
            passes: 1,
        })
    }

    /// The log's own frame rate (its header).
    pub fn rate_hz(&self) -> f64 {
        self.rate_hz
    }

    fn restart(&mut self) -> Result<(), SourceError> {
        self.reader = LogReader::open(&self.path).map_err(|e| SourceError::Unavailable {
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
}

impl FrameSource for ReplaySource {
    fn next_frame(&mut self) -> Result<Frame, SourceError> {
        loop {
            match self.reader.next_frame() {
                Some(Ok(mut f)) => {
                    if self.first_of_pass.is_none() {
                        self.first_of_pass = Some((f.seq, f.t));
                    }
                    f.seq += self.seq_offset;
                    f.t += self.t_offset;
                    self.last_out = Some((f.seq, f.t));
                    if self.pace == Pace::Realtime {
                        let (i0, t0) = *self.anchor.get_or_insert((Instant::now(), f.t));
                        let due = i0 + Duration::from_secs_f64((f.t - t0).clamp(0.0, 1e9));
                        let now = Instant::now();
                        if due > now {
                            std::thread::sleep(due - now);
                        }
                    }
                    return Ok(f);
                }
                Some(Err(e)) => {
                    return Err(SourceError::BadData {
                        place: "replay".into(),
                        msg: e.to_string(),
                    })
                }
                None => {
                    if let Some(line) = self.reader.truncated_at() {
                        tracing::warn!(
                            "{}:{line}: last line cut short, ignored",
                            self.path.display()
                        );
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
}

#[cfg(test)]
mod tests {
    use super::*;
    use lightpose_core::{LogHeader, LogWriter, NDET};

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
        let mut s = ReplaySource::open(&ReplayBackend {
            log: log.clone(),
            pace: Pace::Fast,
            looping: false,
        })
        .unwrap();
        let seqs: Vec<u64> = (0..3).map(|_| s.next_frame().unwrap().seq).collect();
        assert_eq!(seqs, vec![10, 11, 12]);
        assert!(matches!(s.next_frame(), Err(SourceError::Ended)));

        let mut s = ReplaySource::open(&ReplayBackend {
            log,
            pace: Pace::Fast,
            looping: true,
        })
        .unwrap();
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
        let mut s = ReplaySource::open(&ReplayBackend {
            log,
            pace: Pace::Realtime,
            looping: false,
        })
        .unwrap();
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
        let mut s = ReplaySource::open(&ReplayBackend {
            log: log.clone(),
            pace: Pace::Fast,
            looping: false,
        })
        .unwrap();
        assert!(s.next_frame().is_ok());
        let e = s.next_frame().unwrap_err().to_string();
        assert!(e.contains("r.jsonl:3"), "{e}");
        let e = ReplaySource::open(&ReplayBackend {
            log: d.path().join("none"),
            pace: Pace::Fast,
            looping: false,
        })
        .err()
        .unwrap()
        .to_string();
        assert!(e.contains("none"), "{e}");
    }
}
