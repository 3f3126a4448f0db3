//! Which sensor is off: when the reading check calls depth or pitch
//! disagreeing, the tracker learns the offset of the one that is (or of
//! both), and finds which by trying each.
//!
//! Why: a depth sensor off by a constant (a beacon depth surveyed roughly,
//! a pressure zeroed elsewhere) or an AHRS whose pitch is (mounted askew of
//! the dome) went whole into the pose, every axis it touches beyond 3σ,
//! while the check only said so. Each offset is a state the light can
//! learn (`offsets`), but the check cannot say which reading is wrong: a
//! depth 0.1 m off drags the state's pitch, and the good pitch then
//! disagrees too. Learning the wrong one alone is worse than believing:
//! a depth offset fitted to a pitch bias doubled z's error, every pose
//! beyond 3σ. So at the call the tracker becomes three hypotheses (depth,
//! pitch, both), weighed by how well each explains the frames (counts and
//! readings), reported as their mixture, and it becomes the winner once
//! the weights have decided. Each hypothesis starts as if told its prior
//! from the start of the track: the offsets were carried all along as
//! consider states (`offsets::HELD_VAR`), whose covariance with the state
//! is how the state moved with them (docs/estimators.md, "Offsets learned
//! when the check calls").

use lightpose_core::{Frame, PoseEstimate, ReadingUse};

use super::bank::mix_estimates;
use super::offsets::Offset;
#[cfg(test)]
use super::state::Vs;
use super::state::{Ms, NS};
use super::Tracker;

/// What one frame's log-likelihood counts for: successive frames' errors
/// are far from independent (see the water bank's `EVIDENCE`).
const EVIDENCE: f64 = 0.1;

/// The weight at which a hypothesis wins.
const DECIDED: f64 = 0.99;

/// How many hypotheses: the depth sensor off, the pitch off, both.
const N: usize = 3;

/// The hypotheses of which sensor is off, each a tracker learning its
/// offsets: depth, pitch, both.
#[derive(Debug, Clone)]
pub(super) struct WhichOffset {
    members: [Tracker; N],
    /// Their summed log-likelihoods over the frames all explained.
    ll: [f64; N],
    last: [PoseEstimate; N],
}

impl WhichOffset {
    /// The weight of each hypothesis (equal priors).
    fn weights(&self) -> [f64; N] {
        let best = self.ll.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let w = self.ll.map(|l| (EVIDENCE * (l - best)).max(-700.0).exp());
        let total: f64 = w.iter().sum();
        w.map(|v| v / total)
    }

    pub(super) fn take_findings(&mut self, found: &(dyn std::any::Any + Send)) {
        use lightpose_core::Estimator;
        self.members.iter_mut().for_each(|m| m.take_findings(found));
    }

    /// The member the weights favour.
    pub(super) fn heavier(&self) -> &Tracker {
        let w = self.weights();
        let k = (0..N).max_by(|&a, &b| w[a].total_cmp(&w[b])).unwrap_or(0);
        &self.members[k]
    }
}

/// The covariance `p` with offset `i`'s variance raised from the consider
/// state's `HELD_VAR` to `sigma`², the offset never having been updated (a
/// consider state): every covariance with it is the state's sensitivity to
/// it times its variance, so those scale with the variance, and the rest of
/// P gains the sensitivity's outer product times the variance added. The
/// state's doubt is then what a tracker told `sigma` from its start would
/// have (to first order), and P stays positive. Why not a fixed guess of
/// that sensitivity: taking the offset as wholly in its coordinate (z for
/// the depth) left the rest of P as the biased readings had made it, and a
/// depth 0.2 m off with a pitch 1° off, both woken after 5 s, were learned
/// as +0.15 m and −0.34°, each 5σ out.
fn wake_covariance(p: &mut Ms, i: usize, sigma: f64) {
    let v = p[(i, i)];
    let target = sigma * sigma;
    if !(v > 0.0 && target > v) {
        p[(i, i)] = p[(i, i)].max(target);
        return;
    }
    let r = target / v;
    let col = p.column(i).into_owned();
    for a in 0..NS {
        for b in 0..NS {
            if a != i && b != i {
                p[(a, b)] += (r - 1.0) * col[a] * col[b] / v;
            }
        }
    }
    for a in 0..NS {
        if a != i {
            p[(a, i)] *= r;
            p[(i, a)] *= r;
        }
    }
    p[(i, i)] = target;
}

