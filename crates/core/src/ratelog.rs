//! Logging of events that can come every frame (late, failed or lost
//! frames in the daemon, poses the MAVLink sender skips, send errors):
//! visible, not flooding, for weeks. One rule for every crate that logs
//! such events.
//!
//! The first event of a condition is logged at once (with its detail);
//! while the condition lasts, the lines come less and less often (after
//! [`STEPS`]: 1 s, 10 s, 1 min, then every 10 min), each saying how many
//! events came since the line before it; after [`QUIET`] without one, the
//! condition is over and the next event is again logged at once.
//!
//! The events after the last line of a condition are told by a closing
//! line: the owner calls [`RateLog::settle`] from something that runs
//! anyway (a per-frame path, a timer, a status tick), and writes one line
//! when it answers, at the level of the condition's lines: "…: the
//! condition is over: N more since the last line, the last S s ago". So
//! the n of all lines, tick's and settle's, add up to the events counted.
//!
//! When the owner stops (the daemon's shutdown, a source that ended, a
//! fatal error), the events still pending are told by [`RateLog::flush`],
//! whatever the step's wait, in the same line with "at stop" for "the
//! condition is over" ([`Close`]): so the lines, tick's, settle's and
//! flush's, add up to every event counted, the last STATUS's counts.

use std::time::{Duration, Instant};

/// The least time from one line to the next while a condition lasts: the
/// second line 1 s after the first, the third 10 s after that, then 1 min,
/// then every 10 min. A burst (a stall, a host loaded for a few seconds)
/// is told within seconds with its count; a condition that lasts (a board
/// a little slower than `rate_hz`, a destination down for a week) comes
/// down to a line every 10 min: 148 lines the first day, 144 a day after
/// (a line a second was 86 400), and a look at the journal still finds a
/// line at most 10 min old while it goes on.
pub const STEPS: [Duration; 4] = [
    Duration::from_secs(1),
    Duration::from_secs(10),
    Duration::from_secs(60),
    Duration::from_secs(600),
];

/// How long without an event ends a condition (the next event is logged
/// at once, and the steps start again at 1 s): the longest step. A
/// shorter quiet time (say the step in force, 1 s after the first line)
/// would let a condition that comes back a little slower than it (a late
/// frame every 2 s) start anew each time and log every event forever; with
/// the longest step the worst is one line per 10 min.
pub const QUIET: Duration = STEPS[STEPS.len() - 1];

/// Which closing line an owner writes: the one of a condition over
/// ([`RateLog::settle`]) or the one at stop ([`RateLog::flush`]). Its text
/// is the line's "when" ("…: the condition is over: N more since the last
/// line, …" / "…: at stop: N more …"), so that each owner writes its
/// closing line once for both.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Close {
    /// None came for the step in force: [`RateLog::settle`].
    Over,
    /// The owner stops: [`RateLog::flush`].
    AtStop,
}

impl Close {
    pub const fn as_str(self) -> &'static str {
        match self {
            Close::Over => "the condition is over",
            Close::AtStop => "at stop",
        }
    }
}

impl std::fmt::Display for Close {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A rate-limited log of one kind of event: [`RateLog::tick`] at each
/// event says whether to write a line now and how many events it stands
/// for. No allocation, no lock: per frame on the frame thread.
#[derive(Debug, Clone, Copy, Default)]
pub struct RateLog {
    /// When the last line was written.
    said: Option<Instant>,
    /// When the last event came.
    last: Option<Instant>,
    /// Index in [`STEPS`] of the wait from the last line to the next.
    step: u8,
    /// Events since the last line, this one's included once it is said.
    unsaid: u64,
}

impl RateLog {
    pub const fn new() -> Self {
        RateLog {
            said: None,
            last: None,
            step: 0,
            unsaid: 0,
        }
    }

    /// Events counted and not said yet (a field read: owners on a
    /// per-frame path call [`RateLog::settle`], which wants the clock,
    /// only when this is not 0).
    pub const fn pending(&self) -> u64 {
        self.unsaid
    }

