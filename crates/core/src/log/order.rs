//! The order of frames in a log, as one rule that every log reader applies
//! (JSON Lines here, MCAP in lightpose-logs) so that replay, calibration
//! and the daemon's replay backend see the same frames of the same file.
//!
//! The rule (FORMATS.md: `seq` increases by 1, `t` increases):
//!
//! - `t` must be a time: finite and |t| ≤ [`MAX_ABS_T_S`] (1e10 s, past
//!   the year 2286 in Unix time). `t = 1e300` is refused.
//! - `seq` and `t` must both increase. A frame whose `seq` or `t` is not
//!   above the last frame kept (a duplicate, a step back) is skipped and
//!   counted; the caller names its line. A step back is not a gap: it
//!   loses no frame in the count.
//! - A forward step of `seq` by more than 1 is a gap: counted, with the
//!   frames it lost.
//! - A forward step of `t` by more than the gap bound is kept (a recording
//!   paused and resumed is a real log) and flagged: counted as a jump, and
//!   [`FrameOrder::last_jump`] says so for the frame just admitted, so that
//!   a reader at recorded pace does not sleep through it.
//!
//! - A lone glitch: when the frame just admitted claimed a gap in `seq`
//!   (or a jump in `t`) and the next frame steps back in that one only,
//!   in line with the frame before the claim, the claim was the glitch:
//!   the next frame is admitted, counted as a glitch, and the gap taken
//!   back. One corrupt `seq` (500 among 4, 5, 6) used to cost every frame
//!   after it. Once only: the frame after a glitch must be in line.
//!
//! A log whose clock restarts mid-file (a board reset: `seq` and `t` both
//! back) therefore loses the frames after the restart, each one named:
//! split such a file at the line the first skip names.

/// Largest |t| (seconds) a frame or message may carry.
pub const MAX_ABS_T_S: f64 = 1e10;

/// Default bound on a forward step of `t` before it is flagged as a jump.
pub const DEFAULT_MAX_GAP_S: f64 = 10.0;

/// Whether `t` is a time a frame or message may carry (see the module).
pub fn plausible_t(t: f64) -> bool {
    t.is_finite() && t.abs() <= MAX_ABS_T_S
}

/// The rule above, with its counters.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameOrder {
    last: Option<(u64, f64)>,
    /// The frame admitted before `last` (none just after a glitch), the
    /// frames `last`'s gap counted as lost and whether its `t` jumped:
    /// what a glitch in `last` takes back.
    prev: Option<(u64, f64)>,
    last_gap: u64,
    last_jumped: bool,
    glitches: u64,
    max_gap_s: f64,
    gaps: u64,
    lost: u64,
    skipped: u64,
    jumps: u64,
    last_jump: Option<f64>,
}

impl Default for FrameOrder {
    fn default() -> Self {
        FrameOrder::new(DEFAULT_MAX_GAP_S)
    }
}

impl FrameOrder {
    /// A forward step of `t` above `max_gap_s` is a jump.
    pub fn new(max_gap_s: f64) -> Self {
        FrameOrder {
            last: None,
            prev: None,
            last_gap: 0,
            last_jumped: false,
            glitches: 0,
            max_gap_s,
            gaps: 0,
            lost: 0,
            skipped: 0,
            jumps: 0,
            last_jump: None,
        }
    }

    pub fn max_gap_s(&self) -> f64 {
        self.max_gap_s
    }

    /// Admit the frame (`seq`, `t`) after the frames admitted so far, or
    /// say why it is skipped (counted here; the caller adds the place).
    pub fn admit(&mut self, seq: u64, t: f64) -> Result<(), String> {
        if !plausible_t(t) {
            self.skipped += 1;
            return Err(format!(
                "t = {t:e} is not a time in seconds (|t| ≤ {MAX_ABS_T_S:e}): frame skipped"
            ));
        }
        self.last_jump = None;
        let mut glitch = false;
        if let (Some((ls, lt)), Some((ps, pt))) = (self.last, self.prev) {
            let seq_glitch = self.last_gap > 0 && seq < ls && t > lt;
            let t_glitch = self.last_jumped && t <= lt && seq > ls;
            if (seq_glitch || t_glitch) && seq > ps && t > pt {
                // `last` was the glitch: go on from the frame before it.
                glitch = true;
                self.glitches += 1;
                if self.last_gap > 0 {
                    self.gaps -= 1;
                    self.lost -= self.last_gap;
                }
                if self.last_jumped {
                    self.jumps -= 1;
                }
                self.last = self.prev;
            }
        }
        self.last_gap = 0;
        self.last_jumped = false;
        if let Some((ls, lt)) = self.last {
            let why = if seq == ls {
                Some(format!("seq {seq} repeats: frame skipped"))
            } else if seq < ls {
                Some(format!(
                    "seq {seq} after seq {ls}: frame skipped (seq must increase)"
                ))
            } else if t <= lt {
                Some(format!(
                    "t = {t} after t = {lt}: frame skipped (t must increase)"
                ))
            } else {
                None
            };
            if let Some(why) = why {
                self.skipped += 1;
                return Err(why);
            }
            if seq > ls + 1 {
                self.gaps += 1;
                self.last_gap = seq - ls - 1;
                self.lost += self.last_gap;
            }
            if t - lt > self.max_gap_s {
                self.jumps += 1;
                self.last_jumped = true;
                self.last_jump = Some(t - lt);
            }
        }
        self.prev = if glitch { None } else { self.last };
        self.last = Some((seq, t));
        Ok(())
    }

