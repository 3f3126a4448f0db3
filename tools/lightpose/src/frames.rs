//! A log of any of FORMATS.md's three kinds of frame as the frames an
//! estimator reads, for code that takes core's [`FrameLog`] (the
//! pipeline's `replay`): counts as they are, demodulated frames with their
//! amplitudes, BURSTs demodulated by the demodulator the header asks for
//! (`lightpose_demod::demodulator_for`, as its `LogFrames` does for a
//! JSON Lines reader; this is the same over either container).

use anyhow::Context;
use lightpose_core::samples::{Demodulated, Record};
use lightpose_core::{Cut, Frame, FrameLog, FrameOrder, LogError, LogHeader};
use lightpose_demod::Demodulator;
use lightpose_logs::LogFile;
use std::path::Path;

pub struct Frames {
    log: LogFile,
    demod: Option<Demodulator>,
    out: Box<Demodulated>,
}

impl Frames {
    /// The log at `path` in its container; refused when its header's
    /// sampling cannot be demodulated.
    pub fn open(path: &Path) -> anyhow::Result<Frames> {
        let log = LogFile::open(path)?;
        let demod = lightpose_demod::demodulator_for(log.header())
            .with_context(|| format!("{}: header", path.display()))?;
        let out = Box::new(demod.as_ref().map(Demodulator::output).unwrap_or_default());
        Ok(Frames { log, demod, out })
    }

    /// The demodulator in use, if the log's frames are demodulated here.
    pub fn demodulator(&self) -> Option<&Demodulator> {
        self.demod.as_ref()
    }
}

impl FrameLog for Frames {
    fn header(&self) -> &LogHeader {
        self.log.header()
    }
    fn name(&self) -> &str {
        self.log.name()
    }
    fn next_frame(&mut self) -> Option<Result<Frame, LogError>> {
        let burst = match self.log.next_record()? {
            Err(e) => return Some(Err(e)),
            Ok(Record::Frame(f)) => return Some(Ok(f)),
            Ok(Record::Demodulated(d)) => return Some(Ok(d.to_frame())),
            Ok(Record::Burst(b)) => match self.demod.as_mut() {
                Some(d) => d.demodulate_burst(b, &mut self.out).map_err(|e| (b.seq, e)),
                // The reader refuses a BURST in a log of one sample a
                // frame, and then there is no demodulator: said, not assumed.
                None => {
                    return Some(Err(LogError::Refused {
                        name: self.log.name().to_string(),
                        line: self.log.line_no().unwrap_or(0),
                        msg: "a BURST in a log of one sample a frame".into(),
                    }))
                }
            },
        };
        Some(match burst {
            Ok(()) => Ok(self.out.to_frame()),
            // One frame lost, as a bad line is: reading goes on.
            Err((seq, e)) => Err(LogError::Line {
                name: self.log.name().to_string(),
                line: self.log.line_no().unwrap_or(0),
                msg: format!("BURST seq {seq}: {e}"),
            }),
        })
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