    /// How long before `now` the last event came (zero if none, or if it
    /// is stamped after `now`): for the closing line's "the last S s ago".
    pub fn since_last(&self, now: Instant) -> Duration {
        self.last
            .map_or(Duration::ZERO, |t| now.saturating_duration_since(t))
    }

    /// The closing line: `Some(n)` once, when events are pending and none
    /// came for the step in force (the wait the next line would have had:
    /// 1 s after a condition's first line, 10 s after its second, 1 min,
    /// then 10 min), n = those events. `None` while events still come,
    /// and when there is nothing to tell; after it, `None` until another
    /// event.
    ///
    /// Why the step in force and not [`QUIET`]: the end of a burst (a
    /// stall of a few seconds) is told within seconds, not 10 min later,
    /// and the line breaks no rule, as it is the line the next event would
    /// have been given: it comes at least the step after the line before
    /// it (and after the last event), and it counts as a line of the
    /// condition (the step after it is the next one). The lines of one
    /// condition, tick's and settle's together, are spaced as
    /// [`STEPS`] say, so a condition that keeps coming back (within
    /// [`QUIET`]) still comes down to a line per 10 min. Only [`QUIET`]
    /// without an event ends the condition for [`RateLog::tick`]: an
    /// event after the closing line is logged at once if the next step has
    /// passed since it (always after [`QUIET`]; in the 10-min step, the
    /// closing line comes only then), else by the steps as before.
    pub fn settle(&mut self, now: Instant) -> Option<u64> {
        if self.unsaid == 0 {
            return None;
        }
        let wait = STEPS[usize::from(self.step)];
        let since = |t: Option<Instant>| t.is_none_or(|t| now.saturating_duration_since(t) >= wait);
        // The last line too: an event stamped before it (another
        // thread's clock read) must not bring the next line forward.
        if !(since(self.last) && since(self.said)) {
            return None;
        }
        self.step = (self.step + 1).min(STEPS.len() as u8 - 1);
        self.said = Some(now);
        Some(std::mem::take(&mut self.unsaid))
    }

    /// The line at stop: `Some(n)` when n > 0 events are pending, whatever
    /// the step's wait (the owner stops: they would never be told), and
    /// then nothing is pending; `None` when there is nothing to tell. It
    /// counts as a line, as settle's does.
    pub fn flush(&mut self, now: Instant) -> Option<u64> {
        if self.unsaid == 0 {
            return None;
        }
        self.step = (self.step + 1).min(STEPS.len() as u8 - 1);
        self.said = Some(now);
        Some(std::mem::take(&mut self.unsaid))
    }

    /// The closing line `when`: [`RateLog::settle`] for [`Close::Over`],
    /// [`RateLog::flush`] for [`Close::AtStop`].
    pub fn close(&mut self, now: Instant, when: Close) -> Option<u64> {
        match when {
            Close::Over => self.settle(now),
            Close::AtStop => self.flush(now),
        }
    }

