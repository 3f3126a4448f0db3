//! The slow part of a frame: polynomials in time, orthonormal over the
//! frame's N samples, that the fit removes with the constant. Daylight's
//! flicker (below ~20 Hz) is smooth over a frame, so it lies almost wholly
//! in their span, and what is left of it after their removal is too small
//! and too smooth to leak into a square wave of a few hundred hertz.

/// The degree that keeps flicker up to `max_hz` out of a frame of
/// `frame_s` seconds. A sinusoid of ω = π·max_hz·frame_s radians over the
/// half frame has Chebyshev coefficients that fall off fast past degree ω
/// (as the Bessel function J_n(ω)); six degrees past it the residual is
/// ≲ 1e-4 of the flicker, and what of that leaks into a square wave of P
/// whole periods per frame is smaller again by about 1/P (a linear ramp
/// leaks 0.87/P of its size; docs/demodulator.md has the measured figures).
pub fn degree_for(max_hz: f64, frame_s: f64) -> usize {
    let omega = std::f64::consts::PI * max_hz * frame_s;
    // At least a straight line: drift of the dark level within a frame.
    (omega.ceil() as usize + 6).max(1)
}

/// Orthonormal polynomials of degree 0..=d on the samples' times, as a
/// (d + 1) × N row-major table: `row(j)[i]` is p_j at sample i, and
/// Σ_i p_j p_l = δ_jl.
#[derive(Debug, Clone)]
pub struct Basis {
    n: usize,
    rows: Vec<f64>,
}

impl Basis {
    /// Built by the Stieltjes recurrence on x_i in [−1, 1], each new row
    /// orthogonalised twice against all the earlier ones, which keeps it
    /// orthonormal to rounding at the degrees used here (tens).
    pub fn new(n: usize, degree: usize) -> Self {
        let d = degree + 1;
        let mut rows = vec![0.0; d * n];
        let x = |i: usize| {
            if n > 1 {
                2.0 * i as f64 / (n - 1) as f64 - 1.0
            } else {
                0.0
            }
        };
        let inv = 1.0 / (n as f64).sqrt();
        rows[..n].iter_mut().for_each(|v| *v = inv);
        for j in 1..d {
            let (done, rest) = rows.split_at_mut(j * n);
            let new = &mut rest[..n];
            let prev = &done[(j - 1) * n..j * n];
            for i in 0..n {
                new[i] = x(i) * prev[i];
            }
            for _ in 0..2 {
                for l in 0..j {
                    let p = &done[l * n..(l + 1) * n];
                    let c: f64 = p.iter().zip(new.iter()).map(|(a, b)| a * b).sum();
                    new.iter_mut().zip(p).for_each(|(v, a)| *v -= c * a);
                }
            }
            let norm = new.iter().map(|v| v * v).sum::<f64>().sqrt();
            new.iter_mut().for_each(|v| *v /= norm);
        }
        Basis { n, rows }
    }

    /// D: the number of polynomials (degree + 1).
    pub fn len(&self) -> usize {
        self.rows.len() / self.n
    }

    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    pub fn row(&self, j: usize) -> &[f64] {
        &self.rows[j * self.n..(j + 1) * self.n]
    }

    /// `coef = Lᵀ x` and `x ← x − L coef`: x's slow part taken out.
    pub fn remove(&self, x: &mut [f64], coef: &mut [f64]) {
        for (j, c) in coef.iter_mut().enumerate().take(self.len()) {
            let p = self.row(j);
            let v: f64 = p.iter().zip(x.iter()).map(|(a, b)| a * b).sum();
            x.iter_mut().zip(p).for_each(|(xi, a)| *xi -= v * a);
            *c = v;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn orthonormal() {
        for (n, deg) in [(400, 20), (800, 25), (40, 8)] {
            let b = Basis::new(n, deg);
            for j in 0..b.len() {
                for l in 0..=j {
                    let d: f64 = b.row(j).iter().zip(b.row(l)).map(|(a, c)| a * c).sum();
                    let want = if j == l { 1.0 } else { 0.0 };
                    assert!((d - want).abs() < 1e-12, "n {n} rows {j},{l}: {d}");
                }
            }
        }
    }

    #[test]
    fn removes_polynomials() {
        let n = 400;
        let b = Basis::new(n, 3);
        let mut x: Vec<f64> = (0..n)
            .map(|i| {
                let t = i as f64 / 100.0;
                3.0 + 2.0 * t - 0.5 * t * t + 0.1 * t * t * t
            })
            .collect();
        let mut c = [0.0; 4];
        b.remove(&mut x, &mut c);
        assert!(x.iter().all(|v| v.abs() < 1e-10), "{:?}", &x[..4]);
    }
}
