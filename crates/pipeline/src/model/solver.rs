//! Censored, weighted Levenberg–Marquardt fit of one frame's 25 counts to
//! the light equation.
//!
//! Why censored: a channel at full scale only says "at least this bright",
//! one at zero only "at most this dark". Fitting them as data would drag the
//! pose towards a dimmer (or brighter) image than the truth, so such pixels
//! add a penalty only when the model crosses the bound they prove. A channel
//! at or below its own dark offset is handled the same way (one-sided): it
//! proves there is no more light than that, and never pulls the model below
//! the offset, which the light equation cannot go anyway.
//!
//! Everything is fixed-size (5 × 5 normal equations on the stack) so that a
//! frame costs no allocation.

// `!(a < b)` is deliberate: it is true for NaN, which must fail a check.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
// Channel loops index several parallel per-detector arrays at once.
#![allow(clippy::needless_range_loop)]

use lightpose_core::{COLS, NDET, ROWS};
use nalgebra::{SMatrix, SVector};

use super::light::{predict_rolled, predict_with_grad_rolled, PoseJacobian, PoseVec};
use super::SensorModel;

type M5 = SMatrix<f64, 5, 5>;

/// How one channel's count enters the fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Censoring {
    /// An ordinary, Gaussian measurement.
    Data,
    /// At full scale: the true value is at least `full_scale − ½`.
    Saturated,
    /// At or below the channel's dark offset (or at zero): the true value
    /// is at most what was read.
    Dark,
    /// A bound no light can give this channel beside what its neighbours
    /// read (a photodiode or ADC input stuck at full scale or at zero):
    /// left out of the frame, so that one bad channel does not cost the
    /// pose. See [`Censoring::classify`].
    Excluded,
}

impl Censoring {
    /// Classify the channels of one frame.
    ///
    /// A censored channel is checked against its neighbours on the dome
    /// (`Excluded` when the light cannot explain it). The light on the
    /// dome is a Gaussian of the angle to each detector's normal (σ_r,
    /// widened by the halo when there is one), so along a row or a column
    /// its logarithm is concave with curvature −1/σ_r²:
    /// - a channel at full scale has a 4-neighbour with at least
    ///   e^(−s²/σ_r²) of its light (s the spacing: 0.5 in the tank), the
    ///   worst case being the spot's centre half a spacing past it; one
    ///   whose every neighbour has less than half of that (a quarter of
    ///   full scale in the tank: a margin for the channels' gains and a
    ///   response flatter than a Gaussian, both of which only brighten a
    ///   neighbour) is stuck;
    /// - a channel between two lit neighbours of one row or column has at
    ///   least the lesser one's light; one that reads dark between two
    ///   clearly lit (10 σ of the dark noise and 5 % of full scale) is
    ///   stuck.
    ///
    /// `frozen` (bit k for detector k) are channels whose history says they
    /// are stuck between the bounds ([`FrozenWatch`](super::frozen::FrozenWatch)):
    /// `Excluded` too.
    pub fn classify(m: &SensorModel, counts: &[u16; NDET], frozen: u32) -> [Censoring; NDET] {
        let fs = m.full_scale();
        let cpv = m.counts_per_volt();
        let mut out = [Censoring::Data; NDET];
        // Each channel's light above its dark level, as a share of what
        // full scale leaves it.
        let mut lit = [0.0; NDET];
        for k in 0..NDET {
            let c = counts[k] as f64;
            let dark = m.offset_v[k] * cpv;
            lit[k] = (c - dark) / (fs - dark).max(1.0);
            out[k] = if c >= fs {
                Censoring::Saturated
            } else if c <= 0.0 || c <= dark {
                Censoring::Dark
            } else {
                Censoring::Data
            };
        }
        let s = m.geometry.spacing.rad();
        let sigma = m.light.sigma_r.rad();
        let dim = 0.5 * (-(s * s) / (sigma * sigma)).exp();
        let clear = (10.0 * m.count_variance(0.0).sqrt() / fs).max(0.05);
        for k in 0..NDET {
            let (r, c) = ((k / COLS) as isize, (k % COLS) as isize);
            let at = |dr: isize, dc: isize| {
                let (rr, cc) = (r + dr, c + dc);
                ((0..ROWS as isize).contains(&rr) && (0..COLS as isize).contains(&cc))
                    .then(|| lit[rr as usize * COLS + cc as usize])
            };
            let stuck = match out[k] {
                Censoring::Saturated => [(0, 1), (0, -1), (1, 0), (-1, 0)]
                    .iter()
                    .filter_map(|&(dr, dc)| at(dr, dc))
                    .all(|l| l < dim),
                Censoring::Dark => [[(0, 1), (0, -1)], [(1, 0), (-1, 0)]].iter().any(|pair| {
                    pair.iter()
                        .all(|&(dr, dc)| at(dr, dc).is_some_and(|l| l >= clear))
                }),
                _ => false,
            };
            if stuck || frozen & (1 << k) != 0 {
                out[k] = Censoring::Excluded;
            }
        }
        out
    }

