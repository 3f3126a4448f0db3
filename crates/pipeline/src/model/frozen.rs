//! Channels whose count has stopped moving: a photodiode or ADC input
//! stuck at a value between the bounds, which one frame cannot tell from
//! light (see [`Censoring::classify`](super::solver::Censoring::classify)
//! for the bounds) but its history can.
//!
//! Why: a channel frozen at its first reading is right at first and grows
//! wrong as the vehicle moves; fitted as data it cost a quarter of the
//! tank zigzag's poses (the centre channel: 9 of 41 `diverged`, 12
//! `initialising`). Noise alone moves a lit channel's count: two readings
//! of one light with analog noise σ (counts) land on the same code with a
//! chance of at most 1/(2σ√π) when codes are 1 LSB wide (the density of
//! their difference at 0, N(0, 2σ²), which a uniform code position
//! averages over a triangle of area 1); this takes codes up to 2 LSB wide
//! (an ADC's differential non-linearity), 1/(σ√π). A channel is frozen
//! when the chance that noise alone repeated its count as many frames as
//! it has falls below [`FALSE_ALARM`]: 13 frames at σ = 3 counts, 21 at
//! σ = 1.5, never below σ = 1/√π (a channel that quiet may repeat by
//! itself). Motion only makes a repeat less likely, so the figure holds for
//! a vehicle at rest. A count at a bound (0, full scale, at or below the
//! dark level) repeats by itself and is not counted. The first change of
//! the count takes the channel back.

use lightpose_core::NDET;

use super::SensorModel;

/// Chance, per channel and frame, that noise alone keeps a live channel's
/// count long enough to be called frozen: 25 channels at 5 Hz make one
/// such call in ~250 years, at 100 Hz in ~13; each costs one channel until
/// its count next moves.
pub const FALSE_ALARM: f64 = 1e-9;

/// The watch over each channel's history: fixed arrays, nothing
/// allocated, one pass per frame.
#[derive(Debug, Clone, Copy)]
pub struct FrozenWatch {
    last: [u16; NDET],
    /// ln of the chance that noise alone gave the run of equal counts so
    /// far (0 after a change).
    ln_chance: [f64; NDET],
    seen: bool,
}

impl Default for FrozenWatch {
    fn default() -> Self {
        FrozenWatch {
            last: [0; NDET],
            ln_chance: [0.0; NDET],
            seen: false,
        }
    }
}

impl FrozenWatch {
    /// Take one frame's counts (in the order the frames come).
    pub fn observe(&mut self, m: &SensorModel, counts: &[u16; NDET]) {
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
            let p = (1.0 / (sigma * std::f64::consts::PI.sqrt())).min(1.0);
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
        let need = (FALSE_ALARM.ln() / (1.0 / (sigma * std::f64::consts::PI.sqrt())).ln()).ceil();
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
            w.observe(&m, &counts);
            if called_at.is_none() && w.mask() != 0 {
                called_at = Some(j);
                assert_eq!(w.mask(), 1 << k, "only the frozen channel");
            }
        }
        // Frame 0 is the first reading; frame j is its j-th repeat.
        assert_eq!(called_at.map(f64::from), Some(need), "σ {sigma}");
        assert!((5.0..=40.0).contains(&need), "{need} repeats at σ {sigma}");
        // It comes back at its first change.
        counts[k] += 1;
        w.observe(&m, &counts);
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
        for _ in 0..10_000 {
            w.observe(&m, &counts);
        }
        assert_eq!(w.mask(), 0);
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
        for _ in 0..frames {
            let mut counts = [0u16; NDET];
            for (k, c) in counts.iter_mut().enumerate() {
                let dark = m.offset_v[k] * m.counts_per_volt();
                let mean = dark + 20.0 + 10.0 * k as f64;
                let s = sigma_at(&m, k, mean);
                let v = mean + s * rng.normal();
                *c = v.round().clamp(0.0, m.full_scale()) as u16;
            }
            w.observe(&m, &counts);
            flagged += w.mask().count_ones();
        }
        assert_eq!(flagged, 0, "{frames} frames of noise");
    }
}
