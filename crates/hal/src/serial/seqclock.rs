//! When a serial board sampled its newest line, from the lines' `seq`.
//!
//! A line is stamped when it is read, less its time on the wire; but the
//! frame thread reads a port only when a frame wants it, so the newest
//! line has waited in the kernel's buffer for up to a line period (50 ms
//! at the reference firmware's 20 lines/s: 25 ms late on average), and the
//! serial port gives no time of arrival. A board streams at a steady rate
//! (docs/serial-protocol.md), so line k was sampled at a + b·k on the
//! host's clock, and every read stamp is that plus a wait that is never
//! negative: the lines read with the least wait lie lowest under that
//! line. The fit takes its slope (the board's period, its clock's drift
//! in it) from two least-waited lines far apart: each half of a window of
//! recent lines at first, then an anchor kept from an earlier window and
//! the window's own; its offset from the window's least-waited line.
//!
//! What it can and cannot take off: the least wait over the window is
//! the fit's floor. The bank now listens between frames (`idle`), so a
//! line's read stamp is its arrival within a slice, and the fit smooths
//! what jitter is left. Read only at the frame, a crystal board (tens of
//! ppm) read at a divisor rate (5 Hz frames, 20 lines/s) had its newest
//! line the same φ old at every read, the least wait was φ and nothing was
//! taken off; the fit alone helps where the read instants move through the
//! board's period (a resonator-clocked board, a non-divisor frame rate).
//!
//! Guards, so that a board that does not stream steadily is stamped as
//! before: the fit is used only over at least [`MIN_LINES`] lines and
//! [`MIN_SPAN_S`] seconds; a line is moved earlier by at most
//! [`MAX_SHIFT_PERIODS`] periods (the newest line in a buffer came within
//! the last period), never later; and a `seq` that does not step forward
//! by 1 to [`MAX_STEP`] (a board reset, a long gap) starts the window
//! again. No allocation: the window is an array.

// `!(a < b)` is deliberate: it is true for NaN, which must fail a check.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

/// Lines kept: 12.8 s at 20 lines/s.
const WINDOW: usize = 256;
/// Lines before the fit is used.
pub const MIN_LINES: usize = 32;
/// How old the slope's anchor may grow before a newer one is taken: long
/// enough that the slope is steady (3000 lines at 20 lines/s), short
/// enough that a crystal's drift with temperature does not bend it.
const ANCHOR_AGE_S: f64 = 150.0;
/// Seconds the window must span before the fit is used.
pub const MIN_SPAN_S: f64 = 1.0;
/// The most a line is moved earlier, in fitted periods.
pub const MAX_SHIFT_PERIODS: f64 = 1.5;
/// The largest forward step of `seq` still one stream (lines the frame
/// thread never read: 50 s at 20 lines/s).
pub const MAX_STEP: u32 = 1000;

#[derive(Debug, Clone)]
pub struct SeqClock {
    /// (k, stamp) in order of k: k counts lines from the window's start.
    pts: [(f64, f64); WINDOW],
    len: usize,
    head: usize,
    last_seq: Option<u32>,
    k: f64,
    /// A least-waited (k, stamp) from an earlier window: the slope's far end.
    anchor: Option<(f64, f64)>,
}

impl Default for SeqClock {
    fn default() -> Self {
        SeqClock {
            pts: [(0.0, 0.0); WINDOW],
            len: 0,
            head: 0,
            last_seq: None,
            k: 0.0,
            anchor: None,
        }
    }
}

impl SeqClock {
    /// Forget the stream (a port reopened, a board reset).
    pub fn reset(&mut self) {
        self.len = 0;
        self.head = 0;
        self.last_seq = None;
        self.k = 0.0;
        self.anchor = None;
    }

    /// The `i`th oldest point of the window.
    fn at(&self, i: usize) -> (f64, f64) {
        self.pts[(self.head + WINDOW - self.len + i) % WINDOW]
    }

    /// Line `seq`, read-stamped `s` (read time less its time on the wire):
    /// when it was sampled, as near as the board's steady rate tells.
    pub fn stamp(&mut self, seq: u32, s: f64) -> f64 {
        match self.last_seq {
            Some(p) if (1..=MAX_STEP).contains(&seq.wrapping_sub(p)) => {
                self.k += f64::from(seq.wrapping_sub(p));
            }
            Some(_) => self.reset(),
            None => {}
        }
        self.last_seq = Some(seq);
        self.pts[self.head] = (self.k, s);
        self.head = (self.head + 1) % WINDOW;
        self.len = (self.len + 1).min(WINDOW);
        match self.fit() {
            Some((a, b)) => {
                let shift = (s - (a + b * self.k)).clamp(0.0, MAX_SHIFT_PERIODS * b);
                s - shift
            }
            None => s,
        }
    }