    /// `frame` with each `Excluded` channel read as the light its
    /// neighbours say it has (on the stack: nothing allocated), for what
    /// reads the image whole rather than fitting it channel by channel
    /// (the paper's moments, the peak a start is sought from): a corner
    /// stuck at full scale is otherwise the image's peak, a centre stuck at
    /// zero a hole in the spot. Between two neighbours of a row or a column
    /// the Gaussian gives √(S_a·S_b)·e^(s²/2σ_r²) of light above dark (the
    /// geometric mean of both pairs when both exist); a channel without
    /// such a pair takes the mean of its neighbours. Fits leave it out.
    pub fn stand_in(
        m: &SensorModel,
        kinds: &[Censoring; NDET],
        frame: &lightpose_core::Frame,
    ) -> lightpose_core::Frame {
        let mut f = *frame;
        let cpv = m.counts_per_volt();
        let (s, sigma) = (m.geometry.spacing.rad(), m.light.sigma_r.rad());
        let curve = (0.5 * s * s / (sigma * sigma)).exp();
        let light = |j: usize| (frame.counts[j] as f64 - m.offset_v[j] * cpv).max(0.0);
        for k in 0..NDET {
            if kinds[k] != Censoring::Excluded {
                continue;
            }
            let (r, c) = ((k / COLS) as isize, (k % COLS) as isize);
            let at = |dr: isize, dc: isize| {
                let (rr, cc) = (r + dr, c + dc);
                let j = rr * COLS as isize + cc;
                ((0..ROWS as isize).contains(&rr) && (0..COLS as isize).contains(&cc))
                    .then_some(j as usize)
                    .filter(|&j| kinds[j] != Censoring::Excluded)
            };
            let (mut ln_sum, mut pairs) = (0.0, 0.0);
            for [(a, b), (c2, d)] in [[(0, 1), (0, -1)], [(1, 0), (-1, 0)]] {
                if let (Some(i), Some(j)) = (at(a, b), at(c2, d)) {
                    if light(i) > 0.0 && light(j) > 0.0 {
                        ln_sum += 0.5 * (light(i).ln() + light(j).ln()) + curve.ln();
                        pairs += 1.0;
                    }
                }
            }
            let est = if pairs > 0.0 {
                (ln_sum / pairs).exp()
            } else {
                let (mut sum, mut n) = (0.0, 0.0);
                for (dr, dc) in [(0, 1), (0, -1), (1, 0), (-1, 0)] {
                    if let Some(j) = at(dr, dc) {
                        sum += light(j);
                        n += 1.0;
                    }
                }
                if n > 0.0 {
                    sum / n
                } else {
                    0.0
                }
            };
            let fs = m.full_scale();
            f.counts[k] = (m.offset_v[k] * cpv + est).round().clamp(0.0, fs) as u16;
        }
        f
    }

    /// The channels a frame's classification left out, as a bit mask
    /// (bit k for detector k).
    pub fn excluded_mask(kinds: &[Censoring; NDET]) -> u32 {
        kinds
            .iter()
            .enumerate()
            .filter(|(_, k)| **k == Censoring::Excluded)
            .fold(0, |m, (i, _)| m | 1 << i)
    }

    /// The value a filter should pull the prediction `pred` toward for a
    /// channel that read `obs` (full scale `fs`): the reading for data;
    /// for a censored channel the bound it proves, only when the
    /// prediction is on the wrong side of it (else the channel says
    /// nothing).
    #[inline]
    pub fn target(self, obs: f64, pred: f64, fs: f64) -> Option<f64> {
        match self {
            Censoring::Data => Some(obs),
            Censoring::Saturated => (pred < fs - 0.5).then_some(fs - 0.5),
            Censoring::Dark => (pred > obs.max(0.5)).then_some(obs.max(0.5)),
            Censoring::Excluded => None,
        }
    }
}

