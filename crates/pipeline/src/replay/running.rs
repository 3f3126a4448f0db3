//! Running error statistics of one axis in bounded memory, so that a replay
//! of a million frames with truth holds kilobytes, not every frame's error.
//!
//! The mean and the RMSE are running sums, exactly what summing every error
//! in order gives. The 95th percentile of |error| is the nearest-rank value:
//!
//! - exact while an axis has at most [`EXACT`] errors (every test log and
//!   most recordings);
//! - beyond, read from a histogram with log-spaced bins (the top 9 mantissa
//!   bits of the f64: 512 bins per octave): the bin's middle, within 0.1 %
//!   of the exact value for |error| in [2⁻²⁰, 2¹⁶) ≈ [9.5e-7, 65536), within
//!   4.8e-7 below that, and the largest error seen (an upper bound) above.
//!   The histogram is 18,432 counters (72 KiB) per axis, allocated only
//!   when an axis passes [`EXACT`].

use super::AxisError;

/// Errors an axis keeps exactly before it switches to the histogram.
pub const EXACT: usize = 2048;
const MANT_BITS: u32 = 9;
const MIN_EXP: i32 = -20;
const MAX_EXP: i32 = 16;
const BINS: usize = ((MAX_EXP - MIN_EXP) as usize) << MANT_BITS;

/// Where |error| `v` (finite, ≥ 0) falls.
enum Bin {
    Below,
    At(usize),
    Above,
}

fn bin(v: f64) -> Bin {
    let bits = v.to_bits();
    let exp = ((bits >> 52) & 0x7ff) as i32 - 1023;
    if v == 0.0 || exp < MIN_EXP {
        return Bin::Below;
    }
    if exp >= MAX_EXP {
        return Bin::Above;
    }
    let mant = ((bits >> (52 - MANT_BITS)) & ((1 << MANT_BITS) - 1)) as usize;
    Bin::At((((exp - MIN_EXP) as usize) << MANT_BITS) + mant)
}

/// The middle of bin `i`.
fn middle(i: usize) -> f64 {
    let exp = (i >> MANT_BITS) as i32 + MIN_EXP;
    let step = 1.0 / (1u32 << MANT_BITS) as f64;
    let mant = (i & ((1 << MANT_BITS) - 1)) as f64;
    2f64.powi(exp) * (1.0 + (mant + 0.5) * step)
}

/// The nearest-rank quantiles of |error|, exact up to [`EXACT`] values.
#[derive(Debug, Default)]
struct AbsQuantile {
    exact: Vec<f64>,
    hist: Option<Vec<u32>>,
    below: u64,
    above: u64,
}

impl AbsQuantile {
    fn push(&mut self, v: f64) {
        if self.hist.is_none() && self.exact.len() < EXACT {
            self.exact.push(v);
            return;
        }
        if self.hist.is_none() {
            let exact = std::mem::take(&mut self.exact);
            self.hist = Some(vec![0; BINS]);
            for e in exact {
                self.count(e);
            }
        }
        self.count(v);
    }

    fn count(&mut self, v: f64) {
        match (bin(v), self.hist.as_mut()) {
            (Bin::Below, _) => self.below += 1,
            (Bin::Above, _) => self.above += 1,
            (Bin::At(i), Some(h)) => h[i] = h[i].saturating_add(1),
            (Bin::At(_), None) => {}
        }
    }

    /// The `rank`-th smallest (1-based); `max` stands for those above.
    fn ranked(&mut self, rank: u64, max: f64) -> f64 {
        let Some(h) = &self.hist else {
            self.exact.sort_by(f64::total_cmp);
            return self.exact[(rank as usize).clamp(1, self.exact.len()) - 1];
        };
        if rank <= self.below {
            return 2f64.powi(MIN_EXP - 1);
        }
        let mut seen = self.below;
        for (i, &c) in h.iter().enumerate() {
            seen += u64::from(c);
            if seen >= rank {
                return middle(i);
            }
        }
        max
    }
}

/// One axis's signed errors, summed as they come.
#[derive(Debug, Default)]
pub(super) struct RunningAxis {
    n: usize,
    sum: f64,
    sum_sq: f64,
    max_abs: f64,
    last: f64,
    abs: AbsQuantile,
}

impl RunningAxis {
    pub fn push(&mut self, e: f64) {
        self.n += 1;
        self.sum += e;
        self.sum_sq += e * e;
        self.max_abs = self.max_abs.max(e.abs());
        self.last = e;
        self.abs.push(e.abs());
    }

    /// The statistics so far; `None` before the first error.
    pub fn report(&mut self) -> Option<AxisError> {
        if self.n == 0 {
            return None;
        }
        let n = self.n;
        let rank = ((0.95 * n as f64).ceil() as u64).clamp(1, n as u64);
        Some(AxisError {
            n,
            mean: self.sum / n as f64,
            rmse: (self.sum_sq / n as f64).sqrt(),
            p95: self.abs.ranked(rank, self.max_abs),
            last: self.last,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn bins_and_their_middles() {
        for v in [1e-6, 0.01, 0.3, 1.0, 7.25, 1000.0, 65535.0] {
            let Bin::At(i) = bin(v) else { panic!("{v}") };
            let m = middle(i);
            assert!((m - v).abs() <= 1e-3 * v, "{v} → {m}");
        }
        assert!(matches!(bin(0.0), Bin::Below));
        assert!(matches!(bin(1e-7), Bin::Below));
        assert!(matches!(bin(65536.0), Bin::Above));
        assert_eq!(BINS, 18_432);
    }

    proptest! {
        /// Past the exact buffer the histogram's p95 is within 0.1 % of the
        /// exact nearest-rank value; mean and RMSE are the plain sums.
        #[test]
        fn p95_within_a_tenth_of_a_percent(
            errs in prop::collection::vec(-50.0f64..50.0, EXACT + 1..EXACT * 3),
        ) {
            let mut r = RunningAxis::default();
            for &e in &errs {
                r.push(e);
            }
            let got = r.report().unwrap();
            let want = AxisError::of(&errs).unwrap();
            prop_assert_eq!(got.n, want.n);
            prop_assert_eq!(got.mean, want.mean);
            prop_assert_eq!(got.rmse, want.rmse);
            prop_assert_eq!(got.last, want.last);
            let tol = 1e-3 * want.p95 + 4.8e-7;
            prop_assert!((got.p95 - want.p95).abs() <= tol, "{} vs {}", got.p95, want.p95);
        }

        /// Up to the exact buffer the report is the exact one.
        #[test]
        fn exact_below_the_buffer(errs in prop::collection::vec(-5.0f64..5.0, 1..200)) {
            let mut r = RunningAxis::default();
            for &e in &errs {
                r.push(e);
            }
            prop_assert_eq!(r.report().unwrap(), AxisError::of(&errs).unwrap());
        }
    }
}
