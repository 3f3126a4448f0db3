//! The reading check: does each own-sensor reading still agree with the
//! light? A reading as good as its σ gives innovations ν/√S that are
//! zero-mean; a biased one (a depth sensor zeroed on another day, a
//! mis-surveyed beacon depth, an AHRS mounted askew) is taken whole by a
//! filter that believes its σ, and its innovations then keep one sign,
//! since the light pulls the state back the other way every frame. The
//! check keeps each component's last normalized innovations (fused or
//! refused by the gate) and calls the component suspect when their mean
//! over a full window is past a limit.
//!
//! Why: measured on the tank zigzag, the dive and the held-out approach
//! with all three sensors (8 seeds each), a depth bias of 0.05–0.2 m went
//! whole into z (and into pitch), every pose `ok`, the reported σ
//! unchanged, the gate silent below 0.2 m: a wrong pose with nothing to say
//! so. What the light can see (depth, pitch) the check tells; what it
//! cannot (a heading bias, a DVL's scale) it does not (docs/estimators.md,
//! "The reading check").
//!
//! The windows are the tracker's, not the state's: they are about the
//! sensor, and survive the filter's restarts.

use lightpose_core::{Agreement, ReadingUse, Refusal};

use super::window::FrameWindow;
use crate::settings::WATER_CHECK_MAX_FRAMES;

/// Components, in [`lightpose_core::CHECKED`] order.
pub(super) const N: usize = 6;

/// The components that may be called suspect: pitch, yaw, depth. The
/// DVL's are reported, not judged: their window means carry the motion
/// model's lag (up to ±0.6 at the to-and-fro's reversals, no bias at all)
/// and no DVL bias tried moved them (5 % scale, 5° turned).
const JUDGED: usize = 3;

/// Each normalized innovation enters its window clipped to ±3: one reading
/// far off (a glitch the gate refused: 100σ) is not a bias, and moves a
/// 25-frame mean by at most 0.12; a bias keeps every value at the clip.
const CLIP: f64 = 3.0;

/// Every component's window.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Agreements {
    windows: [FrameWindow; N],
}

impl Agreements {
    /// Take one frame's normalized innovations (`None`: no such reading,
    /// or its innovation could not be formed) with what became of each
    /// reading (attitude, depth, velocity); only readings fused or refused
    /// by the gate say how the reading and the state compare.
    pub fn push(&mut self, innov: &[Option<f64>; N], uses: &[ReadingUse; 3]) {
        for (i, v) in innov.iter().enumerate() {
            let judged = matches!(
                uses[reading_of(i)],
                ReadingUse::Used | ReadingUse::Refused(Refusal::Gate)
            );
            if let (Some(v), true) = (v, judged) {
                if v.is_finite() {
                    self.windows[i].push(v.clamp(-CLIP, CLIP), WATER_CHECK_MAX_FRAMES);
                }
            }
        }
    }

    /// The check over the last `span` frames with each component, and
    /// which components of this frame's readings are past `limit`.
    pub fn report(&self, span: usize, limit: f64, uses: &[ReadingUse; 3]) -> Agreement {
        let mut a = Agreement::default();
        for (i, w) in self.windows.iter().enumerate() {
            a.mean[i] = w.mean(span);
            let present = !matches!(uses[reading_of(i)], ReadingUse::Absent);
            if i < JUDGED && present && a.mean[i].is_some_and(|m| m.abs() > limit) {
                a.suspect |= 1 << i;
            }
        }
        a
    }
}

/// Which reading (attitude 0, depth 1, velocity 2) component `i` is of.
fn reading_of(i: usize) -> usize {
    match i {
        0 | 1 => 0,
        2 => 1,
        _ => 2,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_component_is_suspect_when_its_window_mean_is_past_the_limit() {
        let mut a = Agreements::default();
        let used = [ReadingUse::Used; 3];
        for k in 0..30 {
            // Depth keeps one sign; pitch alternates.
            let pitch = if k % 2 == 0 { 1.0 } else { -1.0 };
            a.push(&[Some(pitch), None, Some(1.5), None, None, None], &used);
            let r = a.report(25, 1.0, &used);
            if k < 24 {
                assert_eq!(r.mean[2], None, "window not full at {k}");
            } else {
                assert_eq!(r.mean[2], Some(1.5));
                assert_eq!(r.suspect, 1 << 2);
            }
        }
        // Absent from this frame: not suspect now, the mean kept.
        let absent = [ReadingUse::Used, ReadingUse::Absent, ReadingUse::Used];
        let r = a.report(25, 1.0, &absent);
        assert_eq!(r.suspect, 0);
        assert_eq!(r.mean[2], Some(1.5));
        // A reading refused as malformed says nothing of agreement.
        let bad = [
            ReadingUse::Used,
            ReadingUse::Refused(Refusal::NotFinite),
            ReadingUse::Used,
        ];
        a.push(&[None, None, Some(-100.0), None, None, None], &bad);
        assert_eq!(a.report(25, 1.0, &used).mean[2], Some(1.5));
    }
}
