//! A window over the last frames of one per-frame statistic, for the
//! checks that judge a run of frames rather than one: the water check
//! (median of the counts' misfit) and the reading check (mean of a
//! reading's normalized innovation).

use crate::settings::WATER_CHECK_MAX_FRAMES;

/// The last frames' values of one statistic (the counts' normalized
/// innovation squared for the water check, a reading's normalized
/// innovation for the reading check), in a fixed ring: no allocation per
/// frame.
#[derive(Debug, Clone, Copy)]
pub(super) struct FrameWindow {
    vals: [f64; WATER_CHECK_MAX_FRAMES],
    head: usize,
    len: usize,
}

impl Default for FrameWindow {
    fn default() -> Self {
        FrameWindow {
            vals: [0.0; WATER_CHECK_MAX_FRAMES],
            head: 0,
            len: 0,
        }
    }
}

impl FrameWindow {
    /// Add a frame's value to a window of `span` frames (at most
    /// `WATER_CHECK_MAX_FRAMES`), dropping the oldest when full.
    pub fn push(&mut self, nis: f64, span: usize) {
        let span = span.clamp(1, WATER_CHECK_MAX_FRAMES);
        self.vals[self.head] = nis;
        self.head = (self.head + 1) % WATER_CHECK_MAX_FRAMES;
        self.len = (self.len + 1).min(span);
    }

    /// The median over a full window of `span` frames; None until it is
    /// full (or for a span the ring cannot hold). The median, not the
    /// mean: a few frames of large misfit are not the water, which
    /// misfits every frame.
    pub fn median(&self, span: usize) -> Option<f64> {
        let mut v = [0.0; WATER_CHECK_MAX_FRAMES];
        for (slot, x) in v.iter_mut().zip(self.last(span)?) {
            *slot = x;
        }
        let v = &mut v[..span];
        let (_, mid, _) = v.select_nth_unstable_by(span / 2, f64::total_cmp);
        let mid = *mid;
        if span % 2 == 1 {
            return Some(mid);
        }
        // Even span: the mean of the two middle values.
        let below = v[..span / 2]
            .iter()
            .copied()
            .fold(f64::NEG_INFINITY, f64::max);
        Some(0.5 * (below + mid))
    }
}

impl FrameWindow {
    /// The mean over a full window of `span` frames; None until it is full.
    pub fn mean(&self, span: usize) -> Option<f64> {
        Some(self.last(span)?.sum::<f64>() / span as f64)
    }

    /// The last `span` values, newest first, once there are that many
    /// (None for a span the ring cannot hold).
    fn last(&self, span: usize) -> Option<impl Iterator<Item = f64> + '_> {
        if span == 0 || span > WATER_CHECK_MAX_FRAMES || self.len < span {
            return None;
        }
        let n = WATER_CHECK_MAX_FRAMES;
        Some((0..span).map(move |k| self.vals[(self.head + n - 1 - k) % n]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_window_is_the_median_of_the_last_frames_once_full() {
        let mut w = FrameWindow::default();
        for (i, v) in [1.0, 2.0, 30.0].into_iter().enumerate() {
            assert_eq!(w.median(4), None, "not full after {i} frames");
            w.push(v, 4);
        }
        w.push(4.0, 4);
        // 1, 2, 30, 4: a spike does not carry it.
        assert_eq!(w.median(4), Some(3.0));
        w.push(10.0, 4);
        assert_eq!(w.median(4), Some(7.0));
        let mut odd = FrameWindow::default();
        for v in [5.0, 1.0, 9.0, 2.0, 7.0] {
            odd.push(v, 3);
        }
        assert_eq!(odd.median(3), Some(7.0), "of 9, 2, 7");
        // Round the ring more than once: still the last four.
        for k in 0..(3 * WATER_CHECK_MAX_FRAMES) {
            w.push(k as f64, 4);
        }
        let n = (3 * WATER_CHECK_MAX_FRAMES) as f64;
        assert_eq!(w.median(4), Some(n - 2.5));
        assert_eq!(w.median(0), None, "a span of 0 is the check off");
        assert_eq!(w.median(WATER_CHECK_MAX_FRAMES + 1), None);
    }

    #[test]
    fn the_mean_is_of_the_last_frames_once_full() {
        let mut w = FrameWindow::default();
        for v in [1.0, 2.0] {
            w.push(v, 3);
            assert_eq!(w.mean(3), None);
        }
        w.push(6.0, 3);
        assert_eq!(w.mean(3), Some(3.0));
        w.push(-6.0, 3);
        assert_eq!(w.mean(3), Some(2.0 / 3.0));
    }
}
