//! The dark levels of a calibration: each channel's offset and noise from
//! the dark frames (the beacon off), and the no-light threshold, or
//! MODEL.md's nominal ones when there are no dark frames. Apart from the
//! passes over the logs (`paper_fit.rs`) that feed it.

use super::paper_fit::CalibrateError;
use lightpose_core::{frame::full_scale, Frame, NDET};

/// MODEL.md's nominal dark offset, volts: the fallback when no dark frames
/// exist (see docs/pipeline.md for why not the darkest pixels).
pub const NOMINAL_OFFSET_V: f64 = 0.15;
/// MODEL.md's nominal electronic noise, volts: the no-light threshold's
/// basis when no dark frames exist.
pub const NOMINAL_SIGMA_V: f64 = 0.05;
/// A peak this many noise σ above the offset is light, not noise: the
/// largest of 25 channels of pure noise exceeds 5σ about once in 10⁵ frames.
pub const NO_LIGHT_SIGMAS: f64 = 5.0;

/// Per-channel mean and spread of dark frames (Welford).
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct DarkAcc {
    pub(super) n: u64,
    mean: [f64; NDET],
    m2: [f64; NDET],
    lsb: f64,
}

impl DarkAcc {
    pub(super) fn push(&mut self, f: &Frame, v_ref: f64) {
        self.n += 1;
        let n = self.n as f64;
        let scale = v_ref / full_scale(f.adc_bits) as f64;
        self.lsb = self.lsb.max(scale);
        for k in 0..NDET {
            let v = f.counts[k] as f64 * scale;
            let d = v - self.mean[k];
            self.mean[k] += d / n;
            self.m2[k] += d * (v - self.mean[k]);
        }
    }
}

/// Each channel's dark offset and noise, the no-light threshold, and where
/// they came from.
pub(super) struct DarkLevels {
    pub offsets: [f64; NDET],
    pub sigma: Option<Vec<f64>>,
    pub no_light_v: f64,
    pub source: String,
}

/// The dark levels from the dark frames, or MODEL.md's nominal ones when
/// there are none.
pub(super) fn dark_levels(
    dark: &DarkAcc,
    sources: &[String],
) -> Result<DarkLevels, CalibrateError> {
    if dark.n >= 2 {
        let sig: Vec<f64> = dark
            .m2
            .iter()
            .map(|m| (m / (dark.n - 1) as f64).sqrt())
            .collect();
        let worst = sig.iter().cloned().fold(0.0, f64::max);
        if worst == 0.0 {
            // A real ADC's dark frames always differ by a count somewhere;
            // a stuck one's set the no-light level at two LSB, and beacon-
            // off frames then read as `out_of_range` instead of `no_light`.
            return Err(CalibrateError::Refused(format!(
                "dark log {}: every channel reads the same count on all {} frames (a \
                 stuck ADC?): no noise to set the no-light level from",
                sources.join(", "),
                dark.n
            )));
        }
        // At least two LSB, so that a noise-free scene is not "lit" by one
        // count of rounding.
        let thr = (NO_LIGHT_SIGMAS * worst).max(2.0 * dark.lsb);
        Ok(DarkLevels {
            offsets: dark.mean,
            sigma: Some(sig),
            no_light_v: thr,
            source: sources.join(", "),
        })
    } else if dark.n == 1 {
        Err(CalibrateError::Refused(
            "only one dark frame: the offsets need several to average the noise".into(),
        ))
    } else if !sources.is_empty() {
        // Asked for, but empty: the nominal levels would stand in for
        // what the user meant to measure, without a word.
        Err(CalibrateError::Refused(format!(
            "dark log {} has no frames: record the dark sweep, or leave --dark out for \
             MODEL.md's nominal offsets",
            sources.join(", ")
        )))
    } else {
        Ok(DarkLevels {
            offsets: [NOMINAL_OFFSET_V; NDET],
            sigma: None,
            no_light_v: NO_LIGHT_SIGMAS * NOMINAL_SIGMA_V,
            source: "nominal".to_string(),
        })
    }
}