    /// An event at `now`: `Some(n)` when a line should be written now, n =
    /// the events since the last line, this one included (so the n of all
    /// lines add up to the events counted, less those not said yet).
    pub fn tick(&mut self, now: Instant) -> Option<u64> {
        self.unsaid = self.unsaid.saturating_add(1);
        let since = |t: Option<Instant>| t.map(|t| now.saturating_duration_since(t));
        let quiet = since(self.last).is_none_or(|d| d >= QUIET);
        self.last = Some(now);
        if quiet {
            // A new condition: said at once, then the steps from 1 s.
            self.step = 0;
        } else if since(self.said).is_some_and(|d| d < STEPS[usize::from(self.step)]) {
            return None;
        } else {
            self.step = (self.step + 1).min(STEPS.len() as u8 - 1);
        }
        self.said = Some(now);
        Some(std::mem::take(&mut self.unsaid))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Lines (time since `t0`, count) of events at `t0` + each offset.
    fn lines(
        log: &mut RateLog,
        t0: Instant,
        at: impl Iterator<Item = Duration>,
    ) -> Vec<(Duration, u64)> {
        at.filter_map(|d| log.tick(t0 + d).map(|n| (d, n)))
            .collect()
    }

    /// The audit's case: an event every 10 ms for 2 hours of simulated
    /// time (720 000 events) is 15 lines, not 7 200: at 0, 1 s, 11 s,
    /// 71 s, then every 10 min; their counts and what is not said yet add
    /// up to every event.
    #[test]
    fn a_lasting_condition_is_logged_less_and_less_often() {
        let t0 = Instant::now();
        let mut log = RateLog::new();
        let n = 2 * 3600 * 100;
        let got = lines(&mut log, t0, (0..n).map(|k| Duration::from_millis(10 * k)));
        let at: Vec<u64> = got.iter().map(|(d, _)| d.as_secs()).collect();
        let mut want = vec![0, 1, 11, 71];
        want.extend((0..11).map(|k| 671 + 600 * k));
        assert_eq!(at, want);
        assert_eq!(got[0].1, 1, "the first event is said at once, alone");
        assert_eq!(got[1].1, 100, "the second second's line: the 100 since");
        assert_eq!(got[4].1, 60_000, "10 min of events in one line");
        let said: u64 = got.iter().map(|(_, k)| k).sum();
        assert_eq!(said + log.unsaid, n);
    }

    /// Once a condition has been quiet for `QUIET`, the next event is
    /// logged at once, with the events not said before it, and the steps
    /// start again at 1 s.
    #[test]
    fn after_a_quiet_gap_the_next_event_is_logged_at_once() {
        let t0 = Instant::now();
        let mut log = RateLog::new();
        // 5 minutes of events every 10 ms: the last line at 71 s, the
        // next not before 671 s.
        let first = lines(
            &mut log,
            t0,
            (0..30_000).map(|k| Duration::from_millis(10 * k)),
        );
        assert_eq!(first.len(), 4);
        let unsaid = log.unsaid;
        assert_eq!(unsaid, 30_000 - 7_101);
        // Quiet for 10 min, then a burst: said at once, then 1 s later.
        let restart = Duration::from_millis(299_990) + QUIET;
        let again = lines(
            &mut log,
            t0,
            (0..200).map(|k| restart + Duration::from_millis(10 * k)),
        );
        assert_eq!(again, [(restart, unsaid + 1), (restart + STEPS[0], 100)]);
    }

    /// A gap shorter than `QUIET` does not start the steps again: a
    /// condition that comes back every 2 s (a board a little slow) still
    /// comes down to a line every 10 min.
    #[test]
    fn a_condition_that_comes_back_before_quiet_is_one_condition() {
        let t0 = Instant::now();
        let mut log = RateLog::new();
        let got = lines(&mut log, t0, (0..3600).map(|k| Duration::from_secs(2 * k)));
        let at: Vec<u64> = got.iter().map(|(d, _)| d.as_secs()).collect();
        let mut want = vec![0, 2, 12, 72];
        want.extend((0..11).map(|k| 672 + 600 * k));
        assert_eq!(at, want);
        // Sparser than `QUIET`: each event is a condition of its own.
        let mut log = RateLog::new();
        let got = lines(&mut log, t0, (0..10).map(|k| QUIET * k));
        assert!(got.iter().all(|&(_, n)| n == 1) && got.len() == 10);
    }

    /// An event stamped before the last one (another thread's clock read)
    /// is neither a quiet gap nor a panic.
    #[test]
    fn an_earlier_instant_is_taken_as_now() {
        let t0 = Instant::now();
        let mut log = RateLog::new();
        let late = t0 + Duration::from_secs(5);
        assert_eq!(log.tick(late), Some(1));
        assert_eq!(log.tick(t0), None);
        assert_eq!(log.tick(late + STEPS[0]), Some(2));
    }

    /// Lines (time since `t0`, count, whether settle's) of a timeline of
    /// events and settle calls at `t0` + each offset.
    fn timeline(
        log: &mut RateLog,
        t0: Instant,
        at: impl Iterator<Item = (Duration, bool)>,
    ) -> Vec<(Duration, u64, bool)> {
        at.filter_map(|(d, settle)| {
            let now = t0 + d;
            let got = if settle {
                log.settle(now)
            } else {
                log.tick(now)
            };
            got.map(|n| (d, n, settle))
        })
        .collect()
    }

    /// Events every 10 ms for 3 s, settle called every 100 ms for 2 min:
    /// lines at 0 and 1 s, then the closing line with the 199 events
    /// after 1 s, the step in force (10 s) after the last one; once. An
    /// event after it within the next step (1 min) waits for that step,
    /// and is told alone by the next closing line.
    #[test]
    fn the_end_of_a_burst_is_told_one_step_after_its_last_event() {
        let t0 = Instant::now();
        let mut log = RateLog::new();
        let ms = Duration::from_millis;
        let events = (0..300).map(|k| (ms(10 * k), false));
        let settles = (0..1200).map(|k| (ms(100 * k + 5), true));
        let mut at: Vec<_> = events.chain(settles).collect();
        at.push((ms(20_000), false));
        at.sort();
        let got = timeline(&mut log, t0, at.into_iter());
        assert_eq!(
            got,
            [
                (ms(0), 1, false),
                (ms(1_000), 100, false),
                (ms(13_005), 199, true),
                (ms(80_005), 1, true),
            ]
        );
        assert_eq!(got.iter().map(|l| l.1).sum::<u64>(), 301);
        assert_eq!(log.pending(), 0);
        assert_eq!(log.since_last(t0 + ms(80_005)), ms(60_005));
    }

    /// Nothing pending, nothing to settle; after the closing line, none
    /// again until an event; and a condition over for `QUIET` starts
    /// anew, its first event logged at once.
    #[test]
    fn settle_says_each_event_once() {
        let t0 = Instant::now();
        let s = Duration::from_secs;
        let mut log = RateLog::new();
        assert_eq!(log.settle(t0), None);
        assert_eq!(log.tick(t0), Some(1));
        assert_eq!(log.settle(t0 + s(5)), None, "the first line said it");
        assert_eq!(log.tick(t0 + s(5)), Some(1));
        assert_eq!(log.tick(t0 + s(6)), None);
        assert_eq!(log.settle(t0 + s(15)), None, "9 s of the 10 s step");
        assert_eq!(log.settle(t0 + s(16)), Some(1));
        assert_eq!(log.settle(t0 + s(17)), None);
        assert_eq!(log.settle(t0 + s(3600)), None);
        let back = t0 + s(6) + QUIET;
        assert_eq!(log.tick(back), Some(1), "a new condition");
        assert_eq!(log.tick(back + s(1) / 2), None);
        assert_eq!(log.settle(back + s(1)), None, "0.5 s without one");
        assert_eq!(log.settle(back + s(3) / 2), Some(1), "the 1 s step");
    }

    /// A burst of 1 s every 5 min for a day (within `QUIET`: one
    /// condition), settle called every second: closing lines come while
    /// the steps are short, and then a line per 10 min as without them:
    /// 148 lines, not a line or two per burst (288 bursts).
    #[test]
    fn bursts_that_keep_coming_back_come_down_to_a_line_per_10_min() {
        let t0 = Instant::now();
        let mut log = RateLog::new();
        let ms = Duration::from_millis;
        let mut at: Vec<_> = (0..288u64)
            .flat_map(|b| (0..100).map(move |k| (ms(300_000 * b + 10 * k), false)))
            .chain((0..86_400).map(|k| (ms(1000 * k + 5), true)))
            .collect();
        at.sort();
        let got = timeline(&mut log, t0, at.into_iter());
        let kinds: Vec<bool> = got.iter().map(|l| l.2).collect();
        assert_eq!(kinds[..4], [false, true, false, true]);
        for w in got[3..].windows(2) {
            assert!(w[1].0 - w[0].0 >= QUIET, "{:?}", w);
        }
        assert!(got.len() <= 4 + 144, "{} lines", got.len());
        let said: u64 = got.iter().map(|l| l.1).sum();
        assert_eq!(said + log.pending(), 288 * 100);
    }

    /// At stop, what is pending is told whatever the step's wait (settle
    /// would wait for it), once; nothing pending, nothing told.
    #[test]
    fn flush_tells_what_is_pending_whatever_the_step() {
        let t0 = Instant::now();
        let ms = Duration::from_millis;
        let mut log = RateLog::new();
        assert_eq!(log.flush(t0), None, "nothing to tell");
        assert_eq!(log.tick(t0), Some(1));
        assert_eq!(log.flush(t0), None, "the first line said it");
        for k in 1..=5 {
            assert_eq!(log.tick(t0 + ms(100 * k)), None);
        }
        let stop = t0 + ms(600);
        assert_eq!(log.settle(stop), None, "0.1 s of the 1 s step");
        assert_eq!(log.close(stop, Close::Over), None);
        assert_eq!(log.pending(), 5);
        assert_eq!(log.close(stop, Close::AtStop), Some(5));
        assert_eq!(log.pending(), 0);
        assert_eq!(log.since_last(stop), ms(100));
        assert_eq!(log.flush(stop), None, "once");
        assert_eq!(log.settle(stop + QUIET), None);
    }

    #[test]
    fn the_closing_lines_say_when() {
        assert_eq!(Close::Over.to_string(), "the condition is over");
        assert_eq!(
            format!("late frames: {}: 3 more", Close::AtStop),
            "late frames: at stop: 3 more"
        );
    }

    proptest! {
        /// Events, settle and flush interleaved whatever the gaps, then a
        /// flush at stop: every line says at least one event, flush says
        /// exactly what is pending, and the lines of tick, settle and flush
        /// add up to every event, nothing left pending.
        #[test]
        fn tick_settle_and_flush_lines_add_up_to_the_events(
            ops in prop::collection::vec(
                (prop_oneof![0u64..2_000, 0u64..120_000, 0u64..1_300_000], 0u8..8),
                0..400,
            )
        ) {
            let t0 = Instant::now();
            let mut log = RateLog::new();
            let mut now = t0;
            let (mut events, mut said) = (0u64, 0u64);
            for (g, op) in &ops {
                now += Duration::from_millis(*g);
                let pending = log.pending();
                let got = match op {
                    0..=4 => {
                        events += 1;
                        log.tick(now)
                    }
                    5 | 6 => log.settle(now),
                    _ => {
                        let got = log.flush(now);
                        prop_assert_eq!(got.unwrap_or(0), pending);
                        got
                    }
                };
                if let Some(n) = got {
                    prop_assert!(n >= 1);
                    said += n;
                }
                prop_assert_eq!(said + log.pending(), events);
            }
            let pending = log.pending();
            let last = log.flush(now);
            prop_assert_eq!(last.unwrap_or(0), pending);
            prop_assert_eq!(last.is_some(), pending > 0);
            said += last.unwrap_or(0);
            prop_assert_eq!(said, events);
            prop_assert_eq!(log.pending(), 0);
            prop_assert_eq!(log.flush(now), None);
        }

        /// Settle interleaved with events, whatever the gaps: events are
        /// said as without settle (at once after a quiet gap, else when the
        /// step since the last line has passed); settle says exactly when
        /// events are pending and none came for the step in force since
        /// the last event and the last line, then counts as a line; never
        /// two closing lines without an event between; every line of a
        /// condition the step after the one before; and the counts said
        /// plus those pending are every event.
        #[test]
        fn settled_lines_keep_the_steps_and_count_every_event(
            ops in prop::collection::vec(
                (prop_oneof![0u64..2_000, 0u64..120_000, 0u64..1_300_000], any::<bool>()),
                1..400,
            )
        ) {
            let t0 = Instant::now();
            let mut log = RateLog::new();
            let mut now = t0;
            let (mut last, mut line_at) = (None::<Instant>, t0);
            let (mut events, mut pending, mut said) = (0u64, 0u64, 0u64);
            let (mut lines_in_condition, mut settled_last) = (0usize, false);
            for (k, (g, settle)) in ops.iter().enumerate() {
                now += Duration::from_millis(*g);
                let step = STEPS[lines_in_condition.saturating_sub(1).min(STEPS.len() - 1)];
                let got = if *settle {
                    let got = log.settle(now);
                    let due = pending > 0
                        && last.is_some_and(|l| now - l >= step)
                        && now - line_at >= step;
                    prop_assert_eq!(got.is_some(), due, "settle {}, {:?} after the last line", k, now - line_at);
                    if got.is_some() {
                        prop_assert!(!settled_last, "two closing lines in a row at {}", k);
                        settled_last = true;
                    }
                    got
                } else {
                    events += 1;
                    pending += 1;
                    settled_last = false;
                    let fresh = last.is_none_or(|l| now - l >= QUIET);
                    last = Some(now);
                    let got = log.tick(now);
                    if fresh {
                        prop_assert!(got.is_some(), "event {} after a quiet gap not said", k);
                        lines_in_condition = 0;
                    } else {
                        let due = now - line_at >= step;
                        prop_assert_eq!(got.is_some(), due, "event {}, {:?} after the last line", k, now - line_at);
                    }
                    got
                };
                if let Some(n) = got {
                    if lines_in_condition > 0 {
                        prop_assert!(now - line_at >= step, "line {} {:?} after the one before", k, now - line_at);
                    }
                    prop_assert!(n >= 1);
                    prop_assert_eq!(n, pending);
                    pending = 0;
                    said += n;
                    lines_in_condition += 1;
                    line_at = now;
                }
                prop_assert_eq!(log.pending(), pending);
            }
            prop_assert_eq!(said + log.pending(), events);
        }

        /// Whatever the gaps: the first event and the first after a quiet
        /// gap are said at once; within one condition a line comes exactly
        /// when the step (1 s, 10 s, 1 min, then 10 min) since the last
        /// one has passed; and the counts
        /// said plus those pending are every event.
        #[test]
        fn lines_are_spaced_by_the_steps_and_count_every_event(
            gaps_ms in prop::collection::vec(0u64..1_000_000, 1..400)
        ) {
            let t0 = Instant::now();
            let mut log = RateLog::new();
            let (mut now, mut last) = (t0, None::<Instant>);
            let (mut said, mut lines_in_condition) = (0u64, 0usize);
            let mut line_at = t0;
            for (k, g) in gaps_ms.iter().enumerate() {
                now += Duration::from_millis(*g);
                let fresh = k == 0 || last.is_some_and(|l| now - l >= QUIET);
                last = Some(now);
                let got = log.tick(now);
                if fresh {
                    prop_assert!(got.is_some(), "event {} after a quiet gap not said", k);
                    lines_in_condition = 0;
                } else {
                    let step = STEPS[(lines_in_condition - 1).min(STEPS.len() - 1)];
                    let due = now - line_at >= step;
                    prop_assert_eq!(got.is_some(), due, "event {}, {:?} after the last line", k, now - line_at);
                }
                if let Some(n) = got {
                    prop_assert!(n >= 1);
                    said += n;
                    lines_in_condition += 1;
                    line_at = now;
                }
            }
            prop_assert_eq!(said + log.unsaid, gaps_ms.len() as u64);
        }
    }
}
