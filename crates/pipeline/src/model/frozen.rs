//! Channels whose count has stopped moving: a photodiode or ADC input
//! stuck at a value between the bounds, which one frame cannot tell from
//! light (see [`Censoring::classify`](super::solver::Censoring::classify)
//! for the bounds) but its history can.
//!
//! Why: a channel frozen at its first reading is right at first and grows
//! wrong as the vehicle moves; fitted as data it cost a quarter of the
//! tank zigzag's poses (the centre channel: 9 of 41 `diverged`, 12
//! `initialising`). Noise alone moves a lit channel's count. The worst case
//! for telling a frozen channel from a live one is a vehicle at rest with
//! the light in the middle of a code: each reading then lands in that code
//! with a chance of P(|Z| < w/2σ) for analog noise σ (counts) and a code w
//! counts wide; this takes codes up to 2 counts wide (an ADC's differential
//! non-linearity), P(|Z| < 1/σ), and calls a channel frozen when the chance
//! that noise alone repeated its count as many frames as it has falls
//! below [`FALSE_ALARM`]: 21 repeats at σ = 3 counts, 40 at 1.5, 73 at 1,
//! 11 at the tank's lit spot. Motion only makes a repeat less likely.
//! A count at a bound (0, full scale, at or below the dark level) repeats
//! by itself and is not counted. The first change of the count takes the
//! channel back. A frame seen twice (the same `t`: a water bank's member
//! taking over the frame its tracker saw) is one observation.

use lightpose_core::NDET;

use super::SensorModel;

/// Chance, per channel and frame, that noise alone keeps a live channel's
/// count long enough to be called frozen: 25 channels at 5 Hz make one
/// such call in ~250 years, at 100 Hz in ~13; each costs one channel until
/// its count next moves.
pub const FALSE_ALARM: f64 = 1e-12;

/// The chance that a reading with analog noise `sigma` (counts) lands in
/// the code of the one before, at worst (the light still, mid-code, codes
/// up to 2 counts wide): P(|Z| < 1/σ).
pub fn repeat_chance(sigma: f64) -> f64 {
    if !(sigma > 0.0) {
        return 1.0;
    }
    let a = 1.0 / sigma;
    (1.0 - super::normal::erfc(a / std::f64::consts::SQRT_2)).clamp(0.0, 1.0)
}

/// The watch over each channel's history: fixed arrays, nothing
/// allocated, one pass per frame.
#[derive(Debug, Clone, Copy)]
pub struct FrozenWatch {
    last: [u16; NDET],
    /// The time of the last frame observed.
    t: f64,
    /// ln of the chance that noise alone gave the run of equal counts so
    /// far (0 after a change).
    ln_chance: [f64; NDET],
    seen: bool,
}

impl Default for FrozenWatch {
    fn default() -> Self {
        FrozenWatch {
            last: [0; NDET],
            t: f64::NAN,
            ln_chance: [0.0; NDET],
            seen: false,
        }
    }
}

impl FrozenWatch {
    /// Take one frame's counts (in the order the frames come; `t` its
    /// time: the same frame again is not a repeat).
    pub fn observe(&mut self, m: &SensorModel, counts: &[u16; NDET], t: f64) {
        if self.seen && t == self.t {
            return;
        }
        self.t = t;
        if !self.seen {
            self.last = *counts;
            self.seen = true;
            return;
        }
        let fs = m.full_scale();
        let cpv = m.counts_per_volt();
        for k in 0..NDET {
            let c = counts[k];
            if c != self.last[k] {
                self.last[k] = c;
                self.ln_chance[k] = 0.0;
                continue;
            }
            let dark = m.offset_v[k] * cpv;
            let cf = f64::from(c);
            if cf >= fs || c == 0 || cf <= dark {
                continue;
            }
            let e = ((cf - dark) / cpv / m.gain[k]).max(0.0);
            // The model's variance less the quantization it adds: the
            // analog noise that moves a code.
            let sigma = (m.count_variance(e) - 1.0 / 12.0).max(0.0).sqrt();
            let p = repeat_chance(sigma);
            if p.is_finite() && p > 0.0 {
                self.ln_chance[k] += p.ln();
            }
        }
    }

    /// The frozen channels, bit k for detector k.
    pub fn mask(&self) -> u32 {
        let limit = FALSE_ALARM.ln();
        (0..NDET)
            .filter(|&k| self.ln_chance[k] <= limit)
            .fold(0, |m, k| m | 1 << k)
    }

