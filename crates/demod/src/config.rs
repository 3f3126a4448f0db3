//! The demodulator's configuration: what it is told (sample and frame
//! rates, the channels' skew, the beacons and their frequencies), checked
//! once into a [`ValidConfig`] so that the per-frame code needs no checks.

use lightpose_core::modulation::{self, check_beacons, BeaconFreq, ModulationError};
use lightpose_core::NDET;

/// Most beacons one demodulator separates: MODEL.md's frequency rules admit
/// as many as the times 2 divides the samples per frame (four at N = 400,
/// six at N = 640); eight, as a demodulated frame holds (core's
/// `samples::MAX_BEACONS`), keeps the per-channel solve on the stack.
pub const MAX_BEACONS: usize = lightpose_core::samples::MAX_BEACONS;

/// One beacon the demodulator looks for: FORMATS.md's header `beacons`
/// entry, `{"id":..,"mod_hz":..}`.
#[derive(Debug, Clone, PartialEq)]
pub struct BeaconSpec {
    pub id: String,
    /// Its nominal blink frequency (its own clock may be off by
    /// [`DemodConfig::max_drift_ppm`]).
    pub mod_hz: f64,
}

impl BeaconSpec {
    pub fn new(id: impl Into<String>, mod_hz: f64) -> Self {
        BeaconSpec {
            id: id.into(),
            mod_hz,
        }
    }
}

/// What a demodulator is told: the header's `sample_hz`, `rate_hz`,
/// `channel_skew_s` and `beacons`, and two limits of the sea.
#[derive(Debug, Clone, PartialEq)]
pub struct DemodConfig {
    pub sample_hz: f64,
    pub rate_hz: f64,
    /// Channel k's samples are taken k · channel_skew_s after channel 0's.
    pub channel_skew_s: f64,
    pub beacons: Vec<BeaconSpec>,
    /// The ambient light's flicker that must not leak into an amplitude
    /// lies below this (MODEL.md: waves' caustics, up to ~10–20 Hz).
    pub flicker_max_hz: f64,
    /// How far a beacon's clock may be from its nominal frequency.
    pub max_drift_ppm: f64,
}

impl DemodConfig {
    /// The defaults for the rest: no skew, flicker up to 20 Hz, ±100 ppm.
    pub fn new(sample_hz: f64, rate_hz: f64, beacons: Vec<BeaconSpec>) -> Self {
        DemodConfig {
            sample_hz,
            rate_hz,
            channel_skew_s: 0.0,
            beacons,
            flicker_max_hz: 20.0,
            max_drift_ppm: 100.0,
        }
    }

    /// Checks every rule the demodulator's arithmetic relies on.
    pub fn validate(&self) -> Result<ValidConfig, ConfigError> {
        positive("sample_hz", self.sample_hz)?;
        positive("rate_hz", self.rate_hz)?;
        let n = modulation::samples_per_frame(self.sample_hz, self.rate_hz)?;
        if !self.channel_skew_s.is_finite()
            || self.channel_skew_s < 0.0
            || self.channel_skew_s * (NDET - 1) as f64 >= 1.0 / self.rate_hz
        {
            return Err(ConfigError::Skew {
                skew_s: self.channel_skew_s,
                frame_s: 1.0 / self.rate_hz,
            });
        }
        if !self.flicker_max_hz.is_finite() || self.flicker_max_hz < 0.0 {
            return Err(ConfigError::Range {
                key: "flicker_max_hz",
                value: self.flicker_max_hz,
                range: "0 or more",
            });
        }
        if !self.max_drift_ppm.is_finite() || !(0.0..=10_000.0).contains(&self.max_drift_ppm) {
            return Err(ConfigError::Range {
                key: "max_drift_ppm",
                value: self.max_drift_ppm,
                range: "0..=10000",
            });
        }
        let half_periods = check_frequencies(self.sample_hz, self.rate_hz, &self.beacons)?;
        let n = n as usize;
        let mut beacons = Vec::with_capacity(self.beacons.len());
        for (b, m) in self.beacons.iter().zip(half_periods) {
            beacons.push(ValidBeacon {
                id: b.id.clone(),
                mod_hz: b.mod_hz,
                half_period: m as usize,
                periods: n / (2 * m as usize),
            });
        }
        Ok(ValidConfig {
            sample_hz: self.sample_hz,
            rate_hz: self.rate_hz,
            n,
            channel_skew_s: self.channel_skew_s,
            beacons,
            flicker_max_hz: self.flicker_max_hz,
            max_drift: self.max_drift_ppm * 1e-6,
        })
    }
}

/// A beacon as the demodulator uses it.
#[derive(Debug, Clone, PartialEq)]
pub struct ValidBeacon {
    pub id: String,
    pub mod_hz: f64,
    /// m: samples per half period (the period is 2m samples).
    pub half_period: usize,
    /// Whole periods per frame, N / 2m.
    pub periods: usize,
}

/// A checked [`DemodConfig`].
#[derive(Debug, Clone, PartialEq)]
pub struct ValidConfig {
    pub sample_hz: f64,
    pub rate_hz: f64,
    /// N: samples per channel per frame.
    pub n: usize,
    pub channel_skew_s: f64,
    pub beacons: Vec<ValidBeacon>,
    pub flicker_max_hz: f64,
    /// The clock's largest relative error (100 ppm: 1e-4).
    pub max_drift: f64,
}

