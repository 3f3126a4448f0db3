//! The journal's account of poses the sender skipped: per reason, core's
//! rule for repeated lines (`RateLog`), with a closing line once a
//! reason's skips stop.

use super::outbound::{skip_why, Outgoing, Skip};
use lightpose_core::ratelog::{Close, RateLog};
use std::sync::atomic::AtomicU64;
use std::sync::atomic::Ordering::Relaxed;
use std::time::Instant;

/// The journal's account of `ok` poses not sent (no std, a bad std or
/// time, a value too big for MAVLink): STATUS counts them all, and the
/// journal says the first of each reason at once, with the pose's seq and
/// why, then less and less often while more come (core's rule: after 1 s,
/// 10 s, 1 min, then every 10 min).
/// (Decimation is the configured rate limit, not a fault: not logged.)
pub(super) struct SkipLog {
    /// VISION_SPEED_ESTIMATE's skips (else VISION_POSITION_ESTIMATE's).
    speed: bool,
    /// Per reason, core's rule: the first at once, then less and less often.
    logs: [RateLog; Skip::ALL.len()],
}

impl SkipLog {
    pub(super) fn new(speed: bool) -> Self {
        SkipLog {
            speed,
            logs: [RateLog::new(); Skip::ALL.len()],
        }
    }

    /// Whether a skip `k` at `now` is to be logged; if so, how many of
    /// that reason came since the last line (this one included).
    fn due(&mut self, k: Skip, now: Instant) -> Option<u64> {
        self.logs.get_mut(k.index())?.tick(now)
    }

    /// Log skip `k` of pose `o`, the `count`th of its reason, if due.
    pub(super) fn note(&mut self, o: &Outgoing, k: Skip, count: u64) {
        if k == Skip::Decimated {
            return;
        }
        let Some(since) = self.due(k, Instant::now()) else {
            return;
        };
        let message = self.message();
        let (seq, why, reason) = (o.seq, skip_why(o, k, self.speed), k.as_str());
        if count == since {
            tracing::warn!(
                seq,
                reason,
                count,
                "mavlink: {message} not sent for pose {seq}: {why}; \
                 while more {reason} skips come they are logged after 1 s, \
                 10 s, 1 min, then every 10 min"
            );
        } else {
            tracing::warn!(
                seq,
                reason,
                count,
                "mavlink: {message} not sent for pose {seq}: {why} \
                 ({since} {reason} skips since the last line, {count} in all)"
            );
        }
    }

    /// The closing line `when` of each reason whose skips stopped (core's
    /// `RateLog::settle`) or, at stop, with skips not told yet
    /// (`RateLog::flush`), with its count in all from `counts` (STATUS's).
    pub(super) fn close(
        &mut self,
        counts: &[AtomicU64; Skip::ALL.len()],
        now: Instant,
        when: Close,
    ) {
        let message = self.message();
        for (k, log) in Skip::ALL.iter().zip(self.logs.iter_mut()) {
            let Some(since) = log.close(now, when) else {
                continue;
            };
            let (reason, count) = (k.as_str(), counts[k.index()].load(Relaxed));
            tracing::warn!(
                reason,
                count,
                since_last_line = since,
                "mavlink: {message} skips ({reason}): {when}: {since} more since \
                 the last line ({count} in all), the last {:.1} s ago",
                log.since_last(now).as_secs_f64()
            );
        }
    }

    fn message(&self) -> &'static str {
        if self.speed {
            "VISION_SPEED_ESTIMATE"
        } else {
            "VISION_POSITION_ESTIMATE"
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    /// The first skip of each reason is logged at once, then at most one
    /// line per second of that reason while more come, each saying how
    /// many came since the last.
    #[test]
    fn skips_are_logged_first_then_at_most_once_a_second() {
        let mut log = SkipLog::new(false);
        let t0 = Instant::now();
        let ms = |n: u64| t0 + Duration::from_millis(n);
        assert_eq!(log.due(Skip::NoStd, ms(0)), Some(1));
        for (k, at) in (2..=40).zip((25..).step_by(25)) {
            assert_eq!(log.due(Skip::NoStd, ms(at)), None, "skip {k}");
        }
        // Another reason has its own first line.
        assert_eq!(log.due(Skip::BadTime, ms(500)), Some(1));
        assert_eq!(log.due(Skip::NoStd, ms(1000)), Some(40));
        assert_eq!(log.due(Skip::NoStd, ms(1999)), None);
        // After a quiet spell the next one is said at once.
        assert_eq!(log.due(Skip::NoStd, ms(60_000)), Some(2));
        assert_eq!(log.due(Skip::BadTime, ms(60_000)), Some(1));
    }

    /// Five `no_std` skips 100 ms apart (the first said at once), of
    /// VISION_SPEED_ESTIMATE when `speed`: the counts, the log, and the
    /// time `n` ms after the first.
    #[allow(clippy::type_complexity)]
    fn five_no_std_skips(
        speed: bool,
    ) -> (
        [AtomicU64; Skip::ALL.len()],
        SkipLog,
        impl Fn(u64) -> Instant,
    ) {
        let counts: [AtomicU64; Skip::ALL.len()] = Default::default();
        counts[Skip::NoStd.index()].store(5, Relaxed);
        let mut log = SkipLog::new(speed);
        let t0 = Instant::now();
        let ms = move |n: u64| t0 + Duration::from_millis(n);
        assert_eq!(log.due(Skip::NoStd, ms(0)), Some(1));
        for k in 1..5 {
            assert_eq!(log.due(Skip::NoStd, ms(100 * k)), None);
        }
        (counts, log, ms)
    }

    /// A reason whose skips stopped is closed with those not said yet,
    /// once, the step in force (1 s) after the last of them (at 1.4 s, not
    /// at 1 s).
    #[test]
    fn skips_that_stop_get_a_closing_line() {
        let (counts, mut log, ms) = five_no_std_skips(true);
        let text = lightpose_testkit::logs::logged(|| {
            log.close(&counts, ms(1000), Close::Over);
            log.close(&counts, ms(1400), Close::Over);
            log.close(&counts, ms(1500), Close::Over);
        });
        let lines: Vec<&str> = text
            .lines()
            .filter(|l| l.contains("skips (no_std)"))
            .collect();
        assert_eq!(lines.len(), 1, "{text}");
        assert!(
            lines[0].contains("VISION_SPEED_ESTIMATE skips (no_std): the condition is over: 4 more since the last line (5 in all), the last 1.0 s ago"),
            "{text}"
        );
    }

    /// Skips whose end the stop cuts (0.1 s after the last, the step is
    /// 1 s) are told at stop, once.
    #[test]
    fn skips_not_told_yet_are_told_at_stop() {
        let (counts, mut log, ms) = five_no_std_skips(false);
        let text = lightpose_testkit::logs::logged(|| {
            log.close(&counts, ms(500), Close::Over);
            log.close(&counts, ms(500), Close::AtStop);
            log.close(&counts, ms(600), Close::AtStop);
        });
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 1, "{text}");
        assert!(
            lines[0].contains("since_last_line=4")
                && lines[0].contains("VISION_POSITION_ESTIMATE skips (no_std): at stop: 4 more since the last line (5 in all), the last 0.1 s ago"),
            "{text}"
        );
    }
}
