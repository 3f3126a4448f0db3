//! How the tracker starts (and restarts): a single-frame fit of the counts
//! with the frame's own-sensor readings as priors, and the velocity from
//! the DVL when there is one.
//!
//! Why its own fit rather than the `"model"` estimator's: a depth reading
//! must be a prior on z *inside* the nonlinear fit. One frame barely
//! separates z from pitch (MODEL.md), so a fit without it can land far
//! along that ridge (1.7 m off in z on the README's dive), and a depth
//! applied afterwards, through that fit's linearized covariance, would be
//! refused as an outlier or pulled only part of the way.
//!
//! Without an attitude reading one frame cannot tell a far vehicle on the
//! beam axis from a near one off it (brightness trades range against the
//! off-axis angle: on the README's dive, x 8.5 m on the axis and x 4.4 m
//! 22° off it fit the first frame equally well). The start then takes the
//! paper's range as a prior on x (as every such frame takes it as a
//! measurement, see `readings::paper_range`) and holds the vehicle within
//! `init_lateral_sigma_deg` of the axis; and, without depth either, the fit
//! tries both readings of the spot's offset from the array's centre — as
//! position (attitude 0) and as attitude (on the beam axis) — and keeps the
//! one that explains the frame better, because the solver, started on one
//! side of the ridge, stays there.

// `!(a < b)` is deliberate: it is true for NaN, which must fail a check.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use lightpose_core::{Frame, ReadingUse, Status};

use super::offsets::Offset;
use super::readings::{Checked, FrameReadings};
use super::state::{body_axes, roll_axes, Ms, State, Vs, KD, VEL};
use super::Tracker;
use crate::model::light::PoseVec;
use crate::model::measurement::Measurement;
use crate::model::single_frame::coarse_start;
use crate::model::solver::{solve, LmResult, Prior, SolveOptions};
use crate::settings::Motion;

impl Tracker {
    /// The solver's limits, as the `"model"` estimator sets them (its
    /// model is the tracker's).
    fn start_options(&self, gt: f64, roll: Option<(f64, f64)>) -> SolveOptions {
        let mut o = self.init.solve_options([true; 5], gt);
        if let Some((r, sd)) = roll {
            o.roll = r;
            o.roll_var = sd * sd;
        }
        o
    }

    /// The start fit's prior: the attitude reading (else the start-up
    /// envelope) on pitch and yaw, the depth reading on z.
    fn start_prior(&self, r: &FrameReadings, x0: f64, paper_x: Option<&Checked<1>>) -> Prior {
        let mut p = Prior::none();
        if let Some(c) = paper_x {
            p.mean[0] = c.z[0];
            p.inv_sigma[0] = 1.0 / c.sigma[0];
        }
        match r.attitude.ready() {
            Some(a) => {
                // The pitch less its offset's mean, with its variance.
                let (offset, var) = self.offsets.prior(Offset::Pitch);
                p.mean[3] = a.z[0] - offset;
                p.inv_sigma[3] = 1.0 / (a.sigma[0] * a.sigma[0] + var).sqrt();
                p.mean[4] = a.z[1];
                p.inv_sigma[4] = 1.0 / a.sigma[1];
            }
            None => {
                let s = self.cfg.init_attitude_sigma_deg.to_radians();
                p.inv_sigma[3] = 1.0 / s;
                p.inv_sigma[4] = 1.0 / s;
            }
        }
        if let (Some(s), None) = (self.cfg.init_lateral_sigma_deg, r.attitude.ready()) {
            let lat = 1.0 / (x0.max(0.5) * s.to_radians().tan());
            p.inv_sigma[1] = lat;
            p.inv_sigma[2] = lat;
        }
        if let Some(d) = r.depth.ready() {
            let (offset, var) = self.offsets.prior(Offset::Depth);
            p.mean[2] = self.dome_z_of_depth(d.z[0] - offset, p.mean[3]);
            p.inv_sigma[2] = 1.0 / (d.sigma[0] * d.sigma[0] + var).sqrt();
        }
        p
    }

    /// The dome centre's z for a depth sensor reading `zd` at pitch `theta`
    /// (the lever arm, see the readings' depth model).
    /// Whether the depth reading `d` is grossly at odds with a state the
    /// light started alone: more than 5σ from its z, σ the state's and the
    /// reading's (with its offset's) together. What the light alone can
    /// say of a wrong depth; a depth merely unlike a first fit is not
    /// that.
    pub(super) fn depth_at_odds(&self, s: &State, d: &Checked<1>) -> bool {
        let (offset, var) = self.offsets.prior(Offset::Depth);
        let want = self.dome_z_of_depth(d.z[0] - offset, s.x[3]);
        let sd2 = s.p[(2, 2)] + d.sigma[0] * d.sigma[0] + var;
        (s.x[2] - want).powi(2) > 25.0 * sd2
    }

