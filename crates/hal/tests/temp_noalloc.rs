//! A DS18B20 that keeps failing costs no allocation a frame: the frame
//! gets the fallback, and the failure's text is kept once, not cloned from
//! the watcher on every frame. A counting global allocator shows it.

use lightpose_hal::temp::{write_fake_w1, Ds18b20, Ds18b20Watcher, TempKind, TempReader};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::Relaxed};
use std::time::{Duration, Instant};

struct Counting;
static ALLOCS: AtomicU64 = AtomicU64::new(0);
static COUNTING: AtomicBool = AtomicBool::new(false);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        if COUNTING.load(Relaxed) {
            ALLOCS.fetch_add(1, Relaxed);
        }
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        unsafe { System.dealloc(p, l) }
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, n: usize) -> *mut u8 {
        if COUNTING.load(Relaxed) {
            ALLOCS.fetch_add(1, Relaxed);
        }
        unsafe { System.realloc(p, l, n) }
    }
}

#[global_allocator]
static A: Counting = Counting;

const BADCRC: &str = "72 01 4b 46 7f ff 0e 10 57 : crc=12 NO\n72 01 4b 46 7f ff 0e 10 57 t=23125\n";

/// Audit: `Ds18b20Watcher::latest` cloned the error (its path, a String)
/// for every frame while the sensor kept failing.
#[test]
fn a_failing_ds18b20_does_not_allocate_per_frame() {
    let dir = tempfile::tempdir().expect("tempdir");
    write_fake_w1(dir.path(), "28-aa", BADCRC).expect("fake sensor");
    // Read once, then not for an hour: its thread allocates nothing more.
    let w = Ds18b20Watcher::spawn(
        Ds18b20 {
            root: dir.path().to_path_buf(),
            device: None,
        },
        Duration::from_secs(3600),
        Duration::from_secs(5),
    );
    let t0 = Instant::now();
    while w.reads() < 1 {
        assert!(t0.elapsed() < Duration::from_secs(5), "never read");
        std::thread::sleep(Duration::from_millis(5));
    }
    let mut r = TempReader::new(TempKind::Ds18b20(w), 19.5);
    let mut frames = |n: u32| {
        ALLOCS.store(0, Relaxed);
        COUNTING.store(true, Relaxed);
        for _ in 0..n {
            assert_eq!(r.for_frame(&[]), Some(19.5));
        }
        COUNTING.store(false, Relaxed);
        ALLOCS.load(Relaxed)
    };
    let first = frames(1);
    assert!(first > 0, "the failure's text is kept once");
    let more = frames(1000);
    assert_eq!(more, 0, "1000 frames of the same failure");
    let h = r.health();
    assert!(h.fallback_active && h.fallbacks == 1001, "{h:?}");
    assert!(
        h.last_error.as_deref().is_some_and(|e| e.contains("CRC")),
        "{h:?}"
    );
}
