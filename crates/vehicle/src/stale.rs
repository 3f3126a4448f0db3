//! A reading that stops reaching the frames, told once when it stops and
//! once when it is back. The hub counts per frame what was attached and
//! what was found too old ([`ReadingsStatus`]); those counts alone say
//! nothing in the journal, so a DVL whose reports arrive already older
//! than `max_age_s`, or an autopilot that stopped streaming ATTITUDE while
//! its link is up, went unseen but in STATUS. Judged over each STATUS
//! interval: stale when no frame got the reading and some found it too
//! old, back when a frame gets it again. A reading that flickers within
//! an interval (some frames with, some without) is STATUS's to show; one
//! that goes stale and back again and again (a sender every 2 s against a
//! 1 s limit) has its episodes told by core's rule for repeated lines,
//! with a count, a "back" only after a "stale" that was told.

use crate::readings::{MaxAge, ReadingStatus, ReadingsStatus};
use lightpose_core::ratelog::{Close, RateLog};
use std::time::{Duration, Instant};

/// The readings, in the order of [`ReadingsStatus`]'s fields.
pub const NAMES: [&str; 4] = ["attitude", "depth", "temperature", "velocity"];

/// A change of one reading to tell.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Change {
    /// No frame of the interval got it; some found it older than its limit.
    Stale {
        reading: &'static str,
        /// How long before the look the latest was taken.
        age_s: Option<f64>,
        max_age_s: f64,
        /// Times it went stale since the last line (this one included).
        episodes: u64,
    },
    /// Times it went stale, not told yet, when they stopped coming
    /// (`Close::Over`) or at stop.
    Untold {
        reading: &'static str,
        episodes: u64,
        when: Close,
    },
    /// Frames get it again.
    Back {
        reading: &'static str,
        /// How long it was stale (from the look that found it so).
        after_s: f64,
        /// Frames that found it too old meanwhile.
        frames_without: u64,
    },
}

#[derive(Debug, Clone, Copy, Default)]
struct One {
    attached: u64,
    stale: u64,
    /// Since when it is stale, and the frames without it since.
    stale_since: Option<(Instant, u64)>,
    /// Whether this stale episode was told (its "back" is told then).
    told: bool,
    log: RateLog,
}

/// Per reading: the counts at the last look and whether it is stale.
#[derive(Debug, Clone, Default)]
pub struct StaleWatch {
    max_age: MaxAge,
    ones: [One; 4],
}

impl StaleWatch {
    pub fn new(max_age: MaxAge) -> Self {
        StaleWatch {
            max_age,
            ones: Default::default(),
        }
    }

    /// Compare `now`'s counts with the last look's; each change to `tell`.
    pub fn look(&mut self, st: &ReadingsStatus, now: Instant, mut tell: impl FnMut(Change)) {
        let m = &self.max_age;
        let all: [(&ReadingStatus, Duration); 4] = [
            (&st.attitude, m.attitude),
            (&st.depth, m.depth),
            (&st.temperature, m.temperature),
            (&st.velocity, m.velocity),
        ];
        for ((one, (r, limit)), reading) in self.ones.iter_mut().zip(all).zip(NAMES) {
            let got = r.attached.saturating_sub(one.attached);
            let without = r.stale.saturating_sub(one.stale);
            one.attached = r.attached;
            one.stale = r.stale;
            // Old at the look too: one that came since the last frame is
            // no stale reading ("taken 0.00 s ago, over its limit").
            let old = r.age_s.is_none_or(|a| a > limit.as_secs_f64());
            match one.stale_since {
                None if got == 0 && without > 0 && old => {
                    one.stale_since = Some((now, without));
                    one.told = false;
                    if let Some(episodes) = one.log.tick(now) {
                        one.told = true;
                        tell(Change::Stale {
                            reading,
                            age_s: r.age_s,
                            max_age_s: limit.as_secs_f64(),
                            episodes,
                        });
                    }
                }
                None => {}
                Some((since, n)) if got > 0 => {
                    one.stale_since = None;
                    if one.told {
                        tell(Change::Back {
                            reading,
                            after_s: now.saturating_duration_since(since).as_secs_f64(),
                            frames_without: n + without,
                        });
                    }
                }
                Some((since, n)) => one.stale_since = Some((since, n + without)),
            }
        }
    }

