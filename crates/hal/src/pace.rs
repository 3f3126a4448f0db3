//! Frame pacing, and the stop request that ends every wait early.
//!
//! A source gives frames at its configured rate, on a fixed schedule so that
//! the rate does not drift with the time a read takes. Every sleep of a
//! source goes through [`Stop`], so that a stop (SIGTERM in the daemon) is
//! never held up by a frame that is not due yet: the waiting thread is woken
//! at once, not at the end of its sleep.
//!
//! A [`Stop`] also carries the waiting thread's sign of life: every wait
//! on it beats at least once a [`BEAT`] (and a source's own waits, such as
//! a serial port's, beat as they go), so that a thread that is alive and
//! waiting as configured — a frame due in 10 s, a board given a minute to
//! answer — is told apart from one stuck in a read that never returns.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

/// The longest a wait on a [`Stop`] goes without a beat.
pub const BEAT: Duration = Duration::from_secs(1);

/// A request to stop, shared by whoever asks (clones share one flag) and
/// the thread that waits; and that thread's heartbeat.
#[derive(Debug, Clone, Default)]
pub struct Stop(Arc<StopInner>);

#[derive(Debug)]
struct StopInner {
    raised: AtomicBool,
    lock: Mutex<()>,
    wake: Condvar,
    /// Base of `beat_ns`.
    epoch: Instant,
    /// Nanoseconds from `epoch` to the last beat.
    beat_ns: AtomicU64,
}

impl Default for StopInner {
    fn default() -> Self {
        StopInner {
            raised: AtomicBool::new(false),
            lock: Mutex::new(()),
            wake: Condvar::new(),
            epoch: Instant::now(),
            beat_ns: AtomicU64::new(0),
        }
    }
}

impl Stop {
    pub fn new() -> Self {
        Stop::default()
    }

    /// Ask to stop, and wake every wait on this stop.
    pub fn raise(&self) {
        self.0.raised.store(true, Ordering::SeqCst);
        // Under the lock, so that a waiter between its check and its wait
        // cannot miss the wake-up.
        let _g = self.0.lock.lock().unwrap_or_else(|p| p.into_inner());
        self.0.wake.notify_all();
    }

    #[inline]
    pub fn is_raised(&self) -> bool {
        self.0.raised.load(Ordering::Relaxed)
    }

    /// Say that the waiting thread is alive (no allocation, no lock).
    #[inline]
    pub fn beat(&self) {
        let ns = self.0.epoch.elapsed().as_nanos().min(u64::MAX as u128) as u64;
        self.0.beat_ns.fetch_max(ns, Ordering::Relaxed);
    }

    /// How long since the last beat (since the stop was made, before any).
    pub fn since_beat(&self) -> Duration {
        let at = Duration::from_nanos(self.0.beat_ns.load(Ordering::Relaxed));
        self.0.epoch.elapsed().saturating_sub(at)
    }

    /// Sleep until `deadline` unless a stop comes first; true when the
    /// deadline was reached, false when stopped. Beats at least once a
    /// [`BEAT`] meanwhile.
    pub fn sleep_until(&self, deadline: Instant) -> bool {
        let mut g = self.0.lock.lock().unwrap_or_else(|p| p.into_inner());
        loop {
            self.beat();
            if self.0.raised.load(Ordering::SeqCst) {
                return false;
            }
            let now = Instant::now();
            if now >= deadline {
                return true;
            }
            g = match self.0.wake.wait_timeout(g, (deadline - now).min(BEAT)) {
                Ok((g, _)) => g,
                Err(p) => p.into_inner().0,
            };
        }
    }

    /// Sleep `d` unless a stop comes first; true when slept whole.
    pub fn sleep(&self, d: Duration) -> bool {
        match Instant::now().checked_add(d) {
            Some(deadline) => self.sleep_until(deadline),
            None => {
                // A wait beyond the clock's range: until stopped.
                while self.sleep_until(Instant::now() + Duration::from_secs(3600)) {}
                false
            }
        }
    }
}