    /// (a, b) of the lower line, when the window is long enough and the
    /// line rises. The slope: from the least-waited line of each half of
    /// the window (found against the slope so far, twice), or, once an
    /// anchor half a window or more back is kept, from the anchor to the
    /// window's least-waited line: the longer the baseline, the less two
    /// lines' waits tilt it (a slope off by ε a line is off by 128·ε at
    /// the window's end). The offset: the least-waited line of the window
    /// under that slope.
    fn fit(&mut self) -> Option<(f64, f64)> {
        if self.len < MIN_LINES {
            return None;
        }
        let (first, last) = (self.at(0), self.at(self.len - 1));
        if !(last.1 - first.1 >= MIN_SPAN_S) {
            return None;
        }
        let lowest = |c: &Self, b: f64, from: usize, to: usize| {
            (from..to)
                .map(|i| c.at(i))
                .min_by(|p, q| (p.1 - b * p.0).total_cmp(&(q.1 - b * q.0)))
        };
        let half = self.len / 2;
        let slope = |anchor: Option<(f64, f64)>| {
            let mut b = (last.1 - first.1) / (last.0 - first.0);
            for _ in 0..2 {
                let (p, q) = match anchor {
                    Some(a) => (a, lowest(self, b, 0, self.len)?),
                    None => (lowest(self, b, 0, half)?, lowest(self, b, half, self.len)?),
                };
                if !(q.0 > p.0) {
                    return None;
                }
                b = (q.1 - p.1) / (q.0 - p.0);
            }
            Some(b)
        };
        let halves = slope(None)?;
        // The anchor's slope, while the window's own agrees with it (to 2 %:
        // a board whose rate changed without a break of seq, a firmware
        // rate change, drops its anchor).
        let anchor = self.anchor.filter(|a| last.0 - a.0 >= (WINDOW / 2) as f64);
        let b = match anchor.and_then(|a| slope(Some(a))) {
            Some(b) if (b - halves).abs() <= 0.02 * halves.abs() => b,
            Some(_) => {
                self.anchor = None;
                halves
            }
            None => halves,
        };
        if !(b > 0.0 && b.is_finite()) {
            return None;
        }
        let low = lowest(self, b, 0, self.len)?;
        // A new anchor once the window is full and the one kept is over
        // ANCHOR_AGE_S old (or none): the window's least-waited line.
        let stale = self.anchor.is_none_or(|a| last.1 - a.1 > ANCHOR_AGE_S);
        if self.len == WINDOW && stale {
            self.anchor = Some(low);
        }
        Some((low.1 - b * low.0, b))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small deterministic generator (no RNG crate in hal's tests).
    struct Lcg(u64);
    impl Lcg {
        fn uniform(&mut self) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((self.0 >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        }
    }

    /// A board at `period` (its clock off by `drift`), read in bursts
    /// every `read_every` s: each line waits in the buffer until the next
    /// read. Returns, over the newest line of each read (the one a frame
    /// uses) among the last `tail` lines (the window full), the stamps'
    /// largest error and the raw stamps' mean error.
    fn run(period: f64, drift: f64, read_every: f64, lines: u32, tail: u32) -> (f64, f64) {
        let mut c = SeqClock::default();
        let mut rng = Lcg(7);
        let phase = 0.013;
        let sampled = |k: u32| 100.0 + f64::from(k) * period * (1.0 + drift);
        let tick = |t: f64| ((t - phase) / read_every).ceil();
        let (mut worst, mut raw_sum, mut n) = (0.0f64, 0.0, 0);
        for k in 0..lines {
            let at = sampled(k);
            // Read at the next read tick, plus a little scheduler jitter.
            let read = tick(at) * read_every + phase + 0.0005 * rng.uniform();
            let got = c.stamp(k.wrapping_add(u32::MAX - 100), read);
            assert!(got <= read, "never later than read");
            let newest = tick(sampled(k + 1)) > tick(at);
            if k >= lines - tail && newest {
                worst = worst.max((got - at).abs());
                raw_sum += read - at;
                n += 1;
            }
        }
        (worst, raw_sum / f64::from(n))
    }

    /// 20 lines/s read at frame instants that move through the line
    /// period (every 203.1 ms, or every 200 ms by a board whose resonator
    /// is 0.5 % fast): the newest line of a read is late by 0–50 ms raw
    /// (25 ms on average); fitted, within 3 ms (the least wait over the
    /// window's reads, and the scheduler's), with the board's clock off by
    /// ±100 ppm too, and across a seq wrap.
    #[test]
    fn a_steady_board_read_at_moving_instants_is_stamped_when_it_sampled() {
        for (drift, every) in [(0.0, 0.2031), (1e-4, 0.2031), (-1e-4, 0.2031), (5e-3, 0.2)] {
            let (worst, raw) = run(0.05, drift, every, 3000, 1000);
            assert!(raw > 0.015, "raw stamps late by {raw}");
            eprintln!(
                "drift {drift}, every {every} s: raw late {raw:.4} s on average, fitted off by {worst:.4} s at most"
            );
            assert!(worst < 3e-3, "drift {drift}: off by {worst}");
        }
        // Read as fast as it streams: late by up to a period raw.
        let (worst, _) = run(0.05, 0.0, 0.0513, 600, 200);
        assert!(worst < 2e-3, "off by {worst}");
    }

    /// A crystal board read at a divisor rate (20 lines/s, 5 Hz frames
    /// exactly): every newest line waited the same φ, so the least wait is
    /// φ and the fit takes nothing off (see the module's words), nor adds:
    /// the stamps are the raw ones to within the scheduler's jitter.
    #[test]
    fn at_a_divisor_rate_a_crystal_board_is_stamped_as_read() {
        for phase_ms in [13.0, 30.0, 45.0] {
            let mut c = SeqClock::default();
            let (mut fitted, mut raw, mut n) = (0.0, 0.0, 0.0);
            let phi = phase_ms * 1e-3;
            for k in 0..3000u32 {
                let at = 100.0 + f64::from(k) * 0.05;
                // The line sampled φ before a read, every 4th line.
                let read = at + phi + f64::from(3 - k % 4) * 0.05;
                let got = c.stamp(k, read);
                if k % 4 == 3 && k > 1000 {
                    fitted += got - at;
                    raw += read - at;
                    n += 1.0;
                }
            }
            let (fitted, raw) = (fitted / n, raw / n);
            assert!((raw - phi).abs() < 1e-9);
            assert!(
                (fitted - raw).abs() < 1e-3,
                "φ {phi}: fitted {fitted}, raw {raw}"
            );
        }
    }

    /// A board whose rate changes without a break of seq (20 → 10 lines/s)
    /// drops its anchor: within a window its stamps are back to the read
    /// ones' error or better, not fitted to the old period.
    #[test]
    fn a_rate_change_drops_the_anchor() {
        let mut c = SeqClock::default();
        let mut rng = Lcg(5);
        let mut t = 100.0;
        let mut worst_late = 0.0f64;
        for k in 0..4000u32 {
            let period = if k < 3000 { 0.05 } else { 0.1 };
            t += period;
            let read = t + 0.04 * rng.uniform();
            let got = c.stamp(k, read);
            assert!(got <= read);
            if k > 3000 + WINDOW as u32 {
                worst_late = worst_late.max((got - t).abs());
            }
        }
        assert!(worst_late < 0.045, "off by {worst_late} after the change");
    }

    /// Before the window is long enough, and for a line the fit would move
    /// by more than 1.5 periods, stamps are as read (or moved by at most
    /// that); a step back of seq (a board reset) starts again.
    #[test]
    fn guards_keep_the_read_stamp_when_the_fit_cannot_be_trusted() {
        let mut c = SeqClock::default();
        for k in 0..(MIN_LINES as u32 - 1) {
            let s = 10.0 + 0.05 * f64::from(k) + 0.03;
            assert_eq!(c.stamp(k, s), s);
        }
        // Steady for long enough: then a line read 1 s late is moved by
        // 1.5 periods at most.
        for k in (MIN_LINES as u32 - 1)..100 {
            c.stamp(k, 10.0 + 0.05 * f64::from(k));
        }
        let late = 10.0 + 0.05 * 100.0 + 1.0;
        let got = c.stamp(100, late);
        assert!((late - got - 0.075).abs() < 1e-9, "moved {}", late - got);
        // A reset (seq back to 0): as read again.
        assert_eq!(c.stamp(0, 20.0), 20.0);
        assert_eq!(c.stamp(1, 20.05), 20.05);
        // A jump past MAX_STEP is a new stream too.
        assert_eq!(c.stamp(1 + MAX_STEP + 1, 70.0), 70.0);
    }

    /// A board that does not stream steadily (lines at random times): no
    /// line is moved by more than 1.5 of the fitted periods, none later.
    #[test]
    fn an_unsteady_board_is_moved_little() {
        let mut c = SeqClock::default();
        let mut rng = Lcg(3);
        let mut t = 0.0;
        for k in 0..500u32 {
            t += 0.01 + 0.09 * rng.uniform();
            let got = c.stamp(k, t);
            assert!(got <= t && t - got <= 1.5 * 0.1 + 1e-9, "{k}: {t} → {got}");
        }
    }
}