    /// Lone glitches gone over (see the module): frames admitted after one
    /// frame out of line in its `seq` or its `t`.
    pub fn glitches(&self) -> u64 {
        self.glitches
    }

    /// Gaps in `seq`, and the frames they lost.
    pub fn seq_gaps(&self) -> (u64, u64) {
        (self.gaps, self.lost)
    }
    /// Frames skipped: out of order, or with a `t` that is not a time.
    pub fn skipped(&self) -> u64 {
        self.skipped
    }
    /// Forward steps of `t` above the gap bound.
    pub fn jumps(&self) -> u64 {
        self.jumps
    }
    /// The step of `t` before the frame just admitted, when it was a jump.
    pub fn last_jump(&self) -> Option<f64> {
        self.last_jump
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn the_rule_case_by_case() {
        let mut o = FrameOrder::new(5.0);
        assert!(o.admit(10, 1.0).is_ok());
        assert!(o.admit(10, 1.2).unwrap_err().contains("repeats"));
        assert!(o.admit(9, 1.4).unwrap_err().contains("seq 9 after seq 10"));
        assert!(o.admit(11, 1.0).unwrap_err().contains("t = 1 after t = 1"));
        assert!(o.admit(11, 1e300).unwrap_err().contains("not a time"));
        assert!(o.admit(11, f64::NAN).is_err());
        assert_eq!(o.skipped(), 5);
        assert_eq!(o.seq_gaps(), (0, 0), "nothing skipped is lost");
        assert!(o.admit(14, 1.2).is_ok());
        assert_eq!(o.seq_gaps(), (1, 3));
        assert_eq!(o.last_jump(), None);
        assert!(o.admit(15, 61.2).is_ok());
        assert_eq!((o.jumps(), o.last_jump()), (1, Some(60.0)));
        assert!(o.admit(16, 61.4).is_ok());
        assert_eq!(o.last_jump(), None, "flag is for the frame just admitted");
        assert!(plausible_t(-1e10) && !plausible_t(1.0001e10));
    }

    proptest! {
        /// Whatever comes in, what is admitted strictly increases in both
        /// seq and t, and every frame is either admitted or counted.
        #[test]
        fn admitted_frames_increase(frames in prop::collection::vec((0u64..50, -1e3f64..1e3), 0..60)) {
            let mut o = FrameOrder::default();
            let mut kept: Vec<(u64, f64)> = Vec::new();
            for &(s, t) in &frames {
                if o.admit(s, t).is_ok() {
                    kept.push((s, t));
                }
            }
            prop_assert_eq!(kept.len() as u64 + o.skipped(), frames.len() as u64);
            let mut glitches = 0;
            for w in kept.windows(3) {
                if !(w[2].0 > w[1].0 && w[2].1 > w[1].1) {
                    // Only across a glitch, and in line with the one before.
                    prop_assert!(w[2].0 > w[0].0 && w[2].1 > w[0].1);
                    glitches += 1;
                }
            }
            if let [a, b, ..] = kept[..] {
                prop_assert!(b.0 > a.0 && b.1 > a.1);
            }
            prop_assert_eq!(glitches, o.glitches());
        }
    }

    /// One corrupt seq, then one corrupt t: each costs nothing after it,
    /// and the gap the corrupt seq claimed is taken back; a board reset
    /// (both back) still loses what follows.
    #[test]
    fn a_lone_glitch_costs_no_frame_after_it() {
        let mut o = FrameOrder::default();
        for (s, t) in [(1, 0.2), (2, 0.4), (500, 0.6), (4, 0.8), (5, 1.0)] {
            assert!(o.admit(s, t).is_ok(), "{s}");
        }
        assert_eq!(
            (o.glitches(), o.seq_gaps()),
            (1, (1, 1)),
            "3 is lost, not 497"
        );
        for (s, t) in [(6, 1e6), (7, 1.4), (8, 1.6)] {
            assert!(o.admit(s, t).is_ok(), "{s}");
        }
        assert_eq!(o.glitches(), 2);
        assert_eq!(o.skipped(), 0);
        assert!(o.admit(0, 0.0).is_err(), "a reset: both back");
        assert!(o.admit(1, 0.2).is_err());
    }
}
