//! A latest-value cell between the I/O tasks and the frame thread: written
//! from the tokio side, read once per frame, with neither a lock nor an
//! allocation on either side, so the frame thread can never wait on a
//! receiver (a sequence lock over atomic words).
//!
//! A writer makes the sequence number odd, stores the words and makes it
//! even again; a reader takes a copy between two equal even sequence
//! numbers. A reader that keeps meeting a writer gives up after a bounded
//! number of tries and reports nothing rather than spin: the frame then
//! simply lacks that reading.

use std::hint::spin_loop;
use std::sync::atomic::{fence, AtomicU64, Ordering};

/// Tries before a reader gives up (each costs a few nanoseconds; a writer
/// holds the cell for about as long).
const READ_TRIES: u32 = 64;

/// The latest `N` words written, with a version that counts the writes.
pub struct Latest<const N: usize> {
    seq: AtomicU64,
    words: [AtomicU64; N],
}

impl<const N: usize> Default for Latest<N> {
    fn default() -> Self {
        Latest {
            seq: AtomicU64::new(0),
            words: std::array::from_fn(|_| AtomicU64::new(0)),
        }
    }
}

impl<const N: usize> Latest<N> {
    /// Replace the value. Writers exclude each other (a short spin), so
    /// two receivers may share a cell.
    pub fn store(&self, vals: [u64; N]) {
        let mut s = self.seq.load(Ordering::Relaxed);
        loop {
            if s & 1 == 1 {
                spin_loop();
                s = self.seq.load(Ordering::Relaxed);
                continue;
            }
            match self
                .seq
                .compare_exchange_weak(s, s + 1, Ordering::Acquire, Ordering::Relaxed)
            {
                Ok(_) => break,
                Err(now) => s = now,
            }
        }
        fence(Ordering::Release);
        for (w, v) in self.words.iter().zip(vals) {
            w.store(v, Ordering::Relaxed);
        }
        self.seq.store(s + 2, Ordering::Release);
    }

    /// The latest value and its version (the number of writes so far), or
    /// `None` if nothing was ever written or a writer kept the cell busy.
    pub fn load(&self) -> Option<(u64, [u64; N])> {
        for _ in 0..READ_TRIES {
            let s1 = self.seq.load(Ordering::Acquire);
            if s1 == 0 {
                return None;
            }
            if s1 & 1 == 1 {
                spin_loop();
                continue;
            }
            let vals: [u64; N] = std::array::from_fn(|i| self.words[i].load(Ordering::Relaxed));
            fence(Ordering::Acquire);
            if self.seq.load(Ordering::Relaxed) == s1 {
                return Some((s1 / 2, vals));
            }
        }
        None
    }

    /// The number of writes so far (0: never written).
    pub fn version(&self) -> u64 {
        self.seq.load(Ordering::Acquire) / 2
    }
}

/// An optional number as a word: absent is a NaN pattern that never leaves
/// this crate (`opt` turns it back into `None`).
#[inline]
pub(crate) fn word(v: Option<f64>) -> u64 {
    v.unwrap_or(f64::NAN).to_bits()
}

#[inline]
pub(crate) fn opt(w: u64) -> Option<f64> {
    let v = f64::from_bits(w);
    v.is_finite().then_some(v)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    #[test]
    fn empty_then_latest_value_with_its_version() {
        let c = Latest::<2>::default();
        assert!(c.load().is_none());
        c.store([1, 2]);
        c.store([3, 4]);
        assert_eq!(c.load(), Some((2, [3, 4])));
        assert_eq!(c.version(), 2);
        assert_eq!(opt(word(None)), None);
        assert_eq!(opt(word(Some(0.5))), Some(0.5));
    }

    #[test]
    fn readers_never_see_a_torn_value() {
        // Two writers store pairs (k, !k); a reader must only ever see
        // matching halves.
        let c = Arc::new(Latest::<4>::default());
        let stop = Arc::new(std::sync::atomic::AtomicBool::new(false));
        let writers: Vec<_> = (0..2u64)
            .map(|w| {
                let (c, stop) = (c.clone(), stop.clone());
                std::thread::spawn(move || {
                    let mut k = w;
                    while !stop.load(Ordering::Relaxed) {
                        c.store([k, !k, k.wrapping_mul(3), k ^ 0xABCD]);
                        k += 2;
                    }
                })
            })
            .collect();
        // Wait for the first store: on a loaded machine the writers may not
        // have run yet, and the reads below must overlap their writes.
        let t0 = std::time::Instant::now();
        while c.version() == 0 {
            assert!(t0.elapsed().as_secs() < 30, "no writer ran in 30 s");
            std::thread::yield_now();
        }
        let mut seen = 0;
        for _ in 0..200_000 {
            if let Some((_, [a, b, m, x])) = c.load() {
                assert_eq!(b, !a);
                assert_eq!(m, a.wrapping_mul(3));
                assert_eq!(x, a ^ 0xABCD);
                seen += 1;
            }
        }
        stop.store(true, Ordering::Relaxed);
        for w in writers {
            w.join().unwrap();
        }
        assert!(seen > 0);
    }
}
