//! Which sensor is off: when the reading check calls depth or pitch
//! disagreeing, the tracker learns the offset of the one that is, and
//! finds which by trying both.
//!
//! Why: a depth sensor off by a constant (a beacon depth surveyed roughly,
//! a pressure zeroed elsewhere) or an AHRS whose pitch is (mounted askew of
//! the dome) went whole into the pose, every axis it touches beyond 3σ,
//! while the check only said so. Each offset is a state the light can
//! learn (`offsets`), but the check cannot say which reading is wrong: a
//! depth 0.1 m off drags the state's pitch, and the good pitch then
//! disagrees too. Learning both at once leaves their split to the change
//! of range (a depth offset moves the spot's elevation as b/x, a pitch
//! offset does not), slow on most runs: honest, but z up to twice as far
//! off as believing the bias. Learning the wrong one alone is worse: a
//! depth offset fitted to a pitch bias doubled z's error, every pose
//! beyond 3σ. So at the call the tracker becomes two, each learning one
//! offset, weighed by how well each explains the frames (counts and
//! readings), reported as their mixture, and it becomes the winner once
//! the weights have decided.

use lightpose_core::{Frame, PoseEstimate, ReadingUse};

use super::bank::mix_estimates;
use super::offsets::Offset;
use super::state::Ms;
use super::Tracker;

/// What one frame's log-likelihood counts for: successive frames' errors
/// are far from independent (see the water bank's `EVIDENCE`).
const EVIDENCE: f64 = 0.1;

/// The weight at which a hypothesis wins.
const DECIDED: f64 = 0.99;

/// The two hypotheses: the depth sensor off, the pitch off.
#[derive(Debug, Clone)]
pub(super) struct WhichOffset {
    members: [Tracker; 2],
    /// Their summed log-likelihoods over the frames both explained.
    ll: [f64; 2],
    last: [PoseEstimate; 2],
}

impl WhichOffset {
    /// The weight of each hypothesis.
    fn weights(&self) -> [f64; 2] {
        let d = (EVIDENCE * (self.ll[1] - self.ll[0])).clamp(-700.0, 700.0);
        let w0 = 1.0 / (1.0 + d.exp());
        [w0, 1.0 - w0]
    }

    pub(super) fn take_findings(&mut self, found: &(dyn std::any::Any + Send)) {
        use lightpose_core::Estimator;
        self.members.iter_mut().for_each(|m| m.take_findings(found));
    }

    /// The member the weights favour.
    pub(super) fn heavier(&self) -> &Tracker {
        let w = self.weights();
        &self.members[usize::from(w[1] > w[0])]
    }
}

/// The covariance `p` of a state that took a reading of coordinate `c` as
/// unbiased, with its offset (index `i`, held at 0 with no doubt so far)
/// now doubted by `sigma`. What the state knows is the coordinate plus the
/// offset, so the offset's doubt goes into the coordinate too, their sum
/// known as before: P + σ²·(e_c − e_i)(e_c − e_i)ᵀ, which keeps P positive.
/// With the offset's doubt alone the coordinate kept the σ the biased
/// readings had given it, and the light put the bias elsewhere: a depth
/// 0.1 m off was learned as +0.06 m and a pitch offset of +0.5°, each
/// 3.6σ off.
fn wake_covariance(p: &mut Ms, i: usize, c: usize, sigma: f64) {
    let v = sigma * sigma;
    p[(i, i)] += v;
    p[(c, c)] += v;
    p[(i, c)] -= v;
    p[(c, i)] -= v;
}

impl Tracker {
    /// After a frame (estimate `e`): when the reading check calls depth or
    /// pitch disagreeing on a frame that fused both readings, wake the
    /// offsets the settings allow (`called_depth_offset_sigma_m`,
    /// `called_pitch_offset_sigma_deg`): one alone in this tracker, two as
    /// two hypotheses. Without both readings the light cannot tell an
    /// offset from its coordinate (the z–pitch ridge), and nothing is
    /// woken; nor by a reading the gate refuses, which is not in the pose.
    /// Once only: a hypothesis, or the tracker it became, wakes no more.
    pub(super) fn after_frame_checks(&mut self, e: &PoseEstimate) {
        if self.offsets_decided {
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
        self.offsets_decided = true;
        match wakeable {
            [false, false] => {}
            [true, false] => self.wake_offset(Offset::ALL[0]),
            [false, true] => self.wake_offset(Offset::ALL[1]),
            [true, true] => {
                let mut members = [self.clone(), self.clone()];
                for (m, o) in members.iter_mut().zip(Offset::ALL) {
                    m.wake_offset(o);
                }
                self.which = Some(Box::new(WhichOffset {
                    members,
                    ll: [0.0; 2],
                    last: [*e; 2],
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
        wake_covariance(&mut s.p, o.index(), o.coordinate(), sigma);
        self.offsets.keep(s, &self.cfg);
    }

    /// One frame through both hypotheses, their mixture reported; the
    /// tracker becomes the winner once the weights decide.
    pub(super) fn estimate_both(&mut self, frame: &Frame) -> PoseEstimate {
        let Some(mut w) = self.which.take() else {
            return self.estimate_one(frame);
        };
        for (m, last) in w.members.iter_mut().zip(w.last.iter_mut()) {
            *last = m.estimate_one(frame);
        }
        if let [Some(a), Some(b)] = w
            .members
            .each_ref()
            .map(|m| m.frame_log_likelihood(frame.t))
        {
            w.ll[0] += a;
            w.ll[1] += b;
        }
        let weights = w.weights();
        let e = mix_estimates(&w.last, &weights);
        if let Some(k) = weights.iter().position(|p| *p >= DECIDED) {
            let [d, p] = w.members;
            *self = if k == 0 { d } else { p };
        } else {
            self.which = Some(w);
        }
        e
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::tracker::state::{DOFF, NS, POFF};
    use proptest::prelude::*;

    proptest! {
        /// Waking an offset keeps P symmetric and positive, gives the offset
        /// its prior, and leaves the variance of coordinate plus offset (what
        /// the readings measured) and every other entry as they were.
        #[test]
        fn waking_keeps_the_sum_known_and_p_positive(
            seed in proptest::collection::vec(-1.0f64..1.0, NS * NS),
            sigma in 1e-4f64..1.0,
            pitch in any::<bool>(),
        ) {
            let (i, c) = if pitch { (POFF, 3) } else { (DOFF, 2) };
            // A positive P whose offset rows are 0 (held, no doubt).
            let a = Ms::from_iterator(seed);
            let mut p = a * a.transpose() + Ms::identity() * 1e-6;
            for k in 0..NS {
                for o in [DOFF, POFF] {
                    p[(o, k)] = 0.0;
                    p[(k, o)] = 0.0;
                }
            }
            let before = p;
            wake_covariance(&mut p, i, c, sigma);
            let sum = |m: &Ms| m[(c, c)] + m[(i, i)] + 2.0 * m[(i, c)];
            prop_assert!((sum(&p) - sum(&before)).abs() <= 1e-12 * (1.0 + sum(&before)));
            prop_assert!((p[(i, i)] - sigma * sigma).abs() <= 1e-15);
            prop_assert_eq!(p, p.transpose());
            let min = p.symmetric_eigenvalues().min();
            prop_assert!(min >= -1e-9, "least eigenvalue {}", min);
            for r in 0..NS {
                for k in 0..NS {
                    if ![i, c].contains(&r) && ![i, c].contains(&k) {
                        prop_assert_eq!(p[(r, k)], before[(r, k)]);
                    }
                }
            }
        }
    }
}
