//! A bounded single-producer single-consumer ring, its slots allocated
//! once: the frame thread's hand-off to a thread that polls it (the ROS 2
//! node). A channel whose receiver blocks makes every send wake it (a
//! futex, ~10 µs on the frame thread, docs/ros2.md); here a push is two
//! atomic loads, a copy, a release store and a fence, and the consumer is
//! woken only from a long sleep ([`Consumer::wait`]): it polls where an
//! item is due ([`Cadence`]), so in step nobody is woken, and an item that
//! comes early or late waits for no sleep of the consumer's (those waits
//! were capture → wire p99 1.1–2 ms on loopback).
//!
//! Only `Copy` items: a slot is overwritten without a drop, and the items
//! left when both ends go need none.

use std::cell::UnsafeCell;
use std::mem::MaybeUninit;
use std::sync::atomic::{fence, AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, OnceLock};
use std::thread::Thread;
use std::time::{Duration, Instant};

/// Keeps the two indices on cache lines of their own: the producer's
/// stores must not invalidate the consumer's line at each push.
#[repr(align(64))]
struct Padded(AtomicUsize);

struct Ring<T> {
    slots: Box<[UnsafeCell<MaybeUninit<T>>]>,
    /// Items taken so far (written by the consumer only).
    head: Padded,
    /// Items put so far (written by the producer only).
    tail: Padded,
    /// Raised when the producer is dropped: the consumer ends once empty.
    closed: AtomicBool,
    /// Raised while the consumer is in a long sleep: a push wakes it.
    parked: AtomicBool,
    /// The consumer's thread, set at its first long sleep.
    consumer: OnceLock<Thread>,
}

// SAFETY: a slot is written only by the producer while it is outside
// head..tail and read only by the consumer while it is inside; the Release
// store of `tail` after the write and its Acquire load before the read
// (and the same for `head` the other way) order the accesses, so no slot
// is ever touched by both threads at once. T: Send moves the items across.
unsafe impl<T: Copy + Send> Sync for Ring<T> {}
unsafe impl<T: Copy + Send> Send for Ring<T> {}

/// The putting end (one thread).
pub struct Producer<T> {
    ring: Arc<Ring<T>>,
    /// `tail` as this end last wrote it (nobody else writes it).
    tail: usize,
    /// `head` as last read: refreshed only when the ring looks full.
    head: usize,
}

/// The taking end (one thread).
pub struct Consumer<T> {
    ring: Arc<Ring<T>>,
    head: usize,
    /// `tail` as last read: refreshed only when the ring looks empty.
    tail: usize,
}

/// A ring of `capacity` items (at least 1), allocated here, never again.
pub fn ring<T: Copy + Send>(capacity: usize) -> (Producer<T>, Consumer<T>) {
    let cap = capacity.max(1);
    let slots = (0..cap)
        .map(|_| UnsafeCell::new(MaybeUninit::uninit()))
        .collect();
    let ring = Arc::new(Ring {
        slots,
        head: Padded(AtomicUsize::new(0)),
        tail: Padded(AtomicUsize::new(0)),
        closed: AtomicBool::new(false),
        parked: AtomicBool::new(false),
        consumer: OnceLock::new(),
    });
    (
        Producer {
            ring: ring.clone(),
            tail: 0,
            head: 0,
        },
        Consumer {
            ring,
            head: 0,
            tail: 0,
        },
    )
}

impl<T: Copy + Send> Producer<T> {
    /// Put `v`, or give it back if the ring is full. Never blocks, never
    /// allocates; wakes the consumer only out of a long sleep.
    #[inline]
    pub fn push(&mut self, v: T) -> Result<(), T> {
        let cap = self.ring.slots.len();
        if self.tail.wrapping_sub(self.head) == cap {
            self.head = self.ring.head.0.load(Ordering::Acquire);
            if self.tail.wrapping_sub(self.head) == cap {
                return Err(v);
            }
        }
        let slot = &self.ring.slots[self.tail % cap];
        // SAFETY: tail − head < cap, so this slot is not in head..tail:
        // the consumer does not read it until the store below.
        unsafe { (*slot.get()).write(v) };
        self.tail = self.tail.wrapping_add(1);
        self.ring.tail.0.store(self.tail, Ordering::Release);
        self.ring.wake();
        Ok(())
    }
}

impl<T> Ring<T> {
    /// Wake the consumer if it is in a long sleep. The fence pairs with
    /// the consumer's in [`Consumer::wait`]: either it sees this push
    /// before it sleeps, or this sees it parked.
    #[inline]
    fn wake(&self) {
        fence(Ordering::SeqCst);
        if self.parked.load(Ordering::Relaxed) && self.parked.swap(false, Ordering::Relaxed) {
            if let Some(t) = self.consumer.get() {
                t.unpark();
            }
        }
    }
}

