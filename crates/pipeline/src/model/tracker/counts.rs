//! The tracker's update with a frame's 25 counts: the (iterated) EKF's
//! when the attitude is pinned by a reading, else a sigma-point update
//! that carries the beam factor's curvature over the ridges.
//!
//! Saturated and dark channels are censored: they enter the update only
//! when the prediction crosses the bound they prove.

// `!(a < b)` is deliberate: it is true for NaN, which must fail a check.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
// Channel loops index several parallel per-detector arrays at once.
#![allow(clippy::needless_range_loop)]

use lightpose_core::{Frame, NDET};
use nalgebra::{SMatrix, SVector};

use super::state::{k_d_of, Ms, State, Vs, KD, NS};
use super::Tracker;
use crate::model::light::{predict_rolled, predict_with_grad_rolled, PoseVec};
use crate::model::solver::Censoring;

/// The sigma-point update's coordinates: the pose and K_D.
const NP: usize = 6;
/// h² = 3 matches a Gaussian's fourth moment (DD2's choice).
const H2: f64 = 3.0;

type Zv = SVector<f64, NDET>;
type Hm = SMatrix<f64, NDET, NS>;
type Pm = SMatrix<f64, NP, NP>;

/// What a counts update needs to know about the frame besides its counts.
pub(super) struct CountsInput<'a> {
    pub frame: &'a Frame,
    /// Temperature gain g_T of the frame.
    pub gt: f64,
    pub kinds: [Censoring; NDET],
    /// Attitude pinned by a reading this frame: the EKF's update suffices.
    pub pinned: bool,
}

/// A counts update that was not applied (the gate, or numbers that went
/// bad): the state is untouched.
const REFUSED: bool = false;

/// Predicted counts' first- and second-order divided differences along
/// each sigma axis, and their mean.
struct SigmaSpread {
    s1: SMatrix<f64, NDET, NP>,
    s2: SMatrix<f64, NDET, NP>,
    zbar: Zv,
    irr: [f64; NDET],
}

impl Tracker {
    /// Update `s` with the frame's counts (EKF or sigma points, see the
    /// module's doc); false when the gate (normalized innovation squared
    /// per channel above `nis_gate`) or bad numbers refused it.
    pub(super) fn update_counts(&self, s: &mut State, inp: &CountsInput) -> bool {
        if !inp.pinned && self.cfg.sigma_points_without_attitude {
            self.update_sigma(s, inp)
        } else {
            self.update_ekf(s, inp)
        }
    }

    /// The (pose, K_D) block of the covariance the sigma points span: K_D's
    /// doubt is in P whether it is estimated or considered.
    fn sigma_block(s: &State) -> Pm {
        let idx = [0, 1, 2, 3, 4, KD];
        let mut pm = Pm::from_fn(|a, b| s.p[(idx[a], idx[b])]);
        // A K_D known exactly still needs a positive pivot; its columns
        // then evaluate to nothing.
        pm[(5, 5)] = pm[(5, 5)].max(1e-18);
        pm
    }

    /// The light equation at ±√3σ along each Cholesky axis `l` of the
    /// (pose, K_D) covariance about the state.
    fn sigma_spread(&self, s: &State, l: &Pm, gt: f64) -> SigmaSpread {
        let m = &self.model;
        let roll = s.roll_rad();
        let at = |d: &SVector<f64, NP>| -> Zv {
            let q = PoseVec::from_fn(|i, _| s.x[i] + d[i]);
            let kd = (s.x[KD] + d[5]).exp();
            predict_rolled(m, &q, roll, kd, gt).0
        };
        let h = H2.sqrt();
        // The centre point also gives the irradiance the noise model needs.
        let q0 = PoseVec::from_fn(|i, _| s.x[i]);
        let (z0, irr) = predict_rolled(m, &q0, roll, k_d_of(&s.x), gt);
        let mut sp = SigmaSpread {
            s1: SMatrix::zeros(),
            s2: SMatrix::zeros(),
            zbar: z0 * ((H2 - NP as f64) / H2),
            irr,
        };
        for j in 0..NP {
            let col: SVector<f64, NP> = l.column(j) * h;
            let zp = at(&col);
            let zm = at(&(-col));
            sp.s1.set_column(j, &((zp - zm) / (2.0 * h)));
            sp.s2.set_column(
                j,
                &((zp + zm - z0 * 2.0) * ((H2 - 1.0).sqrt() / (2.0 * H2))),
            );
            sp.zbar += (zp + zm) / (2.0 * H2);
        }
        sp
    }

