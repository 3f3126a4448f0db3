//! The clock live board frames are stamped on: the machine's monotonic
//! clock, seconds since boot (Linux's CLOCK_MONOTONIC, which Rust's
//! `Instant` also reads).
//!
//! Why not seconds since the source was opened: a frame's `t` goes out as
//! MAVLink's `usec`, and an autopilot matches it against the times it has
//! seen before (ArduPilot's jitter correction keeps the least offset for
//! seconds). A `t` that starts over at 0 on every daemon restart looked
//! half a second old there for ~13 s after each restart; seconds since
//! boot go on across restarts and are what MAVLink allows `usec` to be.
//! The engine reads the same clock at a frame's arrival to know how long
//! before it the frame was captured ([`crate::FrameSource::t_is_monotonic`]).

/// Seconds since boot on CLOCK_MONOTONIC. A vDSO read on Linux: no system
/// call, no allocation.
#[cfg(unix)]
pub fn monotonic_s() -> f64 {
    use nix::time::{clock_gettime, ClockId};
    match clock_gettime(ClockId::CLOCK_MONOTONIC) {
        Ok(ts) => ts.tv_sec() as f64 + ts.tv_nsec() as f64 * 1e-9,
        // CLOCK_MONOTONIC cannot fail on Linux; should it, the process's
        // own monotonic seconds still give one increasing timeline.
        Err(_) => fallback_s(),
    }
}

/// Seconds on a monotonic clock (elsewhere than unix: since the first
/// call in this process, not since boot).
#[cfg(not(unix))]
pub fn monotonic_s() -> f64 {
    fallback_s()
}

fn fallback_s() -> f64 {
    static START: std::sync::OnceLock<std::time::Instant> = std::sync::OnceLock::new();
    START
        .get_or_init(std::time::Instant::now)
        .elapsed()
        .as_secs_f64()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn monotonic_seconds_increase_and_follow_instant() {
        let (a, i0) = (monotonic_s(), std::time::Instant::now());
        std::thread::sleep(std::time::Duration::from_millis(20));
        let (b, di) = (monotonic_s(), i0.elapsed().as_secs_f64());
        assert!(a > 0.0 && b > a, "{a} {b}");
        // The two clocks tick together (same clock on Linux); the bound
        // is the scheduler's, between two reads on a loaded CI machine.
        assert!((b - a - di).abs() < 20e-3, "{} vs {di}", b - a);
    }
}