impl<T> Drop for Producer<T> {
    fn drop(&mut self) {
        self.ring.closed.store(true, Ordering::Release);
        self.ring.wake();
    }
}

impl<T: Copy + Send> Consumer<T> {
    /// The oldest item, if any.
    #[inline]
    pub fn pop(&mut self) -> Option<T> {
        if self.head == self.tail {
            self.tail = self.ring.tail.0.load(Ordering::Acquire);
            if self.head == self.tail {
                return None;
            }
        }
        let cap = self.ring.slots.len();
        let slot = &self.ring.slots[self.head % cap];
        // SAFETY: head < tail (Acquire above): the producer wrote this slot
        // and will not write it again until `head` passes it.
        let v = unsafe { (*slot.get()).assume_init_read() };
        self.head = self.head.wrapping_add(1);
        self.ring.head.0.store(self.head, Ordering::Release);
        Some(v)
    }

    /// True once the producer is gone (items may still wait: pop them).
    pub fn producer_gone(&self) -> bool {
        self.ring.closed.load(Ordering::Acquire)
    }

    /// Sleep `d` (the ring found empty). A sleep longer than
    /// [`Cadence::FINE`] ends at the next push or the producer's end: the
    /// producer pays a wake-up only for an item that finds the consumer
    /// there (early or late for its cadence), never for one that comes in
    /// step. True when a push (or the end) woke it.
    pub fn wait(&mut self, d: Duration) -> bool {
        if d <= Cadence::FINE {
            std::thread::sleep(d);
            return false;
        }
        let r = &self.ring;
        r.consumer.get_or_init(std::thread::current);
        r.parked.store(true, Ordering::Relaxed);
        fence(Ordering::SeqCst);
        let came = r.tail.0.load(Ordering::Acquire) != self.head;
        if !came && !r.closed.load(Ordering::Acquire) {
            std::thread::park_timeout(d);
        }
        // Lowered already: the producer lowered it to wake this thread.
        !r.parked.swap(false, Ordering::Relaxed)
    }
}

/// When a polling consumer should look next. Items come at a cadence
/// (the frame rate): it sleeps until a little before the next is due, then
/// looks often until it comes, and seldom when nothing is due, so that an
/// item waits little without the producer waking anyone and without the
/// consumer waking thousands of times a second for nothing.
#[derive(Debug, Clone, Copy)]
pub struct Cadence {
    last: Option<Instant>,
    /// The items' period (a running mean of the gaps under [`Cadence::IDLE_GAP`]).
    period: Option<Duration>,
}

impl Default for Cadence {
    fn default() -> Self {
        Self::new()
    }
}

impl Cadence {
    /// How often to look around the due moment.
    pub const FINE: Duration = Duration::from_micros(100);
    /// Looking this long before the due moment, and this long after it.
    /// Early by 2 ms: a long sleep here may end a millisecond or more late
    /// (a VM's timers, a busy core), and an item that finds the consumer
    /// still asleep costs the producer a wake-up (~15 µs). Measured
    /// (`examples/ros2_cost`, 2000 estimates at 200 Hz, five runs each):
    /// 300 µs woke the node for 5–10 % of the items, the frame thread's
    /// p99 14–20 µs; 1 ms 0.3–0.8 %, p99 2.0–3.9 µs; 2 ms 0.1–0.3 %, p99
    /// 1.4–1.9 µs. Polling 2.7 ms of each period every 100 µs costs the
    /// node's thread ~27 short wake-ups a frame.
    pub const EARLY: Duration = Duration::from_micros(2000);
    pub const LATE: Duration = Duration::from_micros(700);
    /// How often to look when nothing is due (the cadence unknown, or
    /// broken: a stalled source).
    pub const SLOW: Duration = Duration::from_micros(500);
    /// Gaps longer than this are a pause, not the period.
    pub const IDLE_GAP: Duration = Duration::from_secs(1);
    /// The longest sleep, so that other work (STATUS) is seen.
    pub const MAX_SLEEP: Duration = Duration::from_millis(20);

    pub const fn new() -> Self {
        Cadence {
            last: None,
            period: None,
        }
    }

    /// An item came at `now`.
    pub fn came(&mut self, now: Instant) {
        if let Some(l) = self.last {
            let gap = now.saturating_duration_since(l);
            if gap < Self::IDLE_GAP {
                // A mean over ~8 gaps: jitter smoothed, a new rate learnt.
                self.period = Some(match self.period {
                    Some(p) => (p * 7 + gap) / 8,
                    None => gap,
                });
            }
        }
        self.last = Some(now);
    }

