//! Frames for estimators from a log of any of FORMATS.md's three kinds of
//! frame, in either container (core's [`FrameLog`]: JSON Lines or MCAP):
//! counts as they are, demodulated frames with their amplitudes, and raw
//! samples (BURST) demodulated on the way, by a demodulator set up from the
//! log's header (its `sample_hz`, `channel_skew_s` and `beacons`). Every
//! reader of logs that wants poses (replay, calibrate) reads through this
//! one place; it is itself a [`FrameLog`].

use lightpose_core::{Cut, Demodulated, Frame, FrameLog, FrameOrder, LogError, LogHeader, Record};

use crate::{BeaconSpec, ConfigError, DemodConfig, Demodulator, FrameError};

/// Why a log's frames cannot be had.
#[derive(Debug, thiserror::Error)]
pub enum FramesError {
    #[error(transparent)]
    Log(#[from] LogError),
    /// The header's sampling cannot be demodulated (a steady beacon
    /// sampled fast, frequencies that break MODEL.md's rules).
    #[error("{name}: header: {err}")]
    Config { name: String, err: ConfigError },
    /// A BURST the demodulator refused (`line` 0 in a container without
    /// lines).
    #[error("{name}:{line}: {err}")]
    Burst {
        name: String,
        line: usize,
        err: FrameError,
    },
}

impl From<FramesError> for LogError {
    /// A demodulation's error as the log's: a BURST the demodulator
    /// refused costs its frame (a line), a header it cannot demodulate
    /// ends the log.
    fn from(e: FramesError) -> Self {
        match e {
            FramesError::Log(e) => e,
            FramesError::Config { name, err } => LogError::Refused {
                name,
                line: 1,
                msg: format!("header: {err}"),
            },
            FramesError::Burst { name, line, err } => LogError::Line {
                name,
                line,
                msg: err.to_string(),
            },
        }
    }
}

/// The demodulator a log's header asks for: `None` when its frames are one
/// sample each (v1/v2, or demodulated already); an error when it samples
/// faster than its frames but names no blinking beacon.
pub fn demodulator_for(header: &LogHeader) -> Result<Option<Demodulator>, ConfigError> {
    if header.samples_per_frame() <= 1 {
        return Ok(None);
    }
    let beacons = header
        .beacons
        .iter()
        .map(|b| BeaconSpec::new(b.id.clone(), b.mod_hz))
        .collect::<Vec<_>>();
    let mut cfg = DemodConfig::new(
        header.sample_hz.unwrap_or(header.rate_hz),
        header.rate_hz,
        beacons,
    );
    cfg.channel_skew_s = header.channel_skew_s.unwrap_or(0.0);
    Ok(Some(Demodulator::new(cfg.validate()?)))
}

/// A log read as frames for an estimator (see the module's doc).
pub struct LogFrames<L> {
    log: L,
    demod: Option<Demodulator>,
    /// The demodulator's output, reused (3.6 kB: on the heap once).
    out: Box<Demodulated>,
}

impl<L: FrameLog> LogFrames<L> {
    /// Frames of `log`; its header says whether they need demodulating.
    pub fn new(log: L) -> Result<Self, FramesError> {
        let demod = demodulator_for(log.header()).map_err(|err| FramesError::Config {
            name: log.name().to_string(),
            err,
        })?;
        let out = Box::new(demod.as_ref().map(Demodulator::output).unwrap_or_default());
        Ok(LogFrames { log, demod, out })
    }

    /// The next frame, `None` at the end of the log.
    #[allow(clippy::should_implement_trait)]
    pub fn next(&mut self) -> Option<Result<Frame, FramesError>> {
        let rec = match self.log.next_record()? {
            Ok(r) => r,
            Err(e) => return Some(Err(e.into())),
        };
        let got = match rec {
            Record::Frame(f) => return Some(Ok(f)),
            Record::Demodulated(d) => return Some(Ok(d.to_frame())),
            Record::Burst(b) => match self.demod.as_mut() {
                Some(demod) => demod.demodulate_burst(b, &mut self.out),
                // The reader refuses a BURST whose header gives one sample
                // per frame, so this cannot be; said, not assumed.
                None => Err(FrameError::Length {
                    expected: lightpose_core::NDET,
                    got: b.samples().len(),
                    n: 1,
                }),
            },
        };
        Some(match got {
            Ok(()) => Ok(self.out.to_frame()),
            Err(err) => Err(FramesError::Burst {
                name: self.log.name().to_string(),
                line: self.log.line_no().unwrap_or(0),
                err,
            }),
        })
    }

    /// The demodulator in use, if the log's frames are demodulated here.
    pub fn demodulator(&self) -> Option<&Demodulator> {
        self.demod.as_ref()
    }

    pub fn reader(&self) -> &L {
        &self.log
    }

    pub fn reader_mut(&mut self) -> &mut L {
        &mut self.log
    }