/// A Gaussian prior on some pose coordinates (pitch and yaw from an
/// attitude sensor, typically). `inv_sigma[i] = 0` means none on i.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Prior {
    pub mean: PoseVec,
    pub inv_sigma: PoseVec,
}

impl Prior {
    pub fn none() -> Self {
        Prior {
            mean: PoseVec::zeros(),
            inv_sigma: PoseVec::zeros(),
        }
    }
}

/// Knobs of one solve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolveOptions {
    /// Which of x, y, z, θ, ψ are estimated; the others stay at the start.
    pub free: [bool; 5],
    pub max_iter: usize,
    /// Range of x the solver may visit (metres); steps outside are refused.
    pub x_min: f64,
    pub x_max: f64,
    /// |y|, |z| may not exceed this times x (the beam is long gone beyond).
    pub max_lateral_ratio: f64,
    /// |θ|, |ψ| may not exceed this (radians).
    pub max_angle: f64,
    /// K_D used for the light equation.
    pub k_d: f64,
    /// Temperature gain g_T of this frame.
    pub gt: f64,
    /// Channels frozen by their history (bit k for detector k), left out
    /// as stuck ones are (see [`Censoring::classify`]).
    pub frozen: u32,
    /// Spec v3: the roll (rad) the fit holds the vehicle at, and its
    /// variance (rad²): roll is a *consider* parameter, not fitted (one
    /// beacon barely sees it), whose doubt [`solve`] carries into the
    /// covariance. 0 and 0 are spec v1/v2's fit exactly.
    pub roll: f64,
    pub roll_var: f64,
}

/// Outcome of one solve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LmResult {
    pub q: PoseVec,
    /// Covariance of the free coordinates from (JᵀWJ + prior)⁻¹ at the
    /// optimum, plus what the roll's doubt does to them (`roll_var`);
    /// zero rows and columns for fixed ones.
    pub cov: M5,
    /// Σ of squared normalized residuals (data and active penalties).
    pub chi2: f64,
    /// Total cost, chi2 plus prior.
    pub cost: f64,
    /// Channels that entered as data (uncensored).
    pub n_data: usize,
    pub n_saturated: usize,
    pub iterations: usize,
    pub converged: bool,
}

fn residuals(
    counts: &[u16; NDET],
    kinds: &[Censoring; NDET],
    pred: &SVector<f64, NDET>,
    w: &[f64; NDET],
    fs: f64,
    out: &mut [f64; NDET],
) -> f64 {
    let mut chi2 = 0.0;
    for k in 0..NDET {
        let obs = counts[k] as f64;
        let r = match kinds[k] {
            Censoring::Data => pred[k] - obs,
            Censoring::Saturated => (pred[k] - (fs - 0.5)).min(0.0),
            Censoring::Dark => (pred[k] - obs.max(0.5)).max(0.0),
            Censoring::Excluded => 0.0,
        } * w[k];
        out[k] = r;
        chi2 += r * r;
    }
    chi2
}

fn prior_cost(q: &PoseVec, p: &Prior) -> f64 {
    let d = (q - p.mean).component_mul(&p.inv_sigma);
    d.norm_squared()
}

fn admissible(q: &PoseVec, o: &SolveOptions) -> bool {
    q.iter().all(|v| v.is_finite())
        && q[0] >= o.x_min
        && q[0] <= o.x_max
        && q[1].abs() <= o.max_lateral_ratio * q[0]
        && q[2].abs() <= o.max_lateral_ratio * q[0]
        && q[3].abs() <= o.max_angle
        && q[4].abs() <= o.max_angle
}

/// The counts' weights 1/σ_k from the noise model at irradiance `irr`.
#[inline]
fn noise_weights(m: &SensorModel, irr: &[f64; NDET], gt: f64, w: &mut [f64; NDET]) {
    for k in 0..NDET {
        w[k] = 1.0 / m.count_variance(irr[k] * m.gain[k] * gt).sqrt();
    }
}

