//! Each measure of the counting allocator counts what it says, and only
//! that: a no-allocation test passing on a count that missed allocations
//! would prove nothing.

use lightpose_testkit::alloc::Counting;
use std::hint::black_box;
use std::sync::Mutex;

#[global_allocator]
static A: Counting = Counting::new();

/// `everywhere` and `peak_of` see every thread: one test at a time.
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

#[test]
fn this_thread_counts_this_threads_allocations_only() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|p| p.into_inner());
    let (v, n) = A.this_thread(|| black_box(Vec::<u8>::with_capacity(64)));
    assert_eq!(n, 1);
    let ((), n) = A.this_thread(|| {
        let mut v = black_box(v);
        v.reserve(4096); // a reallocation counts once
    });
    assert_eq!(n, 1);
    let ((), n) = A.this_thread(|| {
        std::thread::spawn(|| black_box(vec![0u8; 64]))
            .join()
            .unwrap();
    });
    assert!(n >= 1, "spawning allocates here");
    let spawned = std::thread::spawn(|| A.this_thread(|| black_box(vec![0u8; 64])).1);
    assert_eq!(spawned.join().unwrap(), 1);
}

#[test]
fn everywhere_counts_every_threads_allocations() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|p| p.into_inner());
    let t = std::thread::spawn(|| {
        std::thread::park();
        for _ in 0..100 {
            black_box(vec![0u8; 64]);
        }
    });
    let ((), n) = A.everywhere(|| {
        t.thread().unpark();
        t.join().unwrap();
    });
    assert!(n >= 100, "{n}");
}

#[test]
fn watched_counts_the_watched_threads_only() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|p| p.into_inner());
    let ((), n) = A.watched(|| {
        let watched = std::thread::spawn(|| {
            A.watch_this_thread();
            for _ in 0..10 {
                black_box(vec![0u8; 64]);
            }
        });
        watched.join().unwrap();
        for _ in 0..100 {
            black_box(vec![0u8; 64]);
        }
    });
    assert_eq!(n, 10);
}

#[test]
fn peak_of_is_the_most_held_at_once() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|p| p.into_inner());
    let ((), peak) = A.peak_of(|| {
        for _ in 0..10 {
            black_box(vec![0u8; 1 << 20]);
        }
    });
    assert!((1 << 20..2 << 20).contains(&peak), "{peak}");
    let (v, peak) = A.peak_of(|| {
        let mut v = black_box(Vec::<u8>::with_capacity(1 << 20));
        v.reserve_exact(4 << 20); // a reallocation to 4 MiB: its size held, not both
        v
    });
    assert_eq!(v.capacity(), 4 << 20);
    assert!((4 << 20..5 << 20).contains(&peak), "{peak}");
}
