use super::*;
use crate::chanmap::ChannelMap;
use crate::pace::Pacer;
use crate::temp::TempKind;
use crate::temp::TempReader;
use crate::FrameSource;
use std::time::Duration;

/// One board whose read takes `read` (a sleep).
struct SlowBank {
    read: Duration,
}

impl Bank for SlowBank {
    fn boards(&self) -> Vec<BoardSpec> {
        vec![BoardSpec {
            name: "slow".into(),
            channels: 16,
        }]
    }
    fn bits(&self) -> u8 {
        12
    }
    fn describe(&self) -> String {
        "slow".into()
    }
    fn read(&mut self, _: &[u16], _: &mut [RawBoard]) -> Result<(), SourceError> {
        std::thread::sleep(self.read);
        Ok(())
    }
}

/// CLOCK_MONOTONIC read here, not through the code under test.
fn since_boot() -> f64 {
    let ts = nix::time::clock_gettime(nix::time::ClockId::CLOCK_MONOTONIC).unwrap();
    ts.tv_sec() as f64 + ts.tv_nsec() as f64 * 1e-9
}

fn slow_source(read: Duration) -> BoardSource<SlowBank> {
    BoardSource::new(
        SlowBank { read },
        ChannelMap::sequential(16),
        TempReader::new(TempKind::None, 0.0),
        Pacer::new(None),
    )
}

/// Audit: board frames had no period, so the daemon never judged them
/// late (a 5 s stop showed only as fps). The pace read at is theirs.
#[test]
fn a_paced_board_source_has_its_period() {
    assert_eq!(slow_source(Duration::ZERO).period(), None);
    let paced = BoardSource::new(
        SlowBank {
            read: Duration::ZERO,
        },
        ChannelMap::sequential(16),
        TempReader::new(TempKind::None, 0.0),
        Pacer::from_rate(Some(20.0)),
    );
    assert_eq!(paced.period(), Some(Duration::from_millis(50)));
    assert_eq!(paced.rate_hz(), Some(20.0));
}

/// The middle of the read, on CLOCK_MONOTONIC (seconds since boot).
#[test]
fn a_frame_is_stamped_at_the_middle_of_its_read() {
    let read = Duration::from_millis(60);
    let mut src = slow_source(read);
    assert!(src.t_is_monotonic());
    let called = since_boot();
    let f = src.next_frame().unwrap();
    let returned = since_boot();
    // The read starts after `called` and ends before `returned`, and
    // lasts at least `read`: its middle is at least read / 2 after
    // `called` and read / 2 before `returned`.
    let half = read.as_secs_f64() / 2.0;
    let (lo, hi) = (called + half, returned - half);
    assert!(
        f.t >= lo - 1e-6 && f.t <= hi + 1e-6,
        "{lo} <= {} <= {hi}",
        f.t
    );
}

/// Audit: `t` counted from when the source was made, so every daemon
/// restart started MAVLink's `usec` at 0 again. Two sources made 50 ms
/// apart now stamp one timeline.
#[test]
fn sources_made_apart_stamp_one_timeline() {
    let read = Duration::from_millis(5);
    let mut a = slow_source(read);
    let fa = a.next_frame().unwrap();
    std::thread::sleep(Duration::from_millis(50));
    let mut b = slow_source(read);
    let fb = b.next_frame().unwrap();
    let now = since_boot();
    assert!(fb.t - fa.t >= 0.050, "{} then {}", fa.t, fb.t);
    assert!(fb.t <= now && now - fb.t < 10.0, "{} at {now}", fb.t);
    // And the first source goes on on the same timeline.
    let fa2 = a.next_frame().unwrap();
    assert!(fa2.t > fb.t, "{} after {}", fa2.t, fb.t);
}

#[test]
fn a_channel_the_chip_lacks_is_bad_data_not_a_bus_error() {
    let r = &mut Recent::default();
    let e = bus_error(
        &"board u0 channel 9".into(),
        DriverError::<embedded_hal::i2c::ErrorKind>::NoChannel { ch: 9, max: 8 },
        r,
    );
    assert!(
        matches!(&e, SourceError::BadData { place, msg } if place == "board u0 channel 9" && msg.contains("no channel 9")),
        "{e:?}"
    );
    let e = bus_error(
        &"x".into(),
        DriverError::Bus(embedded_hal::i2c::ErrorKind::Other),
        r,
    );
    assert!(matches!(e, SourceError::Bus { .. }), "{e:?}");
    let e = bus_error(
        &"x".into(),
        DriverError::<embedded_hal::i2c::ErrorKind>::NotReady { polls: 3 },
        r,
    );
    assert!(matches!(e, SourceError::Timeout { .. }), "{e:?}");
}
