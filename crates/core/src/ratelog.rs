//! Logging of events that can come every frame (late, failed or lost
//! frames in the daemon, poses the MAVLink sender skips): visible, not
//! flooding. One rule for every crate that logs such events.

use std::time::{Duration, Instant};

/// Logs the first event of a kind, then at most one line a second with the
/// count since.
#[derive(Debug, Clone, Copy, Default)]
pub struct RateLog {
    last: Option<Instant>,
    suppressed: u64,
}

impl RateLog {
    pub const fn new() -> Self {
        RateLog {
            last: None,
            suppressed: 0,
        }
    }

    /// `Some(n)` when a line should be written now, n = events folded in.
    pub fn tick(&mut self, now: Instant) -> Option<u64> {
        match self.last {
            Some(t) if now.duration_since(t) < Duration::from_secs(1) => {
                self.suppressed += 1;
                None
            }
            _ => {
                self.last = Some(now);
                let n = self.suppressed + 1;
                self.suppressed = 0;
                Some(n)
            }
        }
    }
}