    /// The episodes not told yet `when`: once they stopped coming (at each
    /// STATUS), or at stop.
    pub fn close(&mut self, now: Instant, when: Close, mut tell: impl FnMut(Change)) {
        for (one, reading) in self.ones.iter_mut().zip(NAMES) {
            if let Some(episodes) = one.log.close(now, when) {
                tell(Change::Untold {
                    reading,
                    episodes,
                    when,
                });
            }
        }
    }
}

/// The autopilot falling silent (its HEARTBEAT, 1 Hz), told once, and
/// once when it is heard again. STATUS showed `autopilot_heartbeat_age_s`
/// growing and `send_errors` counting while an autopilot was away for a
/// minute, and the journal said nothing (an audit: ten such minutes).
#[derive(Debug, Clone)]
pub struct SilenceWatch {
    limit: Duration,
    /// Since when it is silent, and whether that was told.
    silent: Option<(Instant, bool)>,
    log: RateLog,
}

/// A change of the autopilot's voice to tell.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Voice {
    /// Not heard for longer than the limit: how long ago it was (`None`:
    /// never since the start).
    Silent {
        age_s: Option<f64>,
        limit_s: f64,
        /// Silences since the last line, this one included.
        episodes: u64,
    },
    /// Heard again after being told silent that long ago.
    Back { after_s: f64 },
    /// Silences not told yet, when they stopped coming or at stop.
    Untold { episodes: u64, when: Close },
}

impl SilenceWatch {
    /// Silent past `limit` (3 s: three heartbeats missed).
    pub fn new(limit: Duration) -> Self {
        SilenceWatch {
            limit,
            silent: None,
            log: RateLog::new(),
        }
    }

    /// Judge the heartbeat's `age_s` (`None`: never heard) at `now`,
    /// `running` after the start.
    pub fn look(&mut self, age_s: Option<f64>, running: Duration, now: Instant) -> Option<Voice> {
        let limit = self.limit.as_secs_f64();
        let silent = match age_s {
            Some(a) => a > limit,
            None => running > self.limit,
        };
        match (silent, self.silent) {
            (true, None) => {
                let told = self.log.tick(now);
                self.silent = Some((now, told.is_some()));
                told.map(|episodes| Voice::Silent {
                    age_s,
                    limit_s: limit,
                    episodes,
                })
            }
            (false, Some((at, told))) => {
                self.silent = None;
                told.then(|| Voice::Back {
                    after_s: now.saturating_duration_since(at).as_secs_f64(),
                })
            }
            _ => None,
        }
    }

