//! What one frame's channels measure, as every model-based estimator reads
//! them: the one place a count and a demodulated amplitude differ.
//!
//! Why one place: the solver, the single-frame estimator and the tracker
//! all compare a channel's reading with the light equation's prediction
//! and weigh it by its noise. A count (v1/v2, or a steady beacon) is
//! predicted as o_k + g_k·g_T·E_k (in counts) and scatters as the noise
//! model says; a demodulated amplitude (spec v3, `Frame::amplitudes`, the
//! beacon in use) is the on level minus the off level, g_k·g_T·E_k with no
//! dark offset, and comes with its own 1σ from the demodulator. Both are
//! put on the count scale of [`SensorModel`]'s prediction here (an
//! amplitude plus the channel's dark level, so that the residual is
//! amplitude − g_k·g_T·E_k exactly), with the σ that goes with them, and
//! the estimators need not know which they hold.

use lightpose_core::{Frame, NDET};

use super::solver::Censoring;
use super::SensorModel;

/// The beacon whose amplitudes the estimators read (one beacon for now:
/// the header's first, or the one steady beacon).
pub const BEACON: u8 = 0;

/// One frame's 25 channels for a fit (fixed size: nothing allocated).
/// An amplitude's model error, relative to the light predicted for it: what
/// the light model and the calibration get wrong on a channel (beam shape,
/// scattering, a gain off by a little), which does not average out from
/// frame to frame as noise does. A count's noise (σ_e, its whole LSB) hides
/// it; an amplitude is about 7× less noisy, and without it the tracker on
/// a blinking beacon claimed σ it did not have (held-out harbour approach:
/// ±2σ coverage x 66 %, y 79 %, 14.6 % of `ok` poses beyond 3σ; with 2 %:
/// 93 / 96 %, 0.8 %, and p95 no worse). Set on that run; a station's
/// calibration measures each beacon's own from its residuals
/// (`BeaconLight::model_rel`), and this is what is assumed where nothing
/// measured it (one beacon, a scene's own station, an older calibration).
pub const AMPLITUDE_MODEL_REL: f64 = 0.02;

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measurement {
    /// Each channel's reading on the model's count scale, dark level
    /// included: the count itself, or the amplitude plus o_k in counts.
    pub z: [f64; NDET],
    /// How each channel enters (a count may be censored; an amplitude is
    /// data, or left out when any of its samples clipped).
    pub kinds: [Censoring; NDET],
    /// Each amplitude's 1σ in counts (the demodulator's); `None` for
    /// counts, whose σ is the noise model's at the predicted light.
    pub sigma: Option<[f64; NDET]>,
}

impl Measurement {
    /// The frame's channels: its beacon's amplitudes when it was
    /// demodulated, else its counts. `frozen` (bit k for detector k) are
    /// channels left out by their history.
    pub fn of(m: &SensorModel, frame: &Frame, frozen: u32) -> Measurement {
        let Some(a) = frame.amplitudes.as_ref() else {
            return Measurement {
                z: frame.counts.map(f64::from),
                kinds: Censoring::classify(m, &frame.counts, frozen),
                sigma: None,
            };
        };
        let cpv = m.counts_per_volt();
        let mut out = Measurement {
            z: [0.0; NDET],
            kinds: [Censoring::Excluded; NDET],
            sigma: Some([1.0; NDET]),
        };
        // A frame without the beacon in use has no channel to fit: no light.
        let Some(b) = a.beacon(BEACON) else {
            return out;
        };
        let mut sigma = [1.0; NDET];
        for k in 0..NDET {
            out.z[k] = b.amplitude[k] + m.offset_v[k] * cpv;
            let s = b.std[k];
            // A clipped sample spoils its channel's amplitude (FORMATS.md):
            // left out, as a stuck channel is; so is one without a σ.
            let usable = a.clipped[k] == 0
                && frozen & (1 << k) == 0
                && b.amplitude[k].is_finite()
                && s.is_finite()
                && s > 0.0;
            if usable {
                out.kinds[k] = Censoring::Data;
                sigma[k] = s;
            }
        }
        out.sigma = Some(sigma);
        out
    }

