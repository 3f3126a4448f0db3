//! What a phase search tells the track (step 4 of docs/demodulator.md):
//! the likelihood's own mean and spread over the window's cells, not the
//! best cell's centre and width. Why: a sampled square wave's likelihood
//! is flat within a cell, and next to a wide cell lie narrow ones that
//! differ from it by one channel's sample at an edge and fit about as
//! well. The best cell's width²/12 then claimed a precision the samples
//! do not have; a track fed it grew sure of itself, its prior outweighed
//! the samples, and its phase walked off the beacon's by a sample on the
//! dimmer frames (port of dock-example, 8 samples a period: amplitudes
//! 10–25 % low over whole stretches of a calibration sweep).

/// Mean and variance of the phase offset from a search's centre (cycles);
/// variance infinite when nothing was searched.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Spread {
    pub mean: f64,
    pub var: f64,
}

impl Default for Spread {
    fn default() -> Self {
        Spread {
            mean: 0.0,
            var: f64::INFINITY,
        }
    }
}

/// Sums of the cells' likelihood-weighted moments, offsets taken about
/// the first cell added (the best), wrapped, so that a window of a whole
/// cycle does not split a peak at its ends.
pub struct SpreadSum {
    about: Option<f64>,
    /// The largest log mass so far: the sums are scaled by it.
    top: f64,
    s0: f64,
    s1: f64,
    s2: f64,
}

impl SpreadSum {
    pub fn new() -> Self {
        SpreadSum {
            about: None,
            top: f64::NEG_INFINITY,
            s0: 0.0,
            s1: 0.0,
            s2: 0.0,
        }
    }

    /// The cell [lo, hi] of log-likelihood `ll` (any common offset): its
    /// mass exp(ll)·width, flat within it.
    pub fn add(&mut self, lo: f64, hi: f64, ll: f64) {
        let c = 0.5 * (lo + hi);
        let about = *self.about.get_or_insert(c);
        let d = wrap(c - about);
        let w = hi - lo;
        let log_mass = ll + w.ln();
        if !log_mass.is_finite() {
            return;
        }
        if log_mass > self.top {
            let r = (self.top - log_mass).exp();
            self.s0 *= r;
            self.s1 *= r;
            self.s2 *= r;
            self.top = log_mass;
        }
        let e = (log_mass - self.top).exp();
        self.s0 += e;
        self.s1 += e * d;
        self.s2 += e * (d * d + w * w / 12.0);
    }

    pub fn finish(&self) -> Spread {
        if self.s0 <= 0.0 {
            return Spread::default();
        }
        let m = self.s1 / self.s0;
        Spread {
            mean: m + self.about.unwrap_or(0.0),
            var: (self.s2 / self.s0 - m * m).max(1e-18),
        }
    }
}

fn wrap(x: f64) -> f64 {
    (x + 0.5).rem_euclid(1.0) - 0.5
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_cell_gives_its_centre_and_width() {
        let mut s = SpreadSum::new();
        s.add(0.002, 0.08, 0.0);
        let p = s.finish();
        assert!((p.mean - 0.041).abs() < 1e-12);
        assert!((p.var - 0.078f64.powi(2) / 12.0).abs() < 1e-12);
    }

    #[test]
    fn equal_neighbours_share_the_mass_and_a_poor_one_counts_little() {
        // Two cells of one width and likelihood either side of 0: the mean
        // between them, the variance their spread.
        let mut s = SpreadSum::new();
        s.add(0.01, 0.02, 0.0);
        s.add(-0.02, -0.01, 0.0);
        let p = s.finish();
        assert!(p.mean.abs() < 1e-12, "{p:?}");
        assert!((p.var - (0.015f64.powi(2) + 0.01f64.powi(2) / 12.0)).abs() < 1e-12);
        // A narrow neighbour e^-10 as likely barely moves a wide cell's.
        let mut s = SpreadSum::new();
        s.add(0.0, 0.08, 0.0);
        s.add(-0.002, 0.0, -10.0);
        assert!((s.finish().mean - 0.04).abs() < 1e-6);
    }

    #[test]
    fn a_peak_at_the_window_s_ends_is_not_split() {
        // Cells at +0.49 and −0.49 are 0.02 apart across the wrap.
        let mut s = SpreadSum::new();
        s.add(0.48, 0.50, 0.0);
        s.add(-0.50, -0.48, 0.0);
        let p = s.finish();
        assert!((p.mean - 0.5).abs() < 1e-12, "{p:?}");
        assert!(p.var < 0.001, "{p:?}");
    }
}
