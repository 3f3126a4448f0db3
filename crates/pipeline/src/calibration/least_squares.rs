//! Streaming least squares for the calibration: a straight line v = a·u + b
//! fitted from its normal equations, accumulated one sample at a time so a
//! sweep of 61,600 frames never sits in memory. The sums are kept about the
//! running means (Welford), which is the same normal equations, centred, and
//! does not lose digits when u is large and varies little.

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum FitError {
    #[error("only {0} samples, at least 3 are needed")]
    TooFew(u64),
    #[error("the input does not vary across the samples")]
    InputConstant,
    #[error("the target does not vary across the samples")]
    TargetConstant,
}

/// Centred sums of a line fit.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LineAcc {
    n: u64,
    mean_u: f64,
    mean_v: f64,
    suu: f64,
    svv: f64,
    suv: f64,
    min_u: f64,
    max_u: f64,
    min_v: f64,
    max_v: f64,
}

/// A fitted line and how well it fits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Line {
    pub slope: f64,
    pub intercept: f64,
    /// Coefficient of determination, 1 − SS_res/SS_tot.
    pub r2: f64,
    /// Residual standard deviation, √(SS_res/(n − 2)).
    pub sigma: f64,
    pub n: u64,
}

impl LineAcc {
    /// Add one sample; non-finite samples are ignored (they carry nothing).
    #[inline]
    pub fn push(&mut self, u: f64, v: f64) {
        if !(u.is_finite() && v.is_finite()) {
            return;
        }
        if self.n == 0 {
            (self.min_u, self.max_u, self.min_v, self.max_v) = (u, u, v, v);
        } else {
            self.min_u = self.min_u.min(u);
            self.max_u = self.max_u.max(u);
            self.min_v = self.min_v.min(v);
            self.max_v = self.max_v.max(v);
        }
        self.n += 1;
        let n = self.n as f64;
        let du = u - self.mean_u;
        let dv = v - self.mean_v;
        self.mean_u += du / n;
        self.mean_v += dv / n;
        self.suu += du * (u - self.mean_u);
        self.svv += dv * (v - self.mean_v);
        self.suv += du * (v - self.mean_v);
    }

    pub fn n(&self) -> u64 {
        self.n
    }

    /// [min, max] of the targets seen.
    pub fn target_range(&self) -> [f64; 2] {
        [self.min_v, self.max_v]
    }

    /// RMS of the residuals v − (intercept + slope·u) of the samples seen
    /// against a line fitted elsewhere (e.g. a subset of them).
    pub fn rms_about(&self, slope: f64, intercept: f64) -> f64 {
        if self.n == 0 {
            return f64::NAN;
        }
        let c = self.mean_v - intercept - slope * self.mean_u;
        let ss = self.svv - 2.0 * slope * self.suv + slope * slope * self.suu;
        ((ss.max(0.0) + self.n as f64 * c * c) / self.n as f64).sqrt()
    }

    /// Solve the normal equations.
    pub fn solve(&self) -> Result<Line, FitError> {
        if self.n < 3 {
            return Err(FitError::TooFew(self.n));
        }
        // "Does not vary": the spread is at rounding level of the values.
        let tiny = |s: f64, lo: f64, hi: f64| {
            s <= 1e-24 * (1.0 + lo * lo + hi * hi) * self.n as f64 || hi == lo
        };
        if tiny(self.suu, self.min_u, self.max_u) {
            return Err(FitError::InputConstant);
        }
        if tiny(self.svv, self.min_v, self.max_v) {
            return Err(FitError::TargetConstant);
        }
        let slope = self.suv / self.suu;
        let intercept = self.mean_v - slope * self.mean_u;
        let ss_res = (self.svv - slope * self.suv).max(0.0);
        Ok(Line {
            slope,
            intercept,
            r2: 1.0 - ss_res / self.svv,
            sigma: (ss_res / (self.n - 2) as f64).sqrt(),
            n: self.n,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn rms_about_another_line() {
        let mut a = LineAcc::default();
        for (u, v) in [(1.0, 2.0), (2.0, 3.0), (3.0, 7.0)] {
            a.push(u, v);
        }
        // residuals against v = 1 + u: 0, 0, 3
        assert!((a.rms_about(1.0, 1.0) - (9.0f64 / 3.0).sqrt()).abs() < 1e-12);
    }

    #[test]
    fn exact_line_is_recovered() {
        let mut a = LineAcc::default();
        for i in 0..10 {
            let u = i as f64 * 0.5 + 4.5;
            a.push(u, 3.0 - 0.2 * u);
        }
        let l = a.solve().unwrap();
        assert!((l.slope + 0.2).abs() < 1e-12 && (l.intercept - 3.0).abs() < 1e-12);
        assert!((l.r2 - 1.0).abs() < 1e-12 && l.sigma < 1e-12);
    }

    #[test]
    fn degenerate_inputs_are_refused() {
        let mut a = LineAcc::default();
        a.push(1.0, 1.0);
        a.push(2.0, 2.0);
        assert_eq!(a.solve(), Err(FitError::TooFew(2)));
        let mut a = LineAcc::default();
        for v in 0..5 {
            a.push(6.5, v as f64);
        }
        assert_eq!(a.solve(), Err(FitError::InputConstant));
        let mut a = LineAcc::default();
        for u in 0..5 {
            a.push(u as f64, 2.0);
        }
        assert_eq!(a.solve(), Err(FitError::TargetConstant));
    }

    proptest! {
        /// The streaming fit equals the textbook closed form.
        #[test]
        fn matches_closed_form(pts in prop::collection::vec((-100.0f64..100.0, -100.0f64..100.0), 3..60)) {
            let mut a = LineAcc::default();
            for &(u, v) in &pts { a.push(u, v); }
            let n = pts.len() as f64;
            let (su, sv) = pts.iter().fold((0.0, 0.0), |s, p| (s.0 + p.0, s.1 + p.1));
            let (mu, mv) = (su / n, sv / n);
            let suu: f64 = pts.iter().map(|p| (p.0 - mu).powi(2)).sum();
            let suv: f64 = pts.iter().map(|p| (p.0 - mu) * (p.1 - mv)).sum();
            prop_assume!(suu > 1e-6);
            if let Ok(l) = a.solve() {
                let slope = suv / suu;
                prop_assert!((l.slope - slope).abs() <= 1e-9 * (1.0 + slope.abs()));
                prop_assert!((l.intercept - (mv - slope * mu)).abs() <= 1e-7 * (1.0 + mv.abs() + (slope * mu).abs()));
                prop_assert!(l.r2 <= 1.0 + 1e-12 && l.r2 >= -1e-9);
            }
        }
    }
}
