//! Reading the sweep logs the fits are taken from: a log streamed frame by
//! frame (a sweep never sits in memory), its refused lines counted and
//! handed on rather than stopping the fit, and the header facts the fits
//! need (the ADC reference, whether it is a dark sweep). JSON Lines or
//! MCAP alike, of any kind of frame (spec v3: counts, BURST or
//! demodulated) through `lightpose_demod::LogFrames`, so that a BURST sweep
//! is demodulated on the way and the fits see each frame's amplitudes.

use lightpose_core::bounds::{Within, MAX_V_REF, MIN_V_REF};
use lightpose_core::{Frame, FrameLog, LogError, LogHeader};
use lightpose_demod::LogFrames;
use lightpose_logs::{open as open_log, LogFile};
use std::path::Path;

/// Log lines refused while streaming: counted, and each handed on; and
/// each log that was cut short, named with where.
pub(super) struct BadLines<'a> {
    pub count: u64,
    pub report: &'a mut dyn FnMut(&LogError),
    pub cuts: Vec<String>,
}

/// Open a log and feed every frame to `each`; bad lines to `bad`.
pub(super) fn stream(
    path: &Path,
    mut each: impl FnMut(&Frame, &LogHeader),
    bad: &mut BadLines,
) -> Result<LogHeader, LogError> {
    let mut frames = LogFrames::new(LogFile::open(path)?).map_err(LogError::from)?;
    let header = frames.header().clone();
    while let Some(item) = frames.next_frame() {
        match item {
            Ok(f) => each(&f, &header),
            Err(e) if e.skippable() => {
                bad.count += 1;
                (bad.report)(&e);
            }
            Err(e) => return Err(e),
        }
    }
    if let Some(c) = frames.cut() {
        bad.cuts.push(format!("{}: {c}", path.display()));
    }
    Ok(header)
}

/// A log's header alone (to tell dark sweeps from lit ones).
pub(super) fn header_of(path: &Path) -> Result<LogHeader, LogError> {
    Ok(open_log(path)?.header().clone())
}

/// The ADC reference the header of log `path` states, else `default`; a
/// stated one that no ADC has is refused, naming the log (it used to be
/// replaced by `default` without a word, and 1e300 was taken).
pub(super) fn header_v_ref(h: &LogHeader, default: f64, path: &Path) -> Result<f64, String> {
    let Some(v) = h.extra.get("v_ref") else {
        return Ok(default);
    };
    let within = Within::closed(MIN_V_REF, MAX_V_REF, " V");
    match v.as_f64() {
        Some(x) => within.check(x),
        None => Err(format!("{v} is not a number of volts")),
    }
    .map_err(|m| format!("{}: header v_ref: {m}", path.display()))
}

/// Whether a log is a dark sweep (beacon off), by its header.
pub(super) fn is_dark_sweep(h: &LogHeader) -> bool {
    h.extra.get("sweep").and_then(|v| v.as_str()) == Some("dark")
}