    /// How long to sleep at `now`, having found nothing.
    pub fn sleep(&self, now: Instant) -> Duration {
        let (Some(last), Some(period)) = (self.last, self.period) else {
            return Self::SLOW;
        };
        let due = last + period;
        let from = due.checked_sub(Self::EARLY).unwrap_or(due);
        if now < from {
            (from - now).min(Self::MAX_SLEEP)
        } else if now < due + Self::LATE {
            Self::FINE
        } else {
            Self::SLOW
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_push_ends_a_long_wait_and_a_short_one_is_slept() {
        let (mut p, mut c) = ring::<u32>(4);
        let t = std::thread::spawn(move || {
            let t0 = Instant::now();
            // A long wait: the push below (after 50 ms) ends it.
            let woken = c.wait(Duration::from_secs(10));
            let waited = t0.elapsed();
            (c.pop(), waited, woken)
        });
        std::thread::sleep(Duration::from_millis(50));
        assert_eq!(p.push(7), Ok(()));
        let (got, waited, woken) = t.join().expect("consumer");
        assert_eq!(got, Some(7));
        assert!(woken, "the push woke it");
        assert!(
            waited < Duration::from_secs(5),
            "woken, not timed out: {waited:?}"
        );
        // The producer's end wakes a waiting consumer too.
        let (p, mut c) = ring::<u32>(1);
        let t = std::thread::spawn(move || {
            while !c.producer_gone() {
                c.wait(Duration::from_secs(10));
            }
        });
        std::thread::sleep(Duration::from_millis(20));
        drop(p);
        t.join().expect("consumer ends");
        // A short wait is a plain sleep: nobody wakes it.
        let (_p, mut c) = ring::<u32>(1);
        assert!(!c.wait(Cadence::FINE));
    }

    #[test]
    fn full_gives_the_item_back_and_order_is_kept() {
        let (mut p, mut c) = ring::<u32>(3);
        assert_eq!((p.push(1), p.push(2), p.push(3)), (Ok(()), Ok(()), Ok(())));
        assert_eq!(p.push(4), Err(4));
        assert_eq!(c.pop(), Some(1));
        assert_eq!(p.push(5), Ok(()));
        assert_eq!(
            (c.pop(), c.pop(), c.pop(), c.pop()),
            (Some(2), Some(3), Some(5), None)
        );
        assert!(!c.producer_gone());
        drop(p);
        assert!(c.producer_gone());
    }

    #[test]
    fn the_cadence_sleeps_until_the_next_item_is_nearly_due() {
        let mut c = Cadence::new();
        let t0 = Instant::now();
        assert_eq!(c.sleep(t0), Cadence::SLOW, "no cadence yet");
        let ms = Duration::from_millis;
        for i in 0..10 {
            c.came(t0 + ms(5) * i);
        }
        let last = t0 + ms(45);
        // Just after an item: asleep until 300 µs before the next.
        assert_eq!(c.sleep(last + ms(1)), ms(4) - Cadence::EARLY);
        // Around the due moment: often.
        assert_eq!(c.sleep(last + ms(5)), Cadence::FINE);
        // Long past it: seldom.
        assert_eq!(c.sleep(last + ms(7)), Cadence::SLOW);
        // A pause is no period; a slow rate sleeps at most MAX_SLEEP.
        let mut slow = Cadence::new();
        slow.came(t0);
        slow.came(t0 + ms(200));
        assert_eq!(slow.sleep(t0 + ms(201)), Cadence::MAX_SLEEP);
    }

    #[test]
    fn two_threads_see_every_item_once_in_order() {
        // Items of several words: a torn read would show as a mismatch.
        let (mut p, mut c) = ring::<[u64; 8]>(4);
        const N: u64 = 200_000;
        let t = std::thread::spawn(move || {
            let mut dropped = 0u64;
            for i in 0..N {
                if p.push([i; 8]).is_err() {
                    dropped += 1;
                }
            }
            dropped
        });
        let (mut got, mut last) = (0u64, None::<u64>);
        let mut see = |v: [u64; 8]| {
            assert!(v.iter().all(|&w| w == v[0]), "torn: {v:?}");
            assert!(last.is_none_or(|l| v[0] > l), "out of order");
            last = Some(v[0]);
            got += 1;
        };
        loop {
            match c.pop() {
                Some(v) => see(v),
                None if c.producer_gone() => {
                    // Pushed before the close: seen after its Acquire.
                    while let Some(v) = c.pop() {
                        see(v);
                    }
                    break;
                }
                None => std::hint::spin_loop(),
            }
        }
        let dropped = t.join().expect("producer");
        assert_eq!(got + dropped, N);
        assert!(got > 0);
    }
}