/// JᵀWJ and JᵀWr over the active rows; a censored row whose bound is not
/// crossed has a zero residual and contributes no curvature either.
#[inline]
fn normal_equations(
    jac: &PoseJacobian,
    kinds: &[Censoring; NDET],
    w: &[f64; NDET],
    r: &[f64; NDET],
) -> (M5, SVector<f64, 5>) {
    let mut h = M5::zeros();
    let mut g = SVector::<f64, 5>::zeros();
    for k in 0..NDET {
        let active = kinds[k] == Censoring::Data || r[k] != 0.0;
        if !active {
            continue;
        }
        let row = jac.fixed_view::<1, 5>(k, 0).transpose() * w[k];
        h += row * row.transpose();
        g += row * r[k];
    }
    (h, g)
}

/// Turn the rows and columns of the coordinates that are not `free` into
/// those of the identity, so that they neither move nor couple.
#[inline]
fn pin_fixed(a: &mut M5, free: &[bool; 5]) {
    for i in 0..5 {
        if !free[i] {
            for j in 0..5 {
                a[(i, j)] = 0.0;
                a[(j, i)] = 0.0;
            }
            a[(i, i)] = 1.0;
        }
    }
}

/// One frame's fit: what stays the same while the pose moves.
struct Problem<'a> {
    m: &'a SensorModel,
    counts: &'a [u16; NDET],
    kinds: [Censoring; NDET],
    fs: f64,
    prior: &'a Prior,
    o: &'a SolveOptions,
}

/// The fit linearized at one pose: χ² of the counts, and the normal
/// equations (information h and gradient g) with the prior in.
struct Linearized {
    chi2: f64,
    h: M5,
    g: SVector<f64, 5>,
}

impl Problem<'_> {
    /// Reweight from the noise model at `q` (into `w`), take the residuals
    /// there (into `r`) and the normal equations.
    #[inline]
    fn linearize(&self, q: &PoseVec, w: &mut [f64; NDET], r: &mut [f64; NDET]) -> Linearized {
        let o = self.o;
        let (pred, irr, jac, _) = predict_with_grad_rolled(self.m, q, o.roll, o.k_d, o.gt);
        noise_weights(self.m, &irr, o.gt, w);
        let chi2 = residuals(self.counts, &self.kinds, &pred, w, self.fs, r);
        let (mut h, mut g) = normal_equations(&jac, &self.kinds, w, r);
        let prior = self.prior;
        for i in 0..5 {
            let s2 = prior.inv_sigma[i] * prior.inv_sigma[i];
            h[(i, i)] += s2;
            g[i] += s2 * (q[i] - prior.mean[i]);
        }
        Linearized { chi2, h, g }
    }

    /// Cost (χ² plus prior) at `q` with the weights `w` held.
    #[inline]
    fn cost_at(&self, q: &PoseVec, w: &[f64; NDET], r: &mut [f64; NDET]) -> f64 {
        let (pred, _) = predict_rolled(self.m, q, self.o.roll, self.o.k_d, self.o.gt);
        residuals(self.counts, &self.kinds, &pred, w, self.fs, r) + prior_cost(q, self.prior)
    }

    /// Levenberg–Marquardt from `q` (cost `cost`): raise the damping until
    /// an admissible step lowers the cost (at most 12 tries), take it and
    /// relax the damping. Returns whether a step was taken and whether the
    /// last step tried was negligible (converged).
    #[inline]
    fn damped_step(
        &self,
        lin: &Linearized,
        cost: f64,
        q: &mut PoseVec,
        lambda: &mut f64,
        w: &[f64; NDET],
        rt: &mut [f64; NDET],
    ) -> (bool, bool) {
        let h = &lin.h;
        let mut step_small = false;
        for _ in 0..12 {
            let mut a = *h;
            for i in 0..5 {
                a[(i, i)] += *lambda * h[(i, i)] + 1e-12;
            }
            let Some(ch) = a.cholesky() else {
                *lambda *= 10.0;
                continue;
            };
            let delta = -ch.solve(&lin.g);
            let qn = *q + delta;
            // A step that is tiny against the current uncertainty ends it.
            step_small = (0..5).all(|i| (delta[i] * delta[i] * h[(i, i)]) < 1e-8);
            if !admissible(&qn, self.o) {
                *lambda *= 4.0;
                continue;
            }
            let cn = self.cost_at(&qn, w, rt);
            if cn.is_finite() && cn <= cost {
                let rel = (cost - cn) / cost.max(1e-300);
                *q = qn;
                *lambda = (*lambda / 3.0).max(1e-9);
                if rel < 1e-12 {
                    step_small = true;
                }
                return (true, step_small);
            }
            *lambda *= 4.0;
        }
        (false, step_small)
    }
}

