//! Latency over the last minute, for STATUS: the whole-run quantiles of a
//! [`Histogram`] that has run for days hide a new slowdown. Each STATUS
//! takes the buckets' growth since the last one (sparse: the buckets that
//! grew), merged into slots of [`SLOT`]; slots that began more than
//! [`RECENT`] ago are dropped. Only the STATUS side runs this: the frame
//! thread still only increments a bucket and a max.

use super::{bucket_of_rank, edge_within, Histogram};
use std::collections::{BTreeMap, VecDeque};
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::sync::PoisonError;
use std::time::{Duration, Instant};

/// How far back the recent quantiles look.
pub const RECENT: Duration = Duration::from_secs(60);

/// Takes closer together than this share a slot, so a window holds at most
/// `RECENT / SLOT + 1` slots however often STATUS is made.
const SLOT: Duration = Duration::from_secs(5);

/// Latency of the samples recorded in the last `window_s` seconds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Recent {
    pub p50: Option<f64>,
    pub p99: Option<f64>,
    pub max: Option<f64>,
    /// How far back the samples go: [`RECENT`] once the daemon has run that
    /// long (a little less: slots start at a STATUS), more only when
    /// STATUS came less often than that.
    pub window_s: f64,
    pub count: u64,
}

/// The samples recorded from `start` to the next slot's start.
struct Slot {
    start: Instant,
    counts: BTreeMap<u32, u64>,
    max_ns: u64,
}

/// The recent slots of a [`Histogram`] and its counts at the last take.
pub(super) struct Window {
    prev: Vec<u64>,
    prev_at: Instant,
    slots: VecDeque<Slot>,
}

impl Window {
    pub(super) fn new() -> Window {
        Window {
            prev: Vec::new(),
            prev_at: Instant::now(),
            slots: VecDeque::new(),
        }
    }

    /// Add what `buckets` recorded since the last take (with `max_ns`, the
    /// largest sample since then) and drop what is too old.
    fn take(&mut self, buckets: &[AtomicU64], max_ns: u64, now: Instant) {
        if self.prev.len() != buckets.len() {
            self.prev = vec![0; buckets.len()];
        }
        let fresh = self
            .slots
            .back()
            .is_none_or(|s| now.saturating_duration_since(s.start) >= SLOT);
        if fresh {
            self.slots.push_back(Slot {
                start: self.prev_at,
                counts: BTreeMap::new(),
                max_ns: 0,
            });
        }
        let Some(slot) = self.slots.back_mut() else {
            return;
        };
        for (i, (b, prev)) in buckets.iter().zip(self.prev.iter_mut()).enumerate() {
            let n = b.load(Relaxed);
            if n > *prev {
                *slot.counts.entry(i as u32).or_default() += n - *prev;
                *prev = n;
            }
        }
        slot.max_ns = slot.max_ns.max(max_ns);
        self.prev_at = now;
        // The newest stays even if older than the window: it is all there is.
        if let Some(cutoff) = now.checked_sub(RECENT) {
            while self.slots.len() > 1 && self.slots.front().is_some_and(|s| s.start < cutoff) {
                self.slots.pop_front();
            }
        }
    }

    fn summary(&self, now: Instant) -> Recent {
        let mut counts: BTreeMap<u32, u64> = BTreeMap::new();
        for s in &self.slots {
            for (&i, &n) in &s.counts {
                *counts.entry(i).or_default() += n;
            }
        }
        let count: u64 = counts.values().sum();
        let max_ns = self.slots.iter().map(|s| s.max_ns).max().unwrap_or(0);
        let max = max_ns as f64 * 1e-9;
        let quantile = |q: f64| {
            let pairs = counts.iter().map(|(&i, &n)| (i as usize, n));
            bucket_of_rank(pairs, count, q).map(|i| edge_within(i, max))
        };
        let has = count > 0;
        let start = self.slots.front().map_or(self.prev_at, |s| s.start);
        Recent {
            p50: has.then(|| quantile(0.5)).flatten(),
            p99: has.then(|| quantile(0.99)).flatten(),
            max: has.then_some(max),
            window_s: now.saturating_duration_since(start).as_secs_f64(),
            count,
        }
    }
}

impl Histogram {
    /// Quantiles of the samples of the last [`RECENT`] (see [`Recent`]).
    pub fn recent(&self) -> Recent {
        self.recent_at(Instant::now())
    }

    /// As [`Histogram::recent`], at `now` (tests step the clock).
    pub fn recent_at(&self, now: Instant) -> Recent {
        let mut w = self.window.lock().unwrap_or_else(PoisonError::into_inner);
        // Taken before the buckets: a sample recorded in between has its
        // count in this take and its max in the next (one bucket's width).
        let max_ns = self.recent_max_ns.swap(0, Relaxed);
        w.take(&self.buckets, max_ns, now);
        w.summary(now)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Slow frames long ago and fast ones recently: the recent quantiles
    /// are the fast ones', the whole run's still show the slow.
    #[test]
    fn recent_quantiles_forget_old_slow_frames() {
        let h = Histogram::default();
        let t0 = Instant::now();
        let mut r = None;
        // A STATUS a second for two minutes; 50 ms frames in the first 10 s.
        for s in 0..120u64 {
            let d = if s < 10 {
                Duration::from_millis(50)
            } else {
                Duration::from_micros(30)
            };
            for _ in 0..5 {
                h.record(d);
            }
            r = Some(h.recent_at(t0 + Duration::from_secs(s + 1)));
        }
        let r = r.unwrap();
        assert!((r.p50.unwrap() - 30e-6).abs() < 1e-12, "{r:?}");
        assert!((r.p99.unwrap() - 30e-6).abs() < 1e-12, "{r:?}");
        assert!((r.max.unwrap() - 30e-6).abs() < 1e-12, "{r:?}");
        assert!((55.0..=60.0).contains(&r.window_s), "{r:?}");
        assert!(r.count >= 275 && r.count <= 300, "{r:?}");
        assert!((h.quantile(0.99).unwrap() - 0.05).abs() < 1e-12);
        // Early on the slow ones are recent: seen.
        let h = Histogram::default();
        h.record(Duration::from_millis(50));
        let r = h.recent_at(Instant::now() + Duration::from_secs(1));
        assert!((r.p99.unwrap() - 0.05).abs() < 1e-12, "{r:?}");
    }

    /// Nothing recorded lately: no quantiles; however often STATUS comes,
    /// the window keeps a bounded number of slots.
    #[test]
    fn an_idle_window_is_empty_and_bounded() {
        let h = Histogram::default();
        let t0 = Instant::now();
        h.record(Duration::from_micros(5));
        // Ten STATUS a second for 200 s; frames in the first 30 s.
        for k in 0..2000u64 {
            if k < 300 {
                h.record(Duration::from_micros(5 + k % 97));
            }
            h.recent_at(t0 + Duration::from_millis(k * 100));
        }
        let w = h.window.lock().unwrap();
        assert!(w.slots.len() <= 13, "{}", w.slots.len());
        drop(w);
        let r = h.recent_at(t0 + Duration::from_secs(200));
        assert_eq!((r.p50, r.p99, r.max, r.count), (None, None, None, 0));
        assert!(r.window_s <= 60.0, "{r:?}");
        assert_eq!(h.count(), 301);
    }
}
