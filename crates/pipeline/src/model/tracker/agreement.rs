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
use crate::settings::{READING_CHECK_SLOT_S, WATER_CHECK_MAX_FRAMES};

/// Components, in [`lightpose_core::CHECKED`] order.
pub(super) const N: usize = 6;

/// The components that may be called suspect: pitch, yaw, depth. The
/// DVL's are reported, not judged: their window means carry the motion
/// model's lag (up to ±0.6 at the to-and-fro's reversals, no bias at all)
/// and no DVL bias tried moved them (5 % scale, 5° turned). A DVL set up
/// wrong (backwards, across the bow, in other units) is judged by the
/// light's range instead (`dvl_check`).
const JUDGED: usize = 3;

/// Each normalized innovation enters its slot clipped to ±3: one reading
/// far off (a glitch the gate refused: 100σ) is not a bias, and moves a
/// 25-slot mean by at most 0.12; a bias keeps every value at the clip.
const CLIP: f64 = 3.0;

/// A slot closes at the first frame this close to its end or past it:
/// frames 0.2 s apart each close one (their times in f64 land a hair
/// either side of it).
const SLOT_SLACK_S: f64 = 0.01;

/// Every component's window of slot means, and the open slot's sums.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Agreements {
    windows: [FrameWindow; N],
    sum: [f64; N],
    count: [u32; N],
    /// When the open slot began (s, the frames' time); none before the
    /// first frame.
    opened: Option<f64>,
}

impl Agreements {
    /// Take one frame's normalized innovations (`None`: no such reading,
    /// or its innovation could not be formed) with what became of each
    /// reading (attitude, depth, velocity); only readings fused or refused
    /// by the gate say how the reading and the state compare.
    ///
    /// Values are averaged per slot of [`READING_CHECK_SLOT_S`] (by the
    /// frames' time `t`), and each slot's mean goes into the window when
    /// the next slot opens: at 5 Hz one frame a slot, at 50 Hz ten, whose
    /// innovations are far from independent (a window of 25 frames at 50 Hz
    /// is 0.5 s of one manoeuvre: with no bias its mean reached 0.80,
    /// against 0.55 at 5 Hz).
    pub fn push(&mut self, innov: &[Option<f64>; N], uses: &[ReadingUse; 3], t: f64) {
        let close = match self.opened {
            None => false,
            // A step back in time (a log's clock restarting) closes it too.
            Some(t0) => t - t0 >= READING_CHECK_SLOT_S - SLOT_SLACK_S || t < t0,
        };
        if close {
            for i in 0..N {
                if self.count[i] > 0 {
                    let mean = self.sum[i] / f64::from(self.count[i]);
                    self.windows[i].push(mean, WATER_CHECK_MAX_FRAMES);
                }
            }
            (self.sum, self.count) = ([0.0; N], [0; N]);
        }
        if close || self.opened.is_none() {
            self.opened = Some(t);
        }
        for (i, v) in innov.iter().enumerate() {
            let judged = matches!(
                uses[reading_of(i)],
                ReadingUse::Used | ReadingUse::Refused(Refusal::Gate)
            );
            if let (Some(v), true) = (v, judged) {
                if v.is_finite() {
                    self.sum[i] += v.clamp(-CLIP, CLIP);
                    self.count[i] += 1;
                }
            }
        }
    }

    /// The check over the last `span` slots with each component, and
    /// which components are past `limit`. A frame without the reading
    /// (a stale depth, a DVL dropout) keeps its verdict: its window has not
    /// moved, and a verdict that came and went with each gap would log a
    /// pair of lines per gap.
    pub fn report(&self, span: usize, limit: f64) -> Agreement {
        let mut a = Agreement::default();
        for (i, w) in self.windows.iter().enumerate() {
            a.mean[i] = w.mean(span);
            if i < JUDGED && a.mean[i].is_some_and(|m| m.abs() > limit) {
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
            a.push(
                &[Some(pitch), None, Some(1.5), None, None, None],
                &used,
                0.2 * k as f64,
            );
            let r = a.report(25, 1.0);
            // A slot's mean enters at the next slot's first frame.
            if k < 25 {
                assert_eq!(r.mean[2], None, "window not full at {k}");
            } else {
                assert_eq!(r.mean[2], Some(1.5));
                assert_eq!(r.suspect, 1 << 2);
            }
        }
        // A frame without depth leaves the verdict as it was.
        let absent = [ReadingUse::Used, ReadingUse::Absent, ReadingUse::Used];
        a.push(&[None; 6], &absent, 6.0);
        let r = a.report(25, 1.0);
        assert_eq!(r.suspect, 1 << 2);
        assert_eq!(r.mean[2], Some(1.5));
        // A reading refused as malformed says nothing of agreement.
        let bad = [
            ReadingUse::Used,
            ReadingUse::Refused(Refusal::NotFinite),
            ReadingUse::Used,
        ];
        a.push(&[None, None, Some(-100.0), None, None, None], &bad, 6.2);
        a.push(&[None, None, None, None, None, None], &bad, 6.4);
        assert_eq!(a.report(25, 1.0).mean[2], Some(1.5));
    }

    /// At 50 Hz ten frames make a slot: the window is 5 s whatever the
    /// rate, and its mean is of slot means.
    #[test]
    fn fast_frames_are_averaged_per_slot() {
        let mut a = Agreements::default();
        let used = [ReadingUse::Used; 3];
        let mut slots = 0;
        for k in 0..260 {
            // Within a slot the values alternate 0 and 2: each slot's mean
            // is 1.
            let v = if k % 2 == 0 { 0.0 } else { 2.0 };
            a.push(
                &[None, None, Some(v), None, None, None],
                &used,
                0.02 * k as f64,
            );
            if a.report(25, 0.5).mean[2].is_some() {
                slots += 1;
            }
        }
        // 250 frames (5 s) fill the 25 slots; then a mean of 1 each.
        assert!((5..=12).contains(&slots), "{slots}");
        let r = a.report(25, 0.5);
        assert!(r.mean[2].is_some_and(|m| (m - 1.0).abs() < 1e-9), "{r:?}");
    }
}
