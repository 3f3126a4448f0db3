//! Frame pacing: a source gives frames at its configured rate, on a fixed
//! schedule so that the rate does not drift with the time a read takes.

use std::thread;
use std::time::{Duration, Instant};

/// Sleeps until the next frame is due. `None` period: as fast as possible.
#[derive(Debug, Clone)]
pub struct Pacer {
    period: Option<Duration>,
    next: Option<Instant>,
}

impl Pacer {
    pub fn new(period: Option<Duration>) -> Self {
        Pacer { period, next: None }
    }

    pub fn from_rate(rate_hz: Option<f64>) -> Self {
        Self::new(rate_hz.map(|r| Duration::from_secs_f64(1.0 / r)))
    }

    pub fn period(&self) -> Option<Duration> {
        self.period
    }

    /// Block until the next frame is due. The first call returns at once. A
    /// source that fell more than a period behind (a slow read, a stall)
    /// restarts the schedule from now instead of bursting to catch up.
    pub fn wait(&mut self) {
        let Some(p) = self.period else { return };
        let now = Instant::now();
        let due = match self.next {
            None => now,
            Some(n) if n > now => {
                thread::sleep(n - now);
                n
            }
            Some(n) if now - n > p => now,
            Some(n) => n,
        };
        self.next = Some(due + p);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paces_at_the_rate_and_does_not_burst_after_a_stall() {
        let mut p = Pacer::from_rate(Some(200.0));
        let t0 = Instant::now();
        for _ in 0..5 {
            p.wait();
        }
        let el = t0.elapsed();
        // 4 periods of 5 ms after the first, immediate, frame
        assert!(el >= Duration::from_millis(20), "{el:?}");
        assert!(el < Duration::from_millis(200), "{el:?}");
        thread::sleep(Duration::from_millis(30));
        let t1 = Instant::now();
        p.wait(); // late: at once
        p.wait(); // then a full period, not a burst
        assert!(
            t1.elapsed() >= Duration::from_millis(4),
            "{:?}",
            t1.elapsed()
        );
        let mut fast = Pacer::from_rate(None);
        let t2 = Instant::now();
        for _ in 0..1000 {
            fast.wait();
        }
        assert!(t2.elapsed() < Duration::from_millis(50));
    }
}
