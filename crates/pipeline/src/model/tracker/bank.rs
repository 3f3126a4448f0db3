//! The tracker in water it was told it does not know: a bank of trackers,
//! each in its own water (K_D spread over the told doubt), weighed by how
//! well each explains the frames' counts, and reported as their mixture.
//!
//! Why: one tracker linearizes Beer's law at one K_D. Told a doubt as
//! wide as unknown water's (±0.3 m⁻¹ about a tank's 0.09), the truth can
//! be 1–2 nepers of brightness away from that point, where the filter's
//! covariance no longer describes its error: in water of K_D 0.29 along a
//! tank zigzag at 5–7 m, 160 of 165 `ok` frames were more than 3σ off in
//! x. Each member of the bank starts in its own water, told only the doubt
//! of its cell, and estimates K_D from there (the ratio of brightness over
//! a change of range is K_D's), so its linearization holds; the mixture's
//! σ holds the members' spread, and the weights say which waters explain
//! the frames.

use std::any::Any;

use lightpose_core::{Estimator, Findings, Frame, PoseEstimate, StdDev};

use super::state::{ln_k_d_reach, ln_k_d_sigma};
use super::Tracker;
use crate::settings::ModelError;

/// The nodes of the bank in units of the told doubt's σ in ln K_D: ±2σ in
/// steps of 2/3σ (7 waters).
const NODES: [f64; 7] = [-2.0, -4.0 / 3.0, -2.0 / 3.0, 0.0, 2.0 / 3.0, 4.0 / 3.0, 2.0];
/// What one frame's likelihood counts for. A member in the wrong water
/// makes the same error frame after frame, and its state absorbs part of
/// it, so successive frames are far from independent evidence about the
/// water: taken whole (1.0), the weights fell onto one member within a
/// second, often the wrong one. On the tank zigzag told ±0.3 (20 runs, in
/// K_D 0.09 / 0.19 / 0.29; `tests.rs`), `ok` frames beyond 3σ: 21 / 39 / —
/// at 1.0, 4 / 41 / — at 0.3, 0 / 4 / 11 at 0.1 (a frame is a tenth of an
/// independent look); over a minute in K_D 0.19 / 0.29 / 0.49, 24 / 7 /
/// 653 of ~1400 at 1.0, 9 / 1 / 495 at 0.3, 0 / 0 / 171 at 0.1.
const EVIDENCE: f64 = 0.1;
/// Each frame a share of every member's prior weight is given back, so
/// that a water ruled out long ago can return (the vehicle may leave a
/// turbid plume): about one in ten thousand.
const REVIVE: f64 = 1e-4;

/// A bank of trackers in different waters (name `"tracker"`).
#[derive(Debug, Clone)]
pub struct WaterBank {
    members: Vec<Tracker>,
    prior: [f64; NODES.len()],
    weight: [f64; NODES.len()],
    /// The members' estimates of the current frame (reused).
    last: Vec<PoseEstimate>,
}

impl WaterBank {
    /// Every member takes over `from`'s histories of the sensors
    /// ([`Tracker::inherit_checks`]).
    pub(crate) fn inherit_checks(&mut self, from: &Tracker) {
        self.members.iter_mut().for_each(|m| m.inherit_checks(from));
    }

    /// The doubt in ln K_D above which a tracker is run as a bank
    /// (`water_bank`): 0.25, a told σ of a quarter of K_D. Over a minute at
    /// 4–6 m (3 runs, attitude sensor, tank calibration), one tracker told σ in
    /// water at +2σ had x beyond 3σ on 25 / 104 / 700 / 873 of ~880 `ok`
    /// frames told 0.015 / 0.03 / 0.05 / 0.08 (0.17 / 0.33 / 0.56 / 0.89
    /// of K_D), the bank on none, with half the x RMS. The bank wins even
    /// at MODEL.md's Monte Carlo spread (0.015, 0.17 in ln K_D), but at
    /// seven times the cost the Monte Carlo's doubt stays one tracker,
    /// whose x ±2σ covers 95–97 % over its 8 s runs with the attitude
    /// sensor (docs/estimators.md). Measured while one tracker held a
    /// told doubt as ln(1 + σ/K_D); it holds σ/K_D now, so the threshold
    /// is σ > 0.25·K_D (0.28·K_D then).
    pub const WIDE_LN_K_D: f64 = 0.25;

    /// Whether `tracker` should run as a bank: `water_bank` on and its
    /// told doubt about its water wide.
    pub fn wanted(tracker: &Tracker) -> bool {
        tracker.cfg.water_bank
            && ln_k_d_sigma(tracker.model.light.k_d, tracker.k_d_sigma) > Self::WIDE_LN_K_D
    }

    /// The bank about `tracker`'s water and its told doubt.
    pub fn new(tracker: &Tracker) -> Result<Self, ModelError> {
        let k0 = tracker.model.light.k_d;
        let sl = ln_k_d_reach(k0, tracker.k_d_sigma);
        let half_cell = sl * (NODES[1] - NODES[0]) / 2.0;
        let mut members = Vec::with_capacity(NODES.len());
        let mut prior = [0.0; NODES.len()];
        for (i, g) in NODES.iter().enumerate() {
            let k = (super::state::ln_k_d(k0) + g * sl).exp();
            // The member's own doubt spans half its cell: σ/K = it.
            members.push(tracker.in_water(k, k * half_cell)?);
            prior[i] = (-0.5 * g * g).exp();
        }
        let total: f64 = prior.iter().sum();
        prior.iter_mut().for_each(|w| *w /= total);
        Ok(WaterBank {
            members,
            prior,
            weight: prior,
            last: Vec::with_capacity(NODES.len()),
        })
    }

