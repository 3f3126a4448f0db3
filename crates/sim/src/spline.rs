//! Natural cubic spline through knots (second derivative zero at both
//! ends), as MODEL.md prescribes for trajectories.

/// One column of a trajectory as a natural cubic spline.
#[derive(Debug, Clone)]
pub struct Spline {
    t: Vec<f64>,
    y: Vec<f64>,
    /// Second derivatives at the knots.
    m: Vec<f64>,
}

impl Spline {
    /// `t` strictly increasing with at least two knots (checked by the
    /// caller, which knows the file and line).
    pub fn new(t: &[f64], y: &[f64]) -> Self {
        let n = t.len();
        let mut m = vec![0.0; n];
        if n > 2 {
            // Tridiagonal system for the interior second derivatives
            // (Thomas algorithm; diagonally dominant, so stable).
            let k = n - 2;
            let mut diag = vec![0.0; k];
            let mut rhs = vec![0.0; k];
            let mut upper = vec![0.0; k];
            for i in 0..k {
                let h0 = t[i + 1] - t[i];
                let h1 = t[i + 2] - t[i + 1];
                diag[i] = 2.0 * (h0 + h1);
                upper[i] = h1;
                rhs[i] = 6.0 * ((y[i + 2] - y[i + 1]) / h1 - (y[i + 1] - y[i]) / h0);
            }
            for i in 1..k {
                let lower = t[i + 1] - t[i];
                let w = lower / diag[i - 1];
                diag[i] -= w * upper[i - 1];
                rhs[i] -= w * rhs[i - 1];
            }
            m[k] = rhs[k - 1] / diag[k - 1];
            for i in (0..k - 1).rev() {
                m[i + 1] = (rhs[i] - upper[i] * m[i + 2]) / diag[i];
            }
        }
        Spline {
            t: t.to_vec(),
            y: y.to_vec(),
            m,
        }
    }

    fn segment(&self, t: f64) -> usize {
        let n = self.t.len();
        match self.t.partition_point(|&k| k <= t) {
            0 => 0,
            i if i >= n => n - 2,
            i => i - 1,
        }
    }

    /// Value and first derivative at `t` (extrapolated linearly-cubic past
    /// the ends; callers sample inside).
    pub fn eval(&self, t: f64) -> (f64, f64) {
        let i = self.segment(t);
        let (t0, t1) = (self.t[i], self.t[i + 1]);
        let h = t1 - t0;
        let a = (t1 - t) / h;
        let b = (t - t0) / h;
        let (m0, m1) = (self.m[i], self.m[i + 1]);
        let (y0, y1) = (self.y[i], self.y[i + 1]);
        let v = a * y0 + b * y1 + ((a * a * a - a) * m0 + (b * b * b - b) * m1) * h * h / 6.0;
        let d =
            (y1 - y0) / h - (3.0 * a * a - 1.0) * h * m0 / 6.0 + (3.0 * b * b - 1.0) * h * m1 / 6.0;
        (v, d)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn passes_through_knots_and_reproduces_lines() {
        let t = [0.0, 1.0, 2.5, 4.0];
        let y = [1.0, 3.0, 6.0, 9.0];
        let s = Spline::new(&t, &y);
        for (tk, yk) in t.iter().zip(y) {
            assert!((s.eval(*tk).0 - yk).abs() < 1e-12);
        }
        let line = Spline::new(&t, &[0.0, 2.0, 5.0, 8.0]);
        assert!((line.eval(1.7).0 - 3.4).abs() < 1e-12);
        assert!((line.eval(3.3).1 - 2.0).abs() < 1e-12);
    }

    #[test]
    fn natural_ends_and_continuity() {
        let t = [0.0, 1.0, 2.0, 3.0, 5.0];
        let y = [0.0, 1.0, 0.0, 2.0, -1.0];
        let s = Spline::new(&t, &y);
        assert_eq!(s.m[0], 0.0);
        assert_eq!(s.m[4], 0.0);
        // first derivative continuous across knots
        for &k in &t[1..4] {
            let (_, dl) = s.eval(k - 1e-9);
            let (_, dr) = s.eval(k + 1e-9);
            assert!((dl - dr).abs() < 1e-6);
        }
    }
}