    pub fn into_reader(self) -> L {
        self.log
    }
}

impl<L: FrameLog> FrameLog for LogFrames<L> {
    fn header(&self) -> &LogHeader {
        self.log.header()
    }
    fn name(&self) -> &str {
        self.log.name()
    }
    fn line_no(&self) -> Option<usize> {
        self.log.line_no()
    }
    fn next_frame(&mut self) -> Option<Result<Frame, LogError>> {
        Some(LogFrames::next(self)?.map_err(LogError::from))
    }
    fn next_record(&mut self) -> Option<Result<Record<'_>, LogError>> {
        self.log.next_record()
    }
    fn cut(&self) -> Option<Cut> {
        self.log.cut()
    }
    fn other_records(&self) -> u64 {
        self.log.other_records()
    }
    fn first_other(&self) -> Option<&str> {
        self.log.first_other()
    }
    fn order(&self) -> &FrameOrder {
        self.log.order()
    }
    fn seq_gaps(&self) -> (u64, u64) {
        self.log.seq_gaps()
    }
    fn bad_readings(&self) -> (u64, Option<&str>) {
        self.log.bad_readings()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use lightpose_core::{BeaconInfo, Burst, LogReader, NDET};

    fn header(sample_hz: Option<f64>) -> LogHeader {
        let mut h = LogHeader::new(12, 5.0);
        h.sample_hz = sample_hz;
        if sample_hz.is_some() {
            h.beacons = vec![BeaconInfo {
                id: "top".into(),
                mod_hz: 250.0,
            }];
        }
        h
    }

    fn read(text: Vec<u8>) -> Result<LogFrames<LogReader<&'static [u8]>>, FramesError> {
        let text: &'static [u8] = Box::leak(text.into_boxed_slice());
        LogFrames::new(LogReader::new(text, "t.jsonl")?)
    }

    #[test]
    fn counts_pass_unchanged() {
        let mut w = lightpose_core::LogWriter::new(Vec::new(), &header(None)).unwrap();
        let mut f = Frame::new(3, 0.6, 12, [700; NDET]);
        f.temp_c = Some(12.5);
        w.write_frame(&f).unwrap();
        let mut frames = read(w.into_inner()).unwrap();
        assert!(frames.demodulator().is_none());
        assert_eq!(frames.next().unwrap().unwrap(), f);
        assert!(frames.next().is_none());
    }

    /// A square wave of 300 counts on 1000 in every channel: the frame an
    /// estimator gets carries it as the beacon's amplitude, at the middle
    /// of its samples, whether the log held the samples or the
    /// demodulator's output.
    #[test]
    fn bursts_are_demodulated_and_demodulated_frames_read() {
        let h = header(Some(2000.0));
        let n = h.samples_per_frame();
        assert_eq!(n, 400);
        let mut w = lightpose_core::LogWriter::new(Vec::new(), &h).unwrap();
        let mut demod = demodulator_for(&h).unwrap().unwrap();
        let mut out = demod.output();
        let mut demodulated = Vec::new();
        for j in 0..4u64 {
            let mut b = Burst::new(n);
            b.seq = j;
            b.t = j as f64 * 0.2;
            b.adc_bits = 12;
            for k in 0..NDET {
                for (i, s) in b.channel_mut(k).iter_mut().enumerate() {
                    // 250 Hz at 2 kHz: 4 samples on, 4 off.
                    *s = if (i / 4) % 2 == 0 { 1300 } else { 1000 };
                }
            }
            w.write_burst(&b).unwrap();
            demod.demodulate_burst(&b, &mut out).unwrap();
            demodulated.push(out);
        }
        let mut frames = read(w.into_inner()).unwrap();
        for (j, d) in demodulated.iter().enumerate() {
            let f = frames.next().unwrap().unwrap();
            assert_eq!(f.seq, j as u64);
            assert!((f.t - (j as f64 * 0.2 + 399.0 / 4000.0)).abs() < 1e-12);
            let a = f.amplitudes.expect("amplitudes");
            assert_eq!(a, d.light);
            if j > 0 {
                // Locked on the beacon's phase after the first frame.
                assert!((a.beacons[0].amplitude[7] - 300.0).abs() < 1.0, "{a:?}");
                assert!((a.ambient[7] - 1000.0).abs() < 1.0);
                assert_eq!(f.counts[7], 1150, "the mean level, for display");
            }
        }
        assert!(frames.next().is_none());

        // The same frames written demodulated read back the same.
        let mut w = lightpose_core::LogWriter::new(Vec::new(), &h).unwrap();
        for d in &demodulated {
            w.write_demodulated(d).unwrap();
        }
        let mut again = read(w.into_inner()).unwrap();
        for d in &demodulated {
            assert_eq!(again.next().unwrap().unwrap(), d.to_frame());
        }
    }

    #[test]
    fn a_fast_sampled_steady_beacon_is_refused_naming_the_log() {
        let mut h = header(Some(2000.0));
        h.beacons.clear();
        let w = lightpose_core::LogWriter::new(Vec::new(), &h).unwrap();
        let err = read(w.into_inner()).err().expect("refused");
        // The header's own reader refuses it, at its line.
        assert!(err.to_string().starts_with("t.jsonl:1: "), "{err}");
    }
}