    pub(super) fn dome_z_of_depth(&self, zd: f64, theta: f64) -> f64 {
        let [lf, _, ld] = self.cfg.depth_lever_arm_m;
        let (st, ct) = theta.sin_cos();
        zd - (lf * st - ld * ct)
    }

    /// Solve from `q0`: position first with the attitude held (the ridges
    /// are easier to walk from there), then all five.
    fn solve_from(
        &self,
        meas: &Measurement,
        q0: &PoseVec,
        prior: &Prior,
        o: &SolveOptions,
    ) -> LmResult {
        let m = &self.model;
        let mut pos_only = *o;
        pos_only.free = [true, true, true, false, false];
        let r1 = solve(m, meas, q0, prior, &pos_only);
        solve(m, meas, &r1.q, prior, o)
    }

    /// The best fit of `frame` under `prior`, from each start candidate.
    fn start_fit(
        &self,
        frame: &Frame,
        r: &FrameReadings,
        paper_x: Option<&Checked<1>>,
        gt: f64,
        roll: Option<(f64, f64)>,
    ) -> Option<LmResult> {
        let mut o = self.start_options(gt, roll);
        o.ambient = self.init.ambient_for(frame);
        let pitch_offset = self.offsets.prior(Offset::Pitch).0;
        let att = r.attitude.ready().map(|a| (a.z[0] - pitch_offset, a.z[1]));
        let meas = &Measurement::of(&self.model, frame, o.frozen);
        let mut q0 = coarse_start(&self.model, meas, gt, att, &o)?;
        let mut prior = self.start_prior(r, q0.fixed_rows::<3>(0).norm(), paper_x);
        let depth = r.depth.ready().is_some();
        if depth {
            let lat = o.max_lateral_ratio * q0[0] * 0.99;
            q0[2] = prior.mean[2].clamp(-lat, lat);
        }
        let mut best = self.solve_from(meas, &q0, &prior, &o);
        if att.is_none() && !depth && self.cfg.start_both_ways {
            // The same spot read as attitude: on the beam axis, facing
            // away from the beacon's direction by the offset.
            let range = q0.fixed_rows::<3>(0).norm();
            let on_axis = PoseVec::new(range, 0.0, 0.0, q0[2].atan2(q0[0]), q0[1].atan2(q0[0]));
            let other = self.solve_from(meas, &on_axis, &prior, &o);
            if other.converged && (!best.converged || other.cost < best.cost) {
                best = other;
            }
        }
        let [lf, _, ld] = self.cfg.depth_lever_arm_m;
        if depth && (lf != 0.0 || ld != 0.0) {
            // The lever arm's share of the depth at the fitted pitch.
            if let Some(d) = r.depth.ready() {
                let offset = self.offsets.prior(Offset::Depth).0;
                prior.mean[2] = self.dome_z_of_depth(d.z[0] - offset, best.q[3]);
                best = solve(&self.model, meas, &best.q, &prior, &o);
            }
        }
        Some(best)
    }

    /// A status for the start fit, as the `"model"` estimator would say
    /// it: `Ok`-like (Ok, Saturated, OutOfRange) lets the filter start.
    fn start_status(&self, frame: &Frame, f: &LmResult) -> Status {
        let c = self.init.config();
        let clipped = Measurement::n_clipped(&self.model, frame);
        let dof = 5usize;
        let red = f.chi2 / (f.n_data.saturating_sub(dof).max(1)) as f64;
        if !f.converged || !f.q.iter().all(|v| v.is_finite()) || !(red <= c.max_reduced_chi2) {
            return super::unusable(clipped, c.max_saturated);
        }
        if !(0..5).all(|i| f.cov[(i, i)].is_finite()) {
            return Status::Diverged;
        }
        Status::Ok
    }

    /// Start from `frame`: the filter's state and what became of the
    /// frame's readings, or why no start was possible. A station's frame
    /// starts from its 6-DOF fit (`station`).
    pub(super) fn start(
        &self,
        frame: &Frame,
        r: &FrameReadings,
        paper_x: Option<&Checked<1>>,
    ) -> Result<(State, [ReadingUse; 3]), Status> {
        if let Some(amps) = self.station_amps(frame) {
            return self.start_station(frame, r, amps);
        }
        if !self.init.has_light(frame) {
            return Err(Status::NoLight);
        }
        let gt = super::gain_of(frame);
        let roll = self.roll_of(frame, r);
        let Some(fit) = self.start_fit(frame, r, paper_x, gt, roll) else {
            return Err(Status::NoLight);
        };
        let status = self.start_status(frame, &fit);
        if status != Status::Ok {
            return Err(status);
        }
        let mut x = Vs::zeros();
        let mut p_fit = Ms::zeros();
        for i in 0..5 {
            x[i] = fit.q[i];
            for j in 0..5 {
                p_fit[(i, j)] = fit.cov[(i, j)];
            }
        }
        let red = fit.chi2 / (fit.n_data.saturating_sub(5).max(1)) as f64;
        let s = self.started_state(frame, r, x, p_fit, red, roll, paper_x)?;
        Ok((s, uses_of(r)))
    }

