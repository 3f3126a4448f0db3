//! A counting global allocator, for the tests that show a path does not
//! allocate (per frame, per message) or holds a bounded heap. A test binary
//! installs it once:
//!
//! ```
//! use lightpose_testkit::alloc::Counting;
//! #[global_allocator]
//! static A: Counting = Counting::new();
//!
//! fn main() {
//!     let (v, n) = A.this_thread(|| std::hint::black_box(Vec::<u8>::with_capacity(64)));
//!     assert_eq!((v.capacity(), n), (64, 1));
//! }
//! ```
//!
//! and measures a closure with the count that fits what it asserts:
//! [`Counting::this_thread`] (tests of a binary run side by side, so a
//! thread's own count is the one that is not blurred), [`Counting::everywhere`]
//! (a path that spreads over threads; the binary's tests must then run one
//! at a time), [`Counting::watched`] (threads that said
//! [`Counting::watch_this_thread`], e.g. a task's own thread) and
//! [`Counting::peak_of`] (heap bytes held at most).
//!
//! Every count runs all the time; a measure is the difference over the
//! closure. A reallocation counts as one allocation (as the default
//! `realloc`, an `alloc` and a copy, would).

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering::Relaxed};

thread_local! {
    // `const` and `Cell`: no lazy initialisation and no destructor, so that
    // reaching them from inside the allocator neither allocates nor
    // recurses. `try_with` below: a thread being torn down still allocates.
    static HERE: Cell<u64> = const { Cell::new(0) };
    static WATCHED: Cell<bool> = const { Cell::new(false) };
}

/// The allocator: the system's, counting allocations (all threads, this
/// thread, watched threads) and the bytes in use and their peak.
pub struct Counting {
    allocs: AtomicU64,
    watched: AtomicU64,
    in_use: AtomicUsize,
    peak: AtomicUsize,
}

impl Counting {
    pub const fn new() -> Self {
        Counting {
            allocs: AtomicU64::new(0),
            watched: AtomicU64::new(0),
            in_use: AtomicUsize::new(0),
            peak: AtomicUsize::new(0),
        }
    }

    /// Allocations by every thread of the process while `f` runs.
    pub fn everywhere<T>(&self, f: impl FnOnce() -> T) -> (T, u64) {
        let before = self.allocs.load(Relaxed);
        let out = f();
        (out, self.allocs.load(Relaxed) - before)
    }

    /// Allocations by the calling thread while `f` runs.
    pub fn this_thread<T>(&self, f: impl FnOnce() -> T) -> (T, u64) {
        let before = HERE.with(Cell::get);
        let out = f();
        (out, HERE.with(Cell::get) - before)
    }

    /// From now on the calling thread's allocations count in
    /// [`Counting::watched`].
    pub fn watch_this_thread(&self) {
        WATCHED.with(|w| w.set(true));
    }

    /// Allocations by the watched threads while `f` runs.
    pub fn watched<T>(&self, f: impl FnOnce() -> T) -> (T, u64) {
        let before = self.watched.load(Relaxed);
        let out = f();
        (out, self.watched.load(Relaxed) - before)
    }

    /// The most heap in use (every thread's) while `f` runs, above what
    /// was in use when it started. One measure at a time in a binary.
    pub fn peak_of<T>(&self, f: impl FnOnce() -> T) -> (T, usize) {
        let before = self.in_use.load(Relaxed);
        self.peak.store(before, Relaxed);
        let out = f();
        (out, self.peak.load(Relaxed).saturating_sub(before))
    }

    fn counted(&self) {
        self.allocs.fetch_add(1, Relaxed);
        let _ = HERE.try_with(|c| c.set(c.get() + 1));
        if WATCHED.try_with(Cell::get).unwrap_or(false) {
            self.watched.fetch_add(1, Relaxed);
        }
    }

    fn grew(&self, by: usize) {
        let now = self.in_use.fetch_add(by, Relaxed) + by;
        self.peak.fetch_max(now, Relaxed);
    }
}

impl Default for Counting {
    fn default() -> Self {
        Counting::new()
    }
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        self.counted();
        self.grew(l.size());
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        self.in_use.fetch_sub(l.size(), Relaxed);
        unsafe { System.dealloc(p, l) }
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, n: usize) -> *mut u8 {
        self.counted();
        if n >= l.size() {
            self.grew(n - l.size());
        } else {
            self.in_use.fetch_sub(l.size() - n, Relaxed);
        }
        unsafe { System.realloc(p, l, n) }
    }
}