    /// The silences not told yet `when` (at each STATUS, or at stop).
    pub fn close(&mut self, now: Instant, when: Close) -> Option<Voice> {
        self.log
            .close(now, when)
            .map(|episodes| Voice::Untold { episodes, when })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn status(att: (u64, u64), vel: (u64, u64), vel_age: f64) -> ReadingsStatus {
        let r = |(attached, stale): (u64, u64), age: f64| ReadingStatus {
            age_s: Some(age),
            stored: attached,
            attached,
            stale,
        };
        ReadingsStatus {
            attitude: r(att, 0.01),
            depth: r((0, 0), 0.0),
            temperature: r((0, 0), 0.0),
            velocity: r(vel, vel_age),
        }
    }

    fn looks(w: &mut StaleWatch, st: &ReadingsStatus, at: Instant) -> Vec<Change> {
        let mut out = Vec::new();
        w.look(st, at, |c| out.push(c));
        out
    }

    #[test]
    fn a_reading_is_told_once_stale_and_once_back() {
        let t0 = Instant::now();
        let s = Duration::from_secs(1);
        let mut w = StaleWatch::new(MaxAge::default());
        // Both readings on every frame: nothing to tell.
        assert!(looks(&mut w, &status((10, 0), (10, 0), 0.2), t0).is_empty());
        // The DVL's reports come 1.6 s old: no frame gets one.
        let c = looks(&mut w, &status((20, 0), (10, 10), 1.6), t0 + s);
        assert_eq!(
            c,
            vec![Change::Stale {
                reading: "velocity",
                age_s: Some(1.6),
                max_age_s: 1.0,
                episodes: 1
            }]
        );
        // Still stale: not told again.
        assert!(looks(&mut w, &status((30, 0), (10, 20), 1.6), t0 + 2 * s).is_empty());
        // A fresh one: back, with the frames that went without.
        let c = looks(&mut w, &status((40, 0), (12, 28), 0.1), t0 + 3 * s);
        assert_eq!(
            c,
            vec![Change::Back {
                reading: "velocity",
                after_s: 2.0,
                frames_without: 28
            }]
        );
        // Flicker within an interval (some frames with, some without) and
        // a reading that never came (no counts) are not told.
        assert!(looks(&mut w, &status((50, 0), (17, 33), 0.9), t0 + 4 * s).is_empty());
        assert!(looks(&mut w, &status((60, 0), (17, 33), 0.9), t0 + 5 * s).is_empty());
    }

    #[test]
    fn each_reading_has_its_own_limit_and_state() {
        let t0 = Instant::now();
        let mut w = StaleWatch::new(MaxAge::default());
        let mut st = status((10, 0), (10, 0), 0.2);
        assert!(looks(&mut w, &st, t0).is_empty());
        st.attitude.stale = 10;
        st.velocity.stale = 5;
        st.attitude.age_s = Some(0.4);
        st.velocity.age_s = Some(1.5);
        let c = looks(&mut w, &st, t0 + Duration::from_secs(1));
        assert_eq!(c.len(), 2, "{c:?}");
        assert!(
            matches!(c[0], Change::Stale { reading: "attitude", max_age_s, .. } if (max_age_s - 0.25).abs() < 1e-12)
        );
        assert!(
            matches!(c[1], Change::Stale { reading: "velocity", max_age_s, .. } if (max_age_s - 1.0).abs() < 1e-12)
        );
        st.attitude.attached = 11;
        let c = looks(&mut w, &st, t0 + Duration::from_secs(2));
        assert!(
            matches!(
                c[..],
                [Change::Back {
                    reading: "attitude",
                    frames_without: 10,
                    ..
                }]
            ),
            "{c:?}"
        );
    }

    #[test]
    fn an_autopilot_is_told_silent_once_and_back_once() {
        let t0 = Instant::now();
        let s = |k: u64| Duration::from_secs(k);
        let mut w = SilenceWatch::new(s(3));
        // Not heard yet, 2 s after the start: nothing; 4 s: silent.
        assert_eq!(w.look(None, s(2), t0), None);
        assert_eq!(
            w.look(None, s(4), t0 + s(2)),
            Some(Voice::Silent {
                age_s: None,
                limit_s: 3.0,
                episodes: 1
            })
        );
        // Heard: back; heard on: nothing.
        assert_eq!(
            w.look(Some(0.5), s(6), t0 + s(4)),
            Some(Voice::Back { after_s: 2.0 })
        );
        assert_eq!(w.look(Some(0.9), s(7), t0 + s(5)), None);
        // Away: told once, however long.
        assert!(matches!(
            w.look(Some(3.5), s(10), t0 + s(8)),
            Some(Voice::Silent { .. })
        ));
        assert_eq!(w.look(Some(60.0), s(67), t0 + s(65)), None);
        // Back, then away and back every 2 s (a heartbeat every 3.5 s):
        // the rule for repeated lines, a "back" only after a told "silent".
        assert!(matches!(
            w.look(Some(0.1), s(68), t0 + s(66)),
            Some(Voice::Back { .. })
        ));
        let mut lines = 0;
        for k in 0..60u64 {
            let at = t0 + s(70 + 2 * k);
            lines += usize::from(w.look(Some(3.5), s(80), at).is_some());
            lines += usize::from(w.look(Some(0.1), s(80), at + s(1)).is_some());
        }
        assert!(lines <= 8, "{lines} lines in 2 min");
        assert!(matches!(
            w.close(t0 + s(400), Close::AtStop),
            Some(Voice::Untold { episodes, .. }) if episodes > 10
        ));
    }

    #[test]
    fn a_reading_stale_and_back_every_other_second_is_told_by_the_rule() {
        let t0 = Instant::now();
        let mut w = StaleWatch::new(MaxAge::default());
        let mut lines = 0;
        let (mut att, mut st) = (0, 0);
        for k in 0..60u64 {
            let at = t0 + Duration::from_secs(k);
            if k % 2 == 0 {
                att += 5;
            } else {
                st += 5;
            }
            let mut now = status((att, st), (0, 0), 0.5);
            now.attitude.age_s = Some(if k % 2 == 0 { 0.1 } else { 0.6 });
            lines += looks(&mut w, &now, at).len();
        }
        assert!(lines <= 8, "{lines} lines in a minute");
        let mut untold = Vec::new();
        w.close(t0 + Duration::from_secs(61), Close::AtStop, |c| {
            untold.push(c)
        });
        assert!(
            matches!(untold[..], [Change::Untold { reading: "attitude", episodes, .. }] if episodes > 20),
            "{untold:?}"
        );
    }
}
