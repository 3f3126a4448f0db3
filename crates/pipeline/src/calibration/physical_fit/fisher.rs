//! Whether the sweeps determine every parameter of the physical fit, read
//! off its Fisher matrix: a parameter no data depends on, a direction the
//! data cannot fix (ill-conditioned), one confounded with the others
//! (variance inflation), or one whose standard error exceeds its value is
//! refused by name, so that a sweep that cannot calibrate says what it lacks.

// `!(a < b)` is deliberate: it is true for NaN, which must fail a check.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use super::CalibError;
use lightpose_core::NDET;
use nalgebra::{DMatrix, DVector, SymmetricEigen};

const PHYS_NAMES: [&str; 6] = ["v1", "sigma_b", "sigma_r", "k_d", "omega", "sigma_h"];

fn param_name(i: usize, np: usize) -> String {
    if i < np {
        PHYS_NAMES[i].to_string()
    } else if i < np + NDET - 1 {
        format!("gain[{}]", i - np)
    } else {
        format!("offset[{}]", i - np - (NDET - 1))
    }
}

/// Refuse a Fisher matrix that cannot determine every parameter,
/// naming the parameter most involved in its weakest direction.
fn check_determined(
    h: &DMatrix<f64>,
    param_name: &dyn Fn(usize) -> String,
) -> Result<DMatrix<f64>, CalibError> {
    let n = h.nrows();
    let mut d = DVector::zeros(n);
    for i in 0..n {
        let v = h[(i, i)];
        if !(v > 0.0 && v.is_finite()) {
            return Err(CalibError::Undetermined {
                parameter: param_name(i),
                reason: "no data depends on it (zero Fisher column)".into(),
            });
        }
        d[i] = 1.0 / v.sqrt();
    }
    let hs = DMatrix::from_fn(n, n, |i, j| h[(i, j)] * d[i] * d[j]);
    let eig = SymmetricEigen::new(hs.clone());
    let (mut imin, mut lmin, mut lmax) = (0, f64::INFINITY, 0.0f64);
    for (i, l) in eig.eigenvalues.iter().enumerate() {
        if *l < lmin {
            lmin = *l;
            imin = i;
        }
        lmax = lmax.max(*l);
    }
    let cond = lmax / lmin.max(1e-300);
    if !(cond < 1e12) {
        let v = eig.eigenvectors.column(imin);
        let worst = (0..n)
            .max_by(|a, b| v[*a].abs().total_cmp(&v[*b].abs()))
            .unwrap_or(0);
        return Err(CalibError::Undetermined {
            parameter: param_name(worst),
            reason: format!("singular or ill-conditioned Fisher matrix (condition {cond:.1e})"),
        });
    }
    let inv = hs
        .cholesky()
        .map(|c| c.inverse())
        .ok_or_else(|| CalibError::Undetermined {
            parameter: param_name(imin),
            reason: "Fisher matrix is not positive definite".into(),
        })?;
    Ok(DMatrix::from_fn(n, n, |i, j| inv[(i, j)] * d[i] * d[j]))
}

/// The covariance at `p`, or which parameter the data leave undetermined.
pub(super) fn determined(
    h: &DMatrix<f64>,
    p: &[f64],
    np: usize,
    npar: usize,
) -> Result<DMatrix<f64>, CalibError> {
    determined_named(h, p, np, npar, &|i| param_name(i, np))
}

/// As [`determined`], the parameters named by `param_name`; the first `np`
/// are positive quantities, whose standard error must stay below their
/// value (a station's fit: each beacon's V1 and σ_b, then the water's).
pub(crate) fn determined_named(
    h: &DMatrix<f64>,
    p: &[f64],
    np: usize,
    npar: usize,
    param_name: &dyn Fn(usize) -> String,
) -> Result<DMatrix<f64>, CalibError> {
    let cov = check_determined(h, param_name)?;
    // A parameter whose marginal variance is vastly above its variance
    // with the others held (variance inflation) is confounded with
    // them; one whose standard error exceeds its value is not measured.
    for i in 0..npar {
        let vif = cov[(i, i)] * h[(i, i)];
        if !(vif < 1e8) {
            return Err(CalibError::Undetermined {
                parameter: param_name(i),
                reason: format!("ill-conditioned Fisher matrix (variance inflation {vif:.1e})"),
            });
        }
    }
    for i in 0..np {
        let se = cov[(i, i)].max(0.0).sqrt();
        if !(se < p[i].abs()) {
            return Err(CalibError::Undetermined {
                parameter: param_name(i),
                reason: format!(
                    "standard error {se:.3e} exceeds the value {:.3e} (Fisher information too small)",
                    p[i]
                ),
            });
        }
    }
    Ok(cov)
}