/// Sleeps until the next frame is due. `None` period: as fast as possible.
#[derive(Debug, Clone)]
pub struct Pacer {
    period: Option<Duration>,
    next: Option<Instant>,
    stop: Stop,
}

impl Pacer {
    pub fn new(period: Option<Duration>) -> Self {
        Pacer {
            period,
            next: None,
            stop: Stop::new(),
        }
    }

    pub fn from_rate(rate_hz: Option<f64>) -> Self {
        Self::new(rate_hz.and_then(|r| Duration::try_from_secs_f64(1.0 / r).ok()))
    }

    /// End waits early when `stop` is raised.
    pub fn stoppable(mut self, stop: Stop) -> Self {
        self.stop = stop;
        self
    }

    pub fn period(&self) -> Option<Duration> {
        self.period
    }

    /// Block until the next frame is due (or a stop). The first call
    /// returns at once. A source that fell more than a period behind (a slow
    /// read, a stall) restarts the schedule from now instead of bursting to
    /// catch up.
    pub fn wait(&mut self) {
        if let Some(until) = self.due() {
            self.stop.sleep_until(until);
        }
    }

    /// The schedule of [`Pacer::wait`] without its sleep: when the next
    /// frame is due, if that is later than now (the caller waits until
    /// then, as it likes: a serial bank listens to its ports meanwhile).
    pub fn due(&mut self) -> Option<Instant> {
        let p = self.period?;
        let now = Instant::now();
        let (due, wait) = match self.next {
            None => (now, None),
            Some(n) if n > now => (n, Some(n)),
            Some(n) if now - n > p => (now, None),
            Some(n) => (n, None),
        };
        self.next = Some(due + p);
        wait
    }

    /// The stop its waits end on.
    pub fn stop(&self) -> &Stop {
        &self.stop
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::thread;

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

    #[test]
    fn a_stop_ends_a_long_wait_at_once() {
        let stop = Stop::new();
        let mut p = Pacer::from_rate(Some(0.1)).stoppable(stop.clone()); // 10 s
        p.wait();
        let s = stop.clone();
        let raiser = thread::spawn(move || {
            thread::sleep(Duration::from_millis(50));
            s.raise();
        });
        let t0 = Instant::now();
        p.wait();
        let el = t0.elapsed();
        raiser.join().unwrap();
        assert!(el < Duration::from_secs(2), "{el:?}");
        assert!(stop.is_raised());
        assert!(!stop.sleep(Duration::from_secs(10)), "stopped: no sleep");
        assert!(Stop::new().sleep(Duration::from_millis(1)), "slept whole");
    }

    /// Audit: a frame due in 10 s left the frame thread silent for 10 s,
    /// and the daemon withheld the watchdog. A wait on the stop beats at
    /// least once a second; a thread stuck elsewhere does not.
    #[test]
    fn a_long_wait_beats_and_a_stuck_thread_does_not() {
        let stop = Stop::new();
        let mut p = Pacer::from_rate(Some(0.1)).stoppable(stop.clone()); // 10 s
        p.wait();
        let waiter = {
            let stop = stop.clone();
            thread::spawn(move || {
                p.wait();
                stop.is_raised()
            })
        };
        let t0 = Instant::now();
        let mut worst = Duration::ZERO;
        while t0.elapsed() < Duration::from_millis(2500) {
            worst = worst.max(stop.since_beat());
            thread::sleep(Duration::from_millis(20));
        }
        stop.raise();
        assert!(waiter.join().unwrap(), "the wait ended on the stop");
        assert!(worst < BEAT + Duration::from_millis(300), "{worst:?}");

        // Nothing waits on this one: its silence grows.
        let idle = Stop::new();
        idle.beat();
        thread::sleep(Duration::from_millis(60));
        assert!(idle.since_beat() >= Duration::from_millis(50));
        idle.beat();
        assert!(idle.since_beat() < Duration::from_millis(50));
    }
}
