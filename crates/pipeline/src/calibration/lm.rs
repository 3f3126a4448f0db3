//! Levenberg–Marquardt for the calibration's fits (the physical fit of one
//! beacon, the fit of a docking station): one loop for both, so that the
//! way a fit steps, damps and stops is the same wherever it is used.

use nalgebra::{DMatrix, DVector};

/// Where Levenberg–Marquardt ended: the parameters, and the normalized
/// residuals, Jacobian and cost there.
pub(crate) struct Lm {
    pub p: Vec<f64>,
    pub r: DVector<f64>,
    pub jac: DMatrix<f64>,
    pub cost: f64,
    pub converged: bool,
}

/// Levenberg–Marquardt from `p` on `nrows` normalized residuals: `eval`
/// gives them at a point (and fills the Jacobian when asked); a step to a
/// point `allowed` refuses is damped harder. Stops when a step no longer
/// lowers the cost by a relative 1e-10, or when no damping gives a step
/// downhill, or after `max_iter`.
pub(crate) fn levenberg_marquardt(
    mut p: Vec<f64>,
    nrows: usize,
    max_iter: usize,
    allowed: impl Fn(&[f64]) -> bool,
    eval: impl Fn(&[f64], Option<&mut DMatrix<f64>>) -> DVector<f64>,
) -> Lm {
    let npar = p.len();
    let mut jac = DMatrix::zeros(nrows, npar);
    let mut r = eval(&p, Some(&mut jac));
    let mut cost = r.norm_squared();
    let mut lambda = 1e-3;
    let mut converged = false;
    for _ in 0..max_iter {
        let h = jac.transpose() * &jac;
        let g = jac.transpose() * &r;
        let mut stepped = false;
        for _ in 0..15 {
            let mut a = h.clone();
            for i in 0..npar {
                a[(i, i)] += lambda * h[(i, i)].max(1e-12);
            }
            let Some(ch) = a.cholesky() else {
                lambda *= 10.0;
                continue;
            };
            let delta = -ch.solve(&g);
            let pn: Vec<f64> = p.iter().zip(delta.iter()).map(|(a, b)| a + b).collect();
            if !allowed(&pn) {
                lambda *= 4.0;
                continue;
            }
            let rn = eval(&pn, None);
            let cn = rn.norm_squared();
            if cn.is_finite() && cn <= cost {
                let rel = (cost - cn) / cost.max(1e-300);
                p = pn;
                cost = cn;
                lambda = (lambda / 3.0).max(1e-12);
                stepped = true;
                if rel < 1e-10 {
                    converged = true;
                }
                break;
            }
            lambda *= 4.0;
        }
        if !stepped {
            converged = true;
        }
        r = eval(&p, Some(&mut jac));
        if converged {
            break;
        }
    }
    Lm {
        p,
        r,
        jac,
        cost,
        converged,
    }
}
