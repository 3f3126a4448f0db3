//! The top-level keys: the frame rate, the lateness tolerance, the
//! estimator's name and the calibration.
//!
//! Ranges: `rate_hz` 0.001..=10000 Hz (the top: hal's bound for every
//! source; the bottom: [`MIN_RATE_HZ`]); `late_tolerance` (0, 10] periods.

use super::locate::{positive_to, within, Ctx};
use super::{embedded, ConfigError, Raw};
use lightpose_core::textfile::TextSource;

pub(super) struct Top {
    pub rate_hz: f64,
    pub late_tolerance: f64,
    pub estimator: String,
    pub calibration: TextSource,
    /// The lines of `estimator` (none when left out) and `calibration`.
    pub estimator_line: Option<usize>,
    pub calibration_line: usize,
}

/// The slowest frame rate: hal's for every source (a frame at least every
/// 1000 s; 1e-300 Hz left the pacer without a period).
use lightpose_hal::config::{MAX_RATE_HZ, MIN_RATE_HZ};

pub(super) fn validate(ctx: &Ctx, raw: &Raw) -> Result<Top, ConfigError> {
    let rate_hz = match &raw.rate_hz {
        Some(v) => within(
            ctx,
            v,
            "rate_hz",
            (MIN_RATE_HZ, MAX_RATE_HZ),
            " Hz (a frame at least every 1000 s)",
        )?,
        None => 5.0,
    };
    let late_tolerance = match &raw.late_tolerance {
        Some(v) => positive_to(ctx, v, "late_tolerance", 10.0, " periods")?,
        None => 0.5,
    };
    let estimator = match &raw.estimator {
        Some(v) if v.get_ref().trim().is_empty() => {
            return Err(ctx.err(v.span(), "estimator", "empty estimator name"))
        }
        // A name, not a text: the estimator's own check names the known
        // ones (at --check-config and at a start).
        Some(v) if v.get_ref().len() > 64 => {
            return Err(ctx.err(
                v.span(),
                "estimator",
                "longer than 64 characters: not a name",
            ))
        }
        Some(v) => v.get_ref().clone(),
        None => "auto".into(),
    };
    let estimator_line = raw.estimator.as_ref().map(|v| ctx.line(v.span().start));
    let (calibration, calibration_line) = match &raw.calibration {
        Some(v) => (
            embedded::resolve(ctx, v.get_ref())
                .map_err(|msg| ctx.err(v.span(), "calibration", msg))?,
            ctx.line(v.span().start),
        ),
        None => {
            return Err(ctx.whole(
                "calibration: missing (a calibration file, or \"embedded:tank-calibration\")",
            ))
        }
    };
    Ok(Top {
        rate_hz,
        late_tolerance,
        estimator,
        calibration,
        estimator_line,
        calibration_line,
    })
}