    /// Whether the channels are demodulated amplitudes.
    #[inline]
    pub fn is_amplitude(&self) -> bool {
        self.sigma.is_some()
    }

    /// Variance (counts²) of channel k when the light it receives, after
    /// its gain and g_T, is `e` volts: the noise model's for a count, the
    /// demodulator's plus the model's error ([`AMPLITUDE_MODEL_REL`]) for an
    /// amplitude.
    #[inline]
    pub fn variance(&self, m: &SensorModel, k: usize, e: f64) -> f64 {
        match &self.sigma {
            None => m.count_variance(e),
            Some(s) => {
                let model = AMPLITUDE_MODEL_REL * e.max(0.0) * m.counts_per_volt();
                s[k] * s[k] + model * model
            }
        }
    }

    /// Channel k's light above its dark level in units of its noise
    /// without light: what says a frame holds any light at all.
    #[inline]
    pub fn snr_without_light(&self, m: &SensorModel, k: usize) -> f64 {
        let cpv = m.counts_per_volt();
        (self.z[k] - m.offset_v[k] * cpv) / self.variance(m, k, 0.0).sqrt()
    }

    /// Channels at or above full scale: an amplitude's channel clipped
    /// (any sample) counts as one.
    pub fn n_clipped(m: &SensorModel, frame: &Frame) -> usize {
        match frame.amplitudes.as_ref() {
            Some(a) => a.clipped.iter().filter(|&&c| c > 0).count(),
            None => {
                let fs = lightpose_core::frame::full_scale(m.adc_bits);
                frame.counts.iter().filter(|&&c| c >= fs).count()
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use lightpose_core::{Amplitudes, BeaconAmplitude};

    #[test]
    fn counts_are_themselves_and_amplitudes_sit_on_the_dark_level() {
        let m = SensorModel::default();
        let mut f = Frame::new(0, 0.0, 10, [400; NDET]);
        let c = Measurement::of(&m, &f, 0);
        assert_eq!(c.z, [400.0; NDET]);
        assert_eq!(c.kinds, Censoring::classify(&m, &f.counts, 0));
        assert_eq!(c.variance(&m, 3, 0.2), m.count_variance(0.2));
        let mut a = Amplitudes {
            n_beacons: 1,
            ..Amplitudes::default()
        };
        a.beacons[0] = BeaconAmplitude {
            beacon: 0,
            amplitude: [250.0; NDET],
            std: [1.5; NDET],
        };
        a.clipped[7] = 2;
        a.beacons[0].std[9] = f64::NAN;
        f.amplitudes = Some(a);
        let d = Measurement::of(&m, &f, 1 << 4);
        let dark = 0.15 * m.counts_per_volt();
        assert!((d.z[0] - (250.0 + dark)).abs() < 1e-12);
        // The demodulator's σ alone without light; with it, the model's
        // error beside (2 % of 3 V in counts).
        assert_eq!(d.variance(&m, 0, 0.0), 2.25);
        let model = AMPLITUDE_MODEL_REL * 3.0 * m.counts_per_volt();
        assert!((d.variance(&m, 0, 3.0) - (2.25 + model * model)).abs() < 1e-9);
        for k in [4, 7, 9] {
            assert_eq!(d.kinds[k], Censoring::Excluded, "{k}");
        }
        assert_eq!(d.kinds[0], Censoring::Data);
        assert!((d.snr_without_light(&m, 0) - 250.0 / 1.5).abs() < 1e-9);
        assert_eq!(Measurement::n_clipped(&m, &f), 1);
        // Without the beacon in use nothing is data.
        a.beacons[0].beacon = 1;
        f.amplitudes = Some(a);
        let none = Measurement::of(&m, &f, 0);
        assert!(none.kinds.iter().all(|k| *k == Censoring::Excluded));
    }
}