/// What is wrong with a configuration, naming the key or the beacons.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ConfigError {
    #[error("{key} = {value}: must be a positive number")]
    NotPositive { key: &'static str, value: f64 },
    #[error("{key} = {value}: must be {range}")]
    Range {
        key: &'static str,
        value: f64,
        range: &'static str,
    },
    #[error("channel_skew_s = {skew_s}: must be 0 or more, and the 25 channels' skew less than a frame ({frame_s} s)")]
    Skew { skew_s: f64, frame_s: f64 },
    #[error("no beacons: a demodulator needs at least one blinking beacon")]
    NoBeacons,
    #[error("{count} beacons: at most {max}")]
    TooManyBeacons { count: usize, max: usize },
    #[error("beacons {a:?} and {b:?}: the same id")]
    DuplicateId { a: String, b: String },
    #[error("beacon {id:?}: mod_hz = {mod_hz}: a steady beacon (or not a frequency) cannot be demodulated; give it a blink frequency")]
    Steady { id: String, mod_hz: f64 },
    /// MODEL.md's frequency rules (lightpose-core's check).
    #[error(transparent)]
    Rules(#[from] ModulationError),
}

fn positive(key: &'static str, value: f64) -> Result<(), ConfigError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(ConfigError::NotPositive { key, value })
    }
}

/// MODEL.md's frequency rules (lightpose-core's one check, as the scene
/// and the log header apply them), and what the demodulator adds: at
/// least one beacon, at most [`MAX_BEACONS`], each with its own id, every
/// one blinking. Gives each beacon's m (sample_hz / mod_hz = 2m).
pub fn check_frequencies(
    sample_hz: f64,
    rate_hz: f64,
    beacons: &[BeaconSpec],
) -> Result<Vec<u64>, ConfigError> {
    if beacons.is_empty() {
        return Err(ConfigError::NoBeacons);
    }
    if beacons.len() > MAX_BEACONS {
        return Err(ConfigError::TooManyBeacons {
            count: beacons.len(),
            max: MAX_BEACONS,
        });
    }
    for (i, b) in beacons.iter().enumerate() {
        if let Some(a) = beacons[..i].iter().find(|a| a.id == b.id) {
            return Err(ConfigError::DuplicateId {
                a: a.id.clone(),
                b: b.id.clone(),
            });
        }
        // Core admits one steady beacon (spec v1/v2); nothing to demodulate.
        if !(b.mod_hz.is_finite() && b.mod_hz > 0.0) {
            return Err(ConfigError::Steady {
                id: b.id.clone(),
                mod_hz: b.mod_hz,
            });
        }
    }
    let freqs: Vec<BeaconFreq<'_>> = beacons
        .iter()
        .map(|b| BeaconFreq {
            id: &b.id,
            mod_hz: b.mod_hz,
        })
        .collect();
    check_beacons(rate_hz, sample_hz, &freqs)?;
    // Whole and even by the check above.
    Ok(beacons
        .iter()
        .map(|b| modulation::whole(sample_hz / b.mod_hz).unwrap_or(2) / 2)
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn err(fs: f64, rate: f64, hz: &[(&str, f64)]) -> String {
        let b = hz.iter().map(|(id, f)| BeaconSpec::new(*id, *f)).collect();
        DemodConfig::new(fs, rate, b)
            .validate()
            .unwrap_err()
            .to_string()
    }

    #[test]
    fn frequency_rules_name_the_beacons() {
        assert_eq!(
            err(4800.0, 10.0, &[("a", 200.0), ("b", 600.0)]),
            "beacons \"a\" (200 Hz) and \"b\" (600 Hz) stand in the ratio 1 : 3 of two odd numbers: they share odd harmonics"
        );
        assert!(err(4000.0, 10.0, &[("a", 200.0), ("b", 200.0)])
            .starts_with("beacons \"a\" and \"b\" both blink at 200 Hz"));
        assert!(err(4000.0, 10.0, &[("a", 0.0)])
            .starts_with("beacon \"a\": mod_hz = 0: a steady beacon"));
        // 4000 / 300 is not whole; 4000 / 4000 is one sample per period, odd.
        assert!(err(4000.0, 10.0, &[("a", 300.0)]).contains("not an even whole number"));
        assert!(err(4000.0, 10.0, &[("a", 4000.0)]).contains("not an even whole number"));
        // 4000 / 160 = 25 samples per period: odd.
        assert!(err(4000.0, 10.0, &[("a", 160.0)]).contains("even whole number"));

        // 3 Hz frames: 66.67 periods of 200 Hz, and N = 666.7.
        assert!(err(2000.0, 3.0, &[("a", 200.0)])
            .starts_with("sample_hz = 2000 is not a whole multiple"));
        assert!(err(2000.0, 8.0, &[("a", 100.0)])
            .contains("periods per frame at rate_hz = 8, not a whole number"));
        assert!(err(2000.0, 5.0, &[]).starts_with("no beacons"));
        assert!(err(2000.0, 5.0, &[("a", 250.0), ("a", 500.0)])
            .starts_with("beacons \"a\" and \"a\": the same id"));
    }

    #[test]
    fn allowed_sets() {
        // 200 : 250 = 4 : 5 is allowed; four beacons at N = 400.
        let ok = |fs: f64, rate: f64, hz: &[f64]| {
            let b = hz
                .iter()
                .enumerate()
                .map(|(i, f)| BeaconSpec::new(format!("b{i}"), *f))
                .collect();
            DemodConfig::new(fs, rate, b).validate()
        };
        assert!(ok(4000.0, 10.0, &[200.0, 250.0]).is_ok());
        let v = ok(4000.0, 10.0, &[2000.0, 1000.0, 500.0, 250.0]).unwrap();
        assert_eq!(v.n, 400);
        assert_eq!(
            v.beacons.iter().map(|b| b.half_period).collect::<Vec<_>>(),
            [1, 2, 4, 8]
        );
        // A fifth at N = 400 must share a power of 2 with one of them.
        assert!(ok(4000.0, 10.0, &[2000.0, 1000.0, 500.0, 250.0, 125.0]).is_err());
    }
}
