//! How the tracker moves its state from one frame to the next: the body
//! model (surge along the bow plus a small sideslip, the default) or the
//! world model (constant velocity in B).

use super::offsets::Offset;
use super::state::{Ms, State, KD, ROLL, VEL};
use super::Tracker;
use crate::settings::Motion;

/// Add the discrete noise of a white acceleration (density `qq`) over `dt`
/// to coordinate `i` and its rate `i + 5`.
fn add_white_accel(q: &mut Ms, i: usize, qq: f64, dt: f64) {
    q[(i, i)] += qq * dt.powi(3) / 3.0;
    q[(i, i + 5)] += qq * dt.powi(2) / 2.0;
    q[(i + 5, i)] += qq * dt.powi(2) / 2.0;
    q[(i + 5, i + 5)] += qq * dt;
}

impl Tracker {
    pub(super) fn predict(&self, s: &mut State, dt: f64) {
        match self.cfg.motion {
            Motion::World => self.predict_world(s, dt),
            Motion::Body => self.predict_body(s, dt),
        }
        if s.k_d_free {
            // The walk's density is in K_D, the state in ln K_D.
            let k = super::state::k_d_of(&s.x);
            s.p[(KD, KD)] += self.cfg.k_d_walk_psd * dt / (k * k).max(1e-18);
        }
        if s.roll_free {
            // A station's roll: a random walk (no rate of its own).
            let q = self.cfg.roll_walk_psd_deg * (std::f64::consts::PI / 180.0).powi(2);
            s.p[(ROLL, ROLL)] += q * dt;
        }
        for o in Offset::ALL {
            if self.offsets.told(o, &self.cfg) {
                let i = o.index();
                s.p[(i, i)] += o.walk(&self.cfg) * dt;
            }
        }
        s.p = (s.p + s.p.transpose()) * 0.5;
    }

    /// `ang_accel_psd_deg` is a density in (°/s²)²/Hz; the state is in rad.
    fn ang_accel_psd_rad(&self) -> f64 {
        self.cfg.ang_accel_psd_deg * (std::f64::consts::PI / 180.0).powi(2)
    }

    /// Constant velocity in B, white acceleration on every axis.
    fn predict_world(&self, s: &mut State, dt: f64) {
        let mut f = Ms::identity();
        for i in 0..5 {
            f[(i, i + 5)] = dt;
        }
        let mut q = Ms::zeros();
        let qa = self.ang_accel_psd_rad();
        for i in 0..5 {
            let qq = if i < 3 { self.cfg.accel_psd } else { qa };
            add_white_accel(&mut q, i, qq, dt);
        }
        s.x = f * s.x;
        s.p = f * s.p * f.transpose() + q;
    }

    /// Velocity in the body frame: the vehicle moves along its bow at
    /// surge u (a random walk) with a small sideslip (v right, w down,
    /// first-order Gauss–Markov towards 0), so that ż = u·sin θ + … ties
    /// the z/pitch and y/yaw ridges of one frame to each other over time.
    /// Its memory is the vehicle's while the attitude is measured, shorter
    /// while it is not (`side_tau_with_attitude_s`).
    fn predict_body(&self, s: &mut State, dt: f64) {
        let c = &self.cfg;
        let x = s.x;
        // Roll turns the sideslip's axes about the bow (the state's roll).
        let (axes, [d_t, d_p]) = s.axes();
        let vel = [x[VEL], x[VEL + 1], x[VEL + 2]];
        let tau = if s.attitude_fused {
            c.side_tau_with_attitude_s
        } else {
            c.side_tau_s
        };
        let phi = (-dt / tau).exp();
        let mut f = Ms::identity();
        for i in 0..3 {
            for (a, axis) in axes.iter().enumerate() {
                s.x[i] += dt * vel[a] * axis[i];
                f[(i, 3)] += dt * vel[a] * d_t[a][i];
                f[(i, 4)] += dt * vel[a] * d_p[a][i];
                f[(i, VEL + a)] = dt * axis[i];
            }
        }
        s.x[3] += dt * x[8];
        s.x[4] += dt * x[9];
        s.x[VEL + 1] *= phi;
        s.x[VEL + 2] *= phi;
        f[(3, 8)] = dt;
        f[(4, 9)] = dt;
        f[(VEL + 1, VEL + 1)] = phi;
        f[(VEL + 2, VEL + 2)] = phi;
        let mut q = Ms::zeros();
        // Each body axis' velocity noise, with the position it drags along
        // (the continuous white-acceleration block, pointed along the axis).
        let q_side = 2.0 * c.side_sigma * c.side_sigma / tau;
        for (a, qq) in [c.accel_psd, q_side, q_side].into_iter().enumerate() {
            let axis = axes[a];
            let vi = VEL + a;
            for i in 0..3 {
                for j in 0..3 {
                    q[(i, j)] += qq * dt.powi(3) / 3.0 * axis[i] * axis[j];
                }
                q[(i, vi)] += qq * dt.powi(2) / 2.0 * axis[i];
                q[(vi, i)] += qq * dt.powi(2) / 2.0 * axis[i];
            }
            q[(vi, vi)] += qq * dt;
        }
        let qa = self.ang_accel_psd_rad();
        for i in 3..5 {
            add_white_accel(&mut q, i, qa, dt);
        }
        s.p = f * s.p * f.transpose() + q;
    }
}