    /// The bank's K_D: the weighted geometric mean of its members' (each
    /// its estimate, or its water before it has one), m⁻¹.
    pub fn k_d(&self) -> f64 {
        let ln: f64 = self
            .members
            .iter()
            .zip(&self.weight)
            .map(|(m, w)| w * m.k_d().map_or(m.model.light.k_d, |(k, _)| k).ln())
            .sum();
        ln.exp()
    }

    /// Weigh the members by this frame's counts: each member's likelihood;
    /// a member that fused no counts this frame while others did is taken
    /// as explaining them no better than the worst that did.
    fn weigh(&mut self, t: f64) {
        let mut ll = [None; NODES.len()];
        for (l, m) in ll.iter_mut().zip(&self.members) {
            *l = m.counts_log_likelihood(t);
        }
        let Some(worst) = ll.iter().flatten().copied().reduce(f64::min) else {
            return;
        };
        let best = ll.iter().flatten().copied().fold(worst, f64::max);
        for (w, l) in self.weight.iter_mut().zip(&ll) {
            *w *= (EVIDENCE * (l.unwrap_or(worst) - best)).exp();
        }
        let total: f64 = self.weight.iter().sum();
        if !(total > 0.0 && total.is_finite()) {
            self.weight = self.prior;
            return;
        }
        for (w, p) in self.weight.iter_mut().zip(&self.prior) {
            *w = (1.0 - REVIVE) * *w / total + REVIVE * p;
        }
    }

    /// The member the weights favour most (the sensors' offsets are its:
    /// the waters differ in range, not in the sensors).
    fn heaviest(&self) -> Option<&Tracker> {
        let k =
            (0..self.members.len()).max_by(|&a, &b| self.weight[a].total_cmp(&self.weight[b]))?;
        self.members.get(k)
    }

    /// The mixture of the members' estimates ([`mix_estimates`]).
    fn mixture(&self) -> PoseEstimate {
        mix_estimates(&self.last, &self.weight)
    }
}

/// The mixture of estimates `ests` weighed by `weight`: each field's
/// weighted mean over the estimates that give it, and a σ that holds their
/// spread; status and readings' verdicts of the heaviest. `ests` not empty.
pub(super) fn mix_estimates(ests: &[PoseEstimate], weight: &[f64]) -> PoseEstimate {
    let heaviest = (0..ests.len())
        .max_by(|&a, &b| weight[a].total_cmp(&weight[b]))
        .unwrap_or(0);
    let mut out = ests[heaviest];
    // Angles about the heaviest's (no wrap at ±180°).
    let centre = out.values().map(|v| v.unwrap_or(0.0));
    // Per field: Σw, Σw·d, Σw·(σ² + d²) over the estimates that give it.
    let mut sums = [[0.0; 3]; 6];
    for (e, w) in ests.iter().zip(weight) {
        for (f, (v, s)) in e.values().into_iter().zip(e.std.values()).enumerate() {
            if let (Some(v), Some(s)) = (v, s) {
                let d = v - centre[f];
                sums[f][0] += w;
                sums[f][1] += w * d;
                sums[f][2] += w * (s * s + d * d);
            }
        }
    }
    let mut vals = [None; 6];
    let mut sds = [None; 6];
    for (f, [sw, m1, m2]) in sums.into_iter().enumerate() {
        if sw > 0.0 {
            let mean = m1 / sw;
            vals[f] = Some(centre[f] + mean);
            sds[f] = Some((m2 / sw - mean * mean).max(0.0).sqrt());
        }
    }
    [out.x, out.y, out.z, out.pitch_deg, out.yaw_deg, out.surge] = vals;
    out.std = StdDev {
        x: sds[0],
        y: sds[1],
        z: sds[2],
        pitch: sds[3],
        yaw: sds[4],
        surge: sds[5],
        roll: None,
    };
    out
}

impl Estimator for WaterBank {
    fn name(&self) -> &'static str {
        Tracker::NAME
    }
    fn std_with_every_ok_pose(&self) -> bool {
        true
    }

    fn estimate(&mut self, frame: &Frame) -> PoseEstimate {
        self.last.clear();
        for m in self.members.iter_mut() {
            self.last.push(m.estimate(frame));
        }
        self.weigh(frame.t);
        self.mixture()
    }

    fn reset(&mut self) {
        self.members.iter_mut().for_each(Estimator::reset);
        self.weight = self.prior;
    }

    /// The weighted water of the members, once one has started.
    fn water_k_d(&self) -> Option<f64> {
        self.members
            .iter()
            .any(|m| m.k_d().is_some())
            .then(|| self.k_d())
    }

    fn depth_offset(&self) -> Option<(f64, f64)> {
        self.heaviest()?.depth_offset()
    }

    fn pitch_offset_deg(&self) -> Option<(f64, f64)> {
        self.heaviest()?.pitch_offset_deg()
    }

    /// The heaviest member's, as it reports them.
    fn findings(&self) -> Option<Findings> {
        self.heaviest()?.findings()
    }

    fn take_findings(&mut self, found: &(dyn Any + Send)) {
        self.members.iter_mut().for_each(|m| m.take_findings(found));
    }
}