    /// The state a start fit gives: its pose `x` and covariance `p_fit`
    /// (widened by a reduced χ² `red` above 1), the velocity, rates, K_D
    /// and offsets' start doubts around it.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn started_state(
        &self,
        frame: &Frame,
        r: &FrameReadings,
        mut x: Vs,
        p_fit: Ms,
        red: f64,
        roll: Option<(f64, f64)>,
        paper_x: Option<&Checked<1>>,
    ) -> Result<State, Status> {
        // A model that fits worse than its noise says: widen, don't lie.
        let mut p = if red > 1.0 { p_fit * red } else { p_fit };
        let roll_now = roll.map_or(x[super::state::ROLL], |(r, _)| r);
        self.start_velocity(&mut x, &mut p, r, roll_now);
        let c = &self.cfg;
        for i in 8..10 {
            p[(i, i)] = c.init_rate_sigma_deg.to_radians().powi(2);
        }
        x[KD] = super::state::ln_k_d(self.model.light.k_d);
        self.start_offsets(&mut x, &mut p, &p_fit, r);
        let mut s = State::new(x, p, frame.t);
        s.roll = roll;
        s.offset_free = Offset::ALL.map(|o| self.offsets.told(o, &self.cfg));
        s.paper_x = paper_x.and(self.paper_bias());
        s.doubt_k_d(self.k_d_sigma);
        let with_velocity = c.estimate_k_d_with_velocity && r.velocity.ready().is_some();
        // A station's beacons stand apart at surveyed places: the images'
        // geometry gives the range whatever the water, and the brightness
        // then tells K_D, which one beacon's cannot (range and K_D trade
        // along its ridge). So a K_D doubt wider than the calibration's is
        // learnt, not only carried: held as a consider doubt, a Monte
        // Carlo in water drawn ±0.015 about the calibration's had x p95
        // 0.070 m with attitude and depth (issue 41's goal 0.05) and y,
        // pitch, yaw ±2σ 99–100 % light alone; learnt, 0.037 m and
        // 97–98 % (docs/docking.md). In the calibration's own water it is
        // held, as for one beacon: learning it there cost x 0.017 → 0.022
        // m and put its ±2σ over 98 %.
        let station_learns = !self.station.is_empty() && self.k_d_told_wider;
        s.k_d_free = c.estimate_k_d || (with_velocity && self.k_d_sigma > 0.0) || station_learns;
        if !s.is_finite() {
            return Err(Status::Diverged);
        }
        s.attitude_fused = r.attitude.ready().is_some();
        Ok(s)
    }

    /// The start's velocity: the DVL's reading when there is one, else
    /// the start-up doubt around rest.
    fn start_velocity(&self, x: &mut Vs, p: &mut Ms, r: &FrameReadings, roll: f64) {
        let c = &self.cfg;
        match (r.velocity.ready(), c.motion) {
            (Some(v), Motion::Body) => {
                for a in 0..3 {
                    x[VEL + a] = v.z[a];
                    p[(VEL + a, VEL + a)] = v.sigma[a] * v.sigma[a];
                }
            }
            (Some(v), Motion::World) => {
                // v_B = R_BV·v_V; the attitude's doubt turns the vector.
                let mut axes = body_axes(x[3], x[4]);
                if roll != 0.0 {
                    axes = roll_axes(&axes, roll);
                }
                let turn = v.z.norm_squared() * (p[(3, 3)] + p[(4, 4)]);
                for i in 0..3 {
                    x[VEL + i] = (0..3).map(|a| axes[a][i] * v.z[a]).sum();
                    for j in 0..3 {
                        p[(VEL + i, VEL + j)] = (0..3)
                            .map(|a| axes[a][i] * axes[a][j] * v.sigma[a] * v.sigma[a])
                            .sum();
                    }
                    p[(VEL + i, VEL + i)] += turn;
                }
            }
            (None, Motion::World) => {
                for i in VEL..VEL + 3 {
                    p[(i, i)] = c.init_velocity_sigma.powi(2);
                }
            }
            (None, Motion::Body) => {
                p[(VEL, VEL)] = c.init_velocity_sigma.powi(2);
                p[(VEL + 1, VEL + 1)] = c.side_sigma.powi(2);
                p[(VEL + 2, VEL + 2)] = c.side_sigma.powi(2);
            }
        }
    }
}

/// What became of a start's readings: each ready one fused (as the start
/// fit's prior).
pub(super) fn uses_of(r: &FrameReadings) -> [ReadingUse; 3] {
    [
        r.attitude.if_fused(),
        r.depth.if_fused(),
        r.velocity.if_fused(),
    ]
}