    /// Sigma-point (second-order divided-difference, Nørgaard et al. 2000
    /// "DD2") update with the frame's counts, for frames whose attitude no
    /// reading pins. Why: along the y/yaw and z/pitch ridges the counts
    /// depend on the pose through the beam factor, which is quadratic about
    /// the beam axis; the EKF's Jacobian at an estimate a few degrees off
    /// that axis claims a slope that the counts do not have over the
    /// ridge's width, and the filter became confident along a ridge it
    /// could not see (±2σ coverage 50–60 % on the dive's z/pitch by the
    /// end). Evaluating the light equation at ±√3σ along each axis of the
    /// pose covariance (and of K_D's doubt) puts that curvature into the
    /// predicted counts' mean and covariance instead.
    ///
    /// Sigma points cover only what the counts depend on (pose and K_D);
    /// the rates are corrected through their covariance with the pose.
    fn update_sigma(&self, s: &mut State, inp: &CountsInput) -> bool {
        let m = &self.model;
        let fs = m.full_scale();
        let Some(chol) = Self::sigma_block(s).cholesky() else {
            return REFUSED;
        };
        let l = chol.l();
        let mut sp = self.sigma_spread(s, &l, inp.gt);
        let mut y = Zv::zeros();
        let mut used = [false; NDET];
        let mut n_used = 0usize;
        for k in 0..NDET {
            let obs = inp.frame.counts[k] as f64;
            if let Some(z) = inp.kinds[k].target(obs, sp.zbar[k], fs) {
                y[k] = z - sp.zbar[k];
                used[k] = true;
                n_used += 1;
            } else {
                sp.s1.row_mut(k).fill(0.0);
                sp.s2.row_mut(k).fill(0.0);
            }
        }
        let mut pzz = sp.s1 * sp.s1.transpose() + sp.s2 * sp.s2.transpose();
        if let Some((roll, sd)) = s.roll.filter(|(_, sd)| *sd > 0.0) {
            let q = PoseVec::from_fn(|i, _| s.x[i]);
            let mut jr = predict_with_grad_rolled(m, &q, roll, k_d_of(&s.x), inp.gt).3;
            for k in 0..NDET {
                if !used[k] {
                    jr[k] = 0.0;
                }
            }
            pzz += jr * jr.transpose() * (sd * sd);
        }
        for k in 0..NDET {
            pzz[(k, k)] += if used[k] {
                m.count_variance(sp.irr[k] * m.gain[k] * inp.gt)
            } else {
                1.0
            };
        }
        let Some(cs) = pzz.cholesky() else {
            return REFUSED;
        };
        let chi2 = y.dot(&cs.solve(&y));
        let nis = chi2 / (n_used.max(1) as f64);
        if !(nis <= self.cfg.nis_gate) {
            return REFUSED;
        }
        let ll = log_likelihood(chi2, &cs.l());
        // Cross-covariance of the whole state with the counts:
        // P[:, idx]·L⁻ᵀ·S1ᵀ (exact for the rates, which the counts see only
        // through the pose and K_D).
        let idx = [0, 1, 2, 3, 4, KD];
        let pcols = SMatrix::<f64, NS, NP>::from_fn(|a, b| s.p[(a, idx[b])]);
        // A = P[:, idx]·L⁻ᵀ, i.e. L·Aᵀ = P[idx, :].
        let Some(at) = l.solve_lower_triangular(&pcols.transpose()) else {
            return REFUSED;
        };
        let pxz = at.transpose() * sp.s1.transpose();
        let mut k = pxz * cs.inverse();
        s.consider(&mut k);
        let xn = s.x + k * y;
        // The general form: the gain may be the optimal one with K_D's row
        // cut (a consider K_D), for which P − K·Pzz·Kᵀ would be wrong.
        let kpxz = k * pxz.transpose();
        let pn = s.p - kpxz - kpxz.transpose() + k * pzz * k.transpose();
        if !commit(s, xn, pn) {
            return REFUSED;
        }
        s.counts_ll = Some(ll);
        s.counts_nis = Some(nis);
        true
    }