impl Tracker {
    /// After a frame (estimate `e`): when the reading check calls depth or
    /// pitch disagreeing on a frame that fused both readings, wake the
    /// offsets not yet estimated that the settings allow
    /// (`called_depth_offset_sigma_m`, `called_pitch_offset_sigma_deg`):
    /// one alone in this tracker, two as three hypotheses (depth, pitch,
    /// both). Without both readings the light cannot tell an offset from
    /// its coordinate (the z–pitch ridge), and nothing is woken; nor by a
    /// reading the gate refuses, which is not in the pose. A hypothesis
    /// being weighed wakes nothing; the one that wins wakes what is left if
    /// the check calls again (one offset learned where both sensors are
    /// off: its other reading keeps disagreeing).
    pub(super) fn after_frame_checks(&mut self, e: &PoseEstimate) {
        if self.weighing || self.which.is_some() {
            return;
        }
        let called = Offset::ALL
            .iter()
            .any(|o| e.agreement.suspect & o.suspect_bit() != 0);
        let fused = e.readings.attitude == ReadingUse::Used && e.readings.depth == ReadingUse::Used;
        if !(called && fused && self.state.is_some()) {
            return;
        }
        let wakeable =
            Offset::ALL.map(|o| !self.offsets.told(o, &self.cfg) && o.called(&self.cfg) > 0.0);
        match wakeable {
            [false, false] => {}
            [true, false] => self.wake_offset(Offset::ALL[0]),
            [false, true] => self.wake_offset(Offset::ALL[1]),
            [true, true] => {
                let mut member = self.clone();
                member.weighing = true;
                let mut members = [member.clone(), member.clone(), member];
                let [d, p, both] = &mut members;
                d.wake_offset(Offset::Depth);
                p.wake_offset(Offset::Pitch);
                both.wake_offset(Offset::Depth);
                both.wake_offset(Offset::Pitch);
                self.which = Some(Box::new(WhichOffset {
                    members,
                    ll: [0.0; N],
                    last: [*e; N],
                }));
            }
        }
    }

    /// `o` estimated from the kept state on, with its `called_*` prior.
    fn wake_offset(&mut self, o: Offset) {
        let sigma = o.called(&self.cfg);
        let Some(s) = self.state.as_mut() else {
            return;
        };
        self.offsets.wake(o, sigma);
        wake_covariance(&mut s.p, o.index(), sigma);
        s.offset_free[o as usize] = true;
        self.offsets.keep(s, &self.cfg);
    }

    /// One frame through every hypothesis, their mixture reported; the
    /// tracker becomes the winner once the weights decide.
    pub(super) fn estimate_weighing(&mut self, frame: &Frame) -> PoseEstimate {
        let Some(mut w) = self.which.take() else {
            return self.estimate_one(frame);
        };
        for (m, last) in w.members.iter_mut().zip(w.last.iter_mut()) {
            *last = m.estimate_one(frame);
        }
        let ll = w
            .members
            .each_ref()
            .map(|m| m.frame_log_likelihood(frame.t));
        if ll.iter().all(Option::is_some) {
            for (sum, l) in w.ll.iter_mut().zip(ll) {
                *sum += l.unwrap_or(0.0);
            }
        }
        let weights = w.weights();
        let e = mix_estimates(&w.last, &weights);
        match weights.iter().position(|p| *p >= DECIDED) {
            Some(k) => {
                if let Some(winner) = w.members.into_iter().nth(k) {
                    *self = winner;
                    self.weighing = false;
                }
            }
            None => self.which = Some(w),
        }
        e
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::tracker::state::{DOFF, POFF};
    use proptest::prelude::*;

    proptest! {
        /// P of y = A·z + s·b (z standard, b of variance v, never updated)
        /// woken to σ² is exactly P of the same with b of variance σ²: the
        /// state's doubt as if told σ² from the start; and it stays
        /// positive.
        #[test]
        fn waking_an_offset_is_telling_it_from_the_start(
            a in proptest::collection::vec(-1.0f64..1.0, NS * NS),
            sens in proptest::collection::vec(-2.0f64..2.0, NS),
            sigma in 1e-3f64..1.0,
            pitch in any::<bool>(),
        ) {
            let i = if pitch { POFF } else { DOFF };
            let a = Ms::from_iterator(a);
            let mut s = Vs::from_iterator(sens);
            s[i] = 1.0;
            let other = if pitch { DOFF } else { POFF };
            s[other] = 0.0;
            let mut base = a * a.transpose();
            for k in 0..NS {
                // The offsets are no mixture of z: their own rows are b's.
                base[(i, k)] = 0.0;
                base[(k, i)] = 0.0;
            }
            let joint = |v: f64| base + s * s.transpose() * v;
            let mut p = joint(super::super::offsets::HELD_VAR);
            wake_covariance(&mut p, i, sigma);
            let want = joint(sigma * sigma);
            let scale = 1.0 + want.abs().max();
            prop_assert!((p - want).abs().max() <= 1e-9 * scale, "{}", (p - want).abs().max());
            let min = p.symmetric_eigenvalues().min();
            prop_assert!(min >= -1e-9 * scale, "least eigenvalue {}", min);
        }
    }
}