    pub fn reset(&mut self) {
        *self = FrozenWatch::default();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::testutil::{tank_model, Rng};

    /// Counts of a lit channel: the model's analog σ at `level` counts.
    fn sigma_at(m: &SensorModel, k: usize, level: f64) -> f64 {
        let dark = m.offset_v[k] * m.counts_per_volt();
        let e = (level - dark) / m.counts_per_volt() / m.gain[k];
        (m.count_variance(e) - 1.0 / 12.0).sqrt()
    }

    #[test]
    fn a_frozen_lit_channel_is_called_after_as_many_frames_as_its_noise_says() {
        let m = tank_model();
        let k = 12;
        let level = 300u16;
        let sigma = sigma_at(&m, k, f64::from(level));
        let need = (FALSE_ALARM.ln() / repeat_chance(sigma).ln()).ceil();
        let mut w = FrozenWatch::default();
        let mut counts = [100u16; NDET];
        counts[k] = level;
        let mut called_at = None;
        for j in 0..200u16 {
            // Every other channel moves; channel k repeats.
            for (i, c) in counts.iter_mut().enumerate() {
                if i != k {
                    *c = 100 + (j % 7) + i as u16;
                }
            }
            w.observe(&m, &counts, f64::from(j));
            if called_at.is_none() && w.mask() != 0 {
                called_at = Some(j);
                assert_eq!(w.mask(), 1 << k, "only the frozen channel");
            }
        }
        // Frame 0 is the first reading; frame j is its j-th repeat.
        assert_eq!(called_at.map(f64::from), Some(need), "σ {sigma}");
        assert!((5.0..=60.0).contains(&need), "{need} repeats at σ {sigma}");
        // It comes back at its first change.
        counts[k] += 1;
        w.observe(&m, &counts, 200.0);
        assert_eq!(w.mask(), 0);
    }

    #[test]
    fn counts_at_a_bound_are_never_frozen() {
        let m = tank_model();
        let fs = m.full_scale() as u16;
        let mut counts = [0u16; NDET];
        counts[1] = fs;
        counts[2] = (m.offset_v[2] * m.counts_per_volt()).floor() as u16;
        let mut w = FrozenWatch::default();
        for j in 0..10_000 {
            w.observe(&m, &counts, f64::from(j));
        }
        assert_eq!(w.mask(), 0);
    }

    #[test]
    fn the_same_frame_twice_is_one_observation() {
        let m = tank_model();
        let mut counts = [100u16; NDET];
        counts[12] = 300;
        let mut once = FrozenWatch::default();
        let mut twice = FrozenWatch::default();
        for j in 0..100 {
            once.observe(&m, &counts, f64::from(j));
            twice.observe(&m, &counts, f64::from(j));
            twice.observe(&m, &counts, f64::from(j));
            assert_eq!(once.mask(), twice.mask(), "frame {j}");
        }
    }

    /// The per-repeat chance: P(|Z| < 1/σ), 1 for no noise.
    #[test]
    fn the_repeat_chance_is_a_normal_s_mass_within_one_code() {
        assert_eq!(repeat_chance(0.0), 1.0);
        assert!((repeat_chance(1.0) - 0.682_689_5).abs() < 1e-6);
        assert!((repeat_chance(2.0) - 0.382_924_9).abs() < 1e-6);
        let n = |s: f64| (FALSE_ALARM.ln() / repeat_chance(s).ln()).ceil();
        assert_eq!((n(3.0), n(1.5), n(1.0)), (21.0, 40.0, 73.0));
    }

    #[test]
    fn noise_alone_is_not_called_frozen() {
        let m = tank_model();
        let mut rng = Rng::new(7);
        let mut w = FrozenWatch::default();
        // The quietest lit level: just above the dark level, where the
        // analog noise is the dark noise alone.
        let mut flagged = 0u32;
        let frames = 200_000;
        for j in 0..frames {
            let mut counts = [0u16; NDET];
            for (k, c) in counts.iter_mut().enumerate() {
                let dark = m.offset_v[k] * m.counts_per_volt();
                let mean = dark + 20.0 + 10.0 * k as f64;
                let s = sigma_at(&m, k, mean);
                let v = mean + s * rng.normal();
                *c = v.round().clamp(0.0, m.full_scale()) as u16;
            }
            w.observe(&m, &counts, f64::from(j));
            flagged += w.mask().count_ones();
        }
        assert_eq!(flagged, 0, "{frames} frames of noise");
    }
}