    /// One linearization of the counts at `xi` rolled by `roll`: Jacobian,
    /// innovation and noise of the channels that enter, and ∂count/∂φ of
    /// those channels (0 for the others).
    fn counts_linearized(&self, xi: &Vs, roll: f64, inp: &CountsInput) -> (Hm, Zv, Zv, usize, Zv) {
        let m = &self.model;
        let fs = m.full_scale();
        let q = PoseVec::from_fn(|i, _| xi[i]);
        let k_d = k_d_of(xi);
        let (pred, irr, jac, mut jr) = predict_with_grad_rolled(m, &q, roll, k_d, inp.gt);
        let mut h = Hm::zeros();
        let mut y = Zv::zeros();
        let mut r = Zv::from_element(1.0);
        let mut n_used = 0usize;
        for k in 0..NDET {
            let obs = inp.frame.counts[k] as f64;
            let Some(z) = inp.kinds[k].target(obs, pred[k], fs) else {
                jr[k] = 0.0;
                continue;
            };
            for j in 0..5 {
                h[(k, j)] = jac[(k, j)];
            }
            h[(k, KD)] = jac[(k, 5)] * k_d;
            y[k] = z - pred[k];
            r[k] = m.count_variance(irr[k] * m.gain[k] * inp.gt);
            n_used += 1;
        }
        (h, y, r, n_used, jr)
    }

    /// Iterated EKF update with the frame's counts (one iteration by
    /// default: a plain EKF).
    fn update_ekf(&self, s: &mut State, inp: &CountsInput) -> bool {
        let xbar = s.x;
        let pbar = s.p;
        let mut xi = xbar;
        let mut ll = 0.0;
        let mut nis = 0.0;
        let mut last: Option<(Hm, SMatrix<f64, NDET, NDET>, SMatrix<f64, NS, NDET>)> = None;
        for it in 0..self.cfg.update_iterations {
            let (h, y, rd, n_used, jr) = self.counts_linearized(&xi, s.roll_rad(), inp);
            let mut r = SMatrix::<f64, NDET, NDET>::from_diagonal(&rd);
            // Roll's doubt as the counts' own (a consider parameter: the
            // channels it moves together are doubted together).
            if let Some((_, sd)) = s.roll.filter(|(_, sd)| *sd > 0.0) {
                r += jr * jr.transpose() * (sd * sd);
            }
            // IEKF: innovation about the linearization point.
            let innov = y - h * (xbar - xi);
            let sm = h * pbar * h.transpose() + r;
            let Some(ch) = sm.cholesky() else {
                return REFUSED;
            };
            if it == 0 {
                let chi2 = innov.dot(&ch.solve(&innov));
                nis = chi2 / (n_used.max(1) as f64);
                if !(nis <= self.cfg.nis_gate) {
                    return REFUSED;
                }
                ll = log_likelihood(chi2, &ch.l());
            }
            let mut k = pbar * h.transpose() * ch.inverse();
            s.consider(&mut k);
            let xn = xbar + k * innov;
            if !xn.iter().all(|v| v.is_finite()) {
                return REFUSED;
            }
            let step = (xn - xi).norm();
            xi = xn;
            last = Some((h, r, k));
            if step < 1e-7 {
                break;
            }
        }
        let Some((h, r, k)) = last else {
            return REFUSED;
        };
        // Joseph form keeps P symmetric and positive through round-off.
        let ikh = Ms::identity() - k * h;
        let p = ikh * pbar * ikh.transpose() + k * r * k.transpose();
        if !commit(s, xi, p) {
            return REFUSED;
        }
        s.counts_ll = Some(ll);
        s.counts_nis = Some(nis);
        true
    }
}

/// ln of the counts' Gaussian density at the innovation, less the constant:
/// −(χ² + ln det S)/2 with S = L·Lᵀ. Channels that did not enter carry a
/// unit variance and a zero innovation: nothing.
fn log_likelihood(chi2: f64, l: &SMatrix<f64, NDET, NDET>) -> f64 {
    let log_det: f64 = (0..NDET).map(|k| 2.0 * l[(k, k)].ln()).sum();
    -0.5 * (chi2 + log_det)
}

/// Take `x`, `p` as the new state if every number is finite and no variance
/// that was positive has gone non-positive; K_D is kept at least
/// `MIN_K_D` (its state is ln K_D, so it is positive by construction).
pub(super) fn commit(s: &mut State, x: Vs, p: Ms) -> bool {
    if !(x.iter().all(|v| v.is_finite()) && p.iter().all(|v| v.is_finite())) {
        return false;
    }
    if (0..NS).any(|i| !(p[(i, i)] > 0.0) && s.p[(i, i)] > 0.0) {
        return false;
    }
    s.x = x;
    s.x[KD] = s.x[KD].max(super::state::ln_k_d(0.0));
    s.p = (p + p.transpose()) * 0.5;
    true
}
