//! Frames lost at the source, from the steps of `seq` between the frames
//! the engine gets, by the rule of core's `FrameOrder` (FORMATS.md): a
//! forward step by more than 1 is a gap, and a lone glitch — a frame that
//! claimed a gap, then a frame back in line with the one before the claim
//! — takes the claim back. One corrupt `seq` in a replayed log (500 among
//! 3, 4, 5) then costs no frame, where it used to count hundreds lost.
//!
//! The frame with the corrupt `seq` was acquired and used: it stands for
//! one of the frames between the ones around it, so it is not counted
//! lost (3, 500, 5: none lost; 3, 500, 7: two). Frames that failed to be
//! read are counted as failed, not again as lost.

/// What one frame's `seq` said.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Step {
    /// In line, a step back, or the first frame: nothing lost.
    InLine,
    /// `lost` frames skipped since `from`.
    Gap { from: u64, lost: u64 },
    /// `glitch` (the frame before) was a lone glitch: the `taken_back`
    /// frames its gap counted are not lost, and `lost` frames are, since
    /// the frame before the glitch.
    Glitch {
        glitch: u64,
        taken_back: u64,
        lost: u64,
    },
}

/// The `seq` bookkeeping between frames.
#[derive(Debug, Default)]
pub(super) struct SeqBooks {
    /// (seq, failures before it) of the last frame.
    last: Option<(u64, u64)>,
    /// The seq of the frame before `last` (none just after a glitch:
    /// once only, as in `FrameOrder`).
    before: Option<u64>,
    /// The frames `last`'s gap counted: what a glitch in `last` takes back.
    claimed: u64,
    /// Failures since the last good frame: a board's seq runs on through
    /// them, and they are already counted as failed, not as lost.
    failed_since_ok: u64,
}

impl SeqBooks {
    /// A frame failed to be read.
    pub(super) fn failed(&mut self) {
        self.failed_since_ok += 1;
    }

    /// The frame `seq` was acquired: what it says of frames lost.
    pub(super) fn admit(&mut self, seq: u64) -> Step {
        let failed = std::mem::take(&mut self.failed_since_ok);
        let mut step = Step::InLine;
        let mut glitch = false;
        if let (Some((ls, lfailed)), Some(b)) = (self.last, self.before) {
            if self.claimed > 0 && seq < ls && seq > b {
                // `ls` was the glitch; it stands for one of the frames
                // between `b` and `seq`.
                glitch = true;
                let lost = (seq - b - 1).saturating_sub(1 + lfailed + failed);
                step = Step::Glitch {
                    glitch: ls,
                    taken_back: self.claimed,
                    lost,
                };
                self.claimed = lost;
            }
        }
        if !glitch {
            self.claimed = 0;
            if let Some((ls, _)) = self.last {
                let lost = seq
                    .saturating_sub(ls.saturating_add(1))
                    .saturating_sub(failed);
                if lost > 0 {
                    step = Step::Gap { from: ls, lost };
                    self.claimed = lost;
                }
            }
        }
        self.before = if glitch {
            None
        } else {
            self.last.map(|(s, _)| s)
        };
        self.last = Some((seq, failed));
        step
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Frames lost in total after `seqs` (`None`: a failed read).
    fn lost_after(seqs: &[Option<u64>]) -> u64 {
        let mut b = SeqBooks::default();
        let mut lost = 0;
        for s in seqs {
            match s.map(|s| b.admit(s)) {
                None => b.failed(),
                Some(Step::InLine) => {}
                Some(Step::Gap { lost: n, .. }) => lost += n,
                Some(Step::Glitch {
                    taken_back,
                    lost: n,
                    ..
                }) => lost = lost - taken_back + n,
            }
        }
        lost
    }

    fn ok(seqs: &[u64]) -> Vec<Option<u64>> {
        seqs.iter().map(|&s| Some(s)).collect()
    }

    #[test]
    fn a_lone_corrupt_seq_costs_no_frame() {
        assert_eq!(lost_after(&ok(&[0, 1, 2, 3, 500, 5, 6, 7])), 0);
        assert_eq!(lost_after(&ok(&[0, 1, 2, 3, 500, 7, 8])), 2);
        // Once only: a step back right after a glitch takes nothing back
        // (the reader skips such a frame; here it is no glitch).
        assert_eq!(lost_after(&ok(&[1, 2, 500, 7, 5])), 3);
        // Two glitches apart are each taken back.
        assert_eq!(lost_after(&ok(&[1, 2, 500, 4, 5, 900, 7, 8])), 0);
    }

    #[test]
    fn gaps_failures_and_steps_back() {
        assert_eq!(lost_after(&ok(&[0, 1, 5, 6])), 3);
        // A real gap then a step back below the frame before it: no glitch.
        assert_eq!(lost_after(&ok(&[5, 6, 9, 2, 3])), 2);
        // Failed reads are not lost again, across a glitch either.
        assert_eq!(lost_after(&[Some(0), None, Some(2), Some(3)]), 0);
        assert_eq!(
            lost_after(&[Some(0), Some(1), None, Some(500), None, Some(5)]),
            0
        );
        assert_eq!(lost_after(&[]), 0);
    }

    #[test]
    fn the_step_says_where() {
        let mut b = SeqBooks::default();
        assert_eq!(b.admit(3), Step::InLine);
        assert_eq!(b.admit(4), Step::InLine);
        assert_eq!(b.admit(500), Step::Gap { from: 4, lost: 495 });
        assert_eq!(
            b.admit(6),
            Step::Glitch {
                glitch: 500,
                taken_back: 495,
                lost: 0
            }
        );
        assert_eq!(
            b.admit(u64::MAX),
            Step::Gap {
                from: 6,
                lost: u64::MAX - 7
            }
        );
    }
}