/// Minimize the censored, weighted squared residuals plus the prior,
/// starting from `q0`. Weights come from the noise model at the current
/// iterate (iteratively reweighted), so κ > 0 is handled too.
pub fn solve(
    m: &SensorModel,
    counts: &[u16; NDET],
    q0: &PoseVec,
    prior: &Prior,
    o: &SolveOptions,
) -> LmResult {
    let kinds = Censoring::classify(m, counts, o.frozen);
    let n_saturated = kinds.iter().filter(|k| **k == Censoring::Saturated).count();
    let n_data = kinds.iter().filter(|k| **k == Censoring::Data).count();
    let p = Problem {
        m,
        counts,
        kinds,
        fs: m.full_scale(),
        prior,
        o,
    };
    let mut q = *q0;
    let mut lambda = 1e-3;
    let mut w = [0.0; NDET];
    let mut r = [0.0; NDET];
    let mut rt = [0.0; NDET];
    let mut converged = false;
    let mut iterations = 0;
    let mut h = M5::zeros();
    let mut chi2 = f64::INFINITY;
    let mut cost = f64::INFINITY;
    for it in 0..o.max_iter {
        iterations = it + 1;
        let mut lin = p.linearize(&q, &mut w, &mut r);
        chi2 = lin.chi2;
        cost = chi2 + prior_cost(&q, prior);
        pin_fixed(&mut lin.h, &o.free);
        for i in 0..5 {
            if !o.free[i] {
                lin.g[i] = 0.0;
            }
        }
        h = lin.h;
        let (accepted, step_small) = p.damped_step(&lin, cost, &mut q, &mut lambda, &w, &mut rt);
        if step_small || !accepted {
            // Either converged, or no admissible downhill step exists here:
            // a local minimum at the current damping.
            converged = step_small || lambda < 1e3;
            break;
        }
    }
    // Covariance at the final point (recompute curvature there).
    let end = p.linearize(&q, &mut w, &mut r);
    if end.chi2.is_finite() {
        chi2 = end.chi2;
        cost = chi2 + prior_cost(&q, prior);
        h = end.h;
    }
    let mut cov = covariance(&h, &o.free);
    if o.roll_var > 0.0 {
        consider_roll(&p, &q, &w, &mut cov);
    }
    LmResult {
        q,
        cov,
        chi2,
        cost,
        n_data,
        n_saturated,
        iterations,
        converged,
    }
}

/// Add the roll's doubt to `cov` (Schmidt's consider covariance of a least
/// squares): the fit at a roll δφ off moves by s·δφ, s = −C·JᵀW²·∂r/∂φ
/// with C the fit's covariance, so C gains s·sᵀ·σ_φ². Only the channels
/// that entered the fit's normal equations count, as there.
fn consider_roll(p: &Problem, q: &PoseVec, w: &[f64; NDET], cov: &mut M5) {
    let o = p.o;
    let (pred, _, jac, jr) = predict_with_grad_rolled(p.m, q, o.roll, o.k_d, o.gt);
    let mut r = [0.0; NDET];
    residuals(p.counts, &p.kinds, &pred, w, p.fs, &mut r);
    let mut g = SVector::<f64, 5>::zeros();
    for k in 0..NDET {
        if !(p.kinds[k] == Censoring::Data || r[k] != 0.0) {
            continue;
        }
        let row = jac.fixed_view::<1, 5>(k, 0).transpose() * (w[k] * w[k]);
        g += row * jr[k];
    }
    let sens = -(*cov * g);
    if sens.iter().all(|v| v.is_finite()) {
        *cov += sens * sens.transpose() * o.roll_var;
    }
}

/// Inverse of the information matrix restricted to the free coordinates;
/// infinite variance where the information is singular.
fn covariance(h: &M5, free: &[bool; 5]) -> M5 {
    let mut a = *h;
    pin_fixed(&mut a, free);
    let mut cov = match a.try_inverse() {
        Some(c) if c.iter().all(|v| v.is_finite()) => c,
        _ => {
            let mut c = M5::zeros();
            for i in 0..5 {
                c[(i, i)] = f64::INFINITY;
            }
            c
        }
    };
    for i in 0..5 {
        if !free[i] {
            for j in 0..5 {
                cov[(i, j)] = 0.0;
                cov[(j, i)] = 0.0;
            }
        }
    }
    cov
}
