//! Ensemble statistics of the Monte Carlo: per time step and axis the mean,
//! the spread and the 2.5/97.5 % percentiles whose half distance is the
//! paper's 95 % confidence interval; and how often an estimator's own σ
//! covered the truth. Reductions walk runs in index order so that they do
//! not depend on how the realizations were scheduled.

use crate::axis::{AXES, NAXES};

/// Statistics of one axis at one step, over the runs that gave a value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisStats {
    /// Runs that gave a value.
    pub n: usize,
    pub mean: f64,
    /// Sample standard deviation (0 for a single value).
    pub std: f64,
    pub p025: f64,
    pub p975: f64,
}

impl AxisStats {
    /// Half-width of the central 95 % of the ensemble: the paper's "CI".
    pub fn half_width(&self) -> f64 {
        0.5 * (self.p975 - self.p025)
    }
}

/// One time step of the ensemble.
#[derive(Debug, Clone, PartialEq)]
pub struct StepStats {
    pub t: f64,
    /// Fraction of runs whose estimate had status `ok`.
    pub ok_fraction: f64,
    /// `None` where no run gave that axis at this step.
    pub axes: [Option<AxisStats>; NAXES],
}

/// How often truth lay within ±2σ of the estimator's own σ.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Coverage {
    /// Estimates that reported both a value and a σ.
    pub n: usize,
    pub inside: usize,
}

impl Coverage {
    pub fn fraction(&self) -> f64 {
        self.inside as f64 / self.n.max(1) as f64
    }
}

/// Linear-interpolated percentile (R type 7) of sorted values, q in [0, 1].
pub fn percentile(sorted: &[f64], q: f64) -> f64 {
    match sorted.len() {
        0 => f64::NAN,
        1 => sorted[0],
        n => {
            let h = (n - 1) as f64 * q.clamp(0.0, 1.0);
            let lo = h.floor() as usize;
            let hi = (lo + 1).min(n - 1);
            sorted[lo] + (h - lo as f64) * (sorted[hi] - sorted[lo])
        }
    }
}

/// Statistics of finite values (order does not matter: they are sorted).
pub fn axis_stats(values: &mut [f64]) -> Option<AxisStats> {
    let n = values.len();
    if n == 0 {
        return None;
    }
    values.sort_by(f64::total_cmp);
    let mean = values.iter().sum::<f64>() / n as f64;
    let var = if n > 1 {
        values.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / (n - 1) as f64
    } else {
        0.0
    };
    Some(AxisStats {
        n,
        mean,
        std: var.sqrt(),
        p025: percentile(values, 0.025),
        p975: percentile(values, 0.975),
    })
}

/// Per-step statistics of run-major samples (`[run][step][axis]`, NaN for
/// no value) and status flags (`[run][step]`).
pub fn per_step(samples: &[f64], ok: &[bool], times: &[f64], runs: usize) -> Vec<StepStats> {
    let nsteps = times.len();
    let mut buf = Vec::with_capacity(runs);
    times
        .iter()
        .enumerate()
        .map(|(j, &t)| {
            let oks = (0..runs).filter(|r| ok[r * nsteps + j]).count();
            let mut axes = [None; NAXES];
            for a in AXES {
                buf.clear();
                buf.extend(
                    (0..runs)
                        .map(|r| samples[(r * nsteps + j) * NAXES + a.index()])
                        .filter(|v| v.is_finite()),
                );
                axes[a.index()] = axis_stats(&mut buf);
            }
            StepStats {
                t,
                ok_fraction: oks as f64 / runs.max(1) as f64,
                axes,
            }
        })
        .collect()
}

/// Per-axis coverage of `[run][step][axis]` codes; `decode` says whether a
/// code is inside (true), outside (false) or unknown (None).
pub fn coverage(codes: &[u8], decode: impl Fn(u8) -> Option<bool>) -> [Option<Coverage>; NAXES] {
    let mut out = [None; NAXES];
    for a in AXES {
        let mut c = Coverage { n: 0, inside: 0 };
        for chunk in codes.chunks_exact(NAXES) {
            if let Some(inside) = decode(chunk[a.index()]) {
                c.n += 1;
                c.inside += inside as usize;
            }
        }
        out[a.index()] = (c.n > 0).then_some(c);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_interpolate_like_r_type_7() {
        let v: Vec<f64> = (0..=100).map(f64::from).collect();
        assert_eq!(percentile(&v, 0.025), 2.5);
        assert_eq!(percentile(&v, 0.975), 97.5);
        assert_eq!(percentile(&[3.0], 0.5), 3.0);
        assert!(percentile(&[], 0.5).is_nan());
    }

    #[test]
    fn stats_of_a_known_set() {
        let mut v = vec![4.0, 2.0, 3.0, 1.0];
        let s = axis_stats(&mut v).unwrap();
        assert_eq!(s.n, 4);
        assert_eq!(s.mean, 2.5);
        assert!((s.std - (5.0f64 / 3.0).sqrt()).abs() < 1e-12);
        assert!((s.p025 - 1.075).abs() < 1e-12 && (s.p975 - 3.925).abs() < 1e-12);
        assert!((s.half_width() - 1.425).abs() < 1e-12);
        assert!(axis_stats(&mut []).is_none());
    }
}
