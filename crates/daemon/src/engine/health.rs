//! The log's account of what the source skipped (hal's health counters):
//! the engine copies them into STATUS once a second, and a line says how
//! much the faults among them grew, by core's rule (the first growth at
//! once, then less and less often while they go on), not a line every
//! second: a board that keeps sending garbage did that for weeks.

use lightpose_core::ratelog::{Close, RateLog};
use lightpose_hal::SourceHealth;
use std::time::Instant;

/// The counters told, and whether their growth alone is worth a line.
/// Lines a board sent faster than frames take them (superseded) are no
/// fault: said once when first seen (by the engine), then only named in
/// the line the faults make.
const SKIPS: [(&str, bool); 7] = [
    ("bad lines", true),
    ("gaps in a board's bursts", true),
    ("burst frames dropped unfinished", true),
    ("lines of another board", true),
    ("glitches in seq or t", true),
    ("malformed readings", true),
    ("lines superseded by a newer one of their board", false),
];

fn counts(h: &SourceHealth) -> [u64; SKIPS.len()] {
    [
        h.bad_lines,
        h.burst_gaps,
        h.bursts_dropped,
        h.wrong_board_lines,
        h.glitches,
        h.bad_readings,
        h.superseded_lines,
    ]
}

#[derive(Default)]
pub(super) struct HealthLog {
    log: RateLog,
    /// The counters as of the last line: each line tells the growth
    /// since, so that the lines add up to STATUS's counters.
    said: [u64; SKIPS.len()],
}

impl HealthLog {
    /// The health copied at `now` (`was` the copy before it): a line if
    /// a fault grew and one is due, or, the faults having stopped growing
    /// for the step in force (core's `RateLog::settle`), the closing line
    /// with the growth not told yet; or `at_exit` (the last copy: nothing
    /// is left unsaid), the closing line at stop with the growth not told
    /// yet (core's `RateLog::flush`). Copies come once a second: the
    /// closing line at most a second late.
    pub(super) fn note(
        &mut self,
        was: Option<&SourceHealth>,
        new: &SourceHealth,
        now: Instant,
        at_exit: bool,
    ) {
        let (now_n, was_n) = (counts(new), was.map_or([0; SKIPS.len()], counts));
        let faults_grew = |from: &[u64; SKIPS.len()]| {
            SKIPS
                .iter()
                .zip(now_n.iter().zip(from))
                .any(|((_, alone), (n, f))| *alone && n > f)
        };
        let grew = faults_grew(&was_n);
        let due = grew && self.log.tick(now).is_some();
        // Settled only in a copy where they did not grow: one where they
        // did is an event, which tick has just counted.
        let over = !due && !grew && !at_exit && self.log.settle(now).is_some();
        if at_exit {
            self.log.flush(now);
        }
        let untold = faults_grew(&self.said);
        if !(due || (at_exit || over) && untold) {
            return;
        }
        let what: Vec<String> = SKIPS
            .iter()
            .zip(now_n.iter().zip(&self.said))
            .map(|((w, _), (n, s))| (w, n.saturating_sub(*s)))
            .filter(|(_, k)| *k > 0)
            .map(|(w, k)| format!("{k} {w}"))
            .collect();
        let last = new
            .last_bad_line
            .as_deref()
            .or(new.last_bad_reading.as_deref());
        if !due {
            let when = if at_exit { Close::AtStop } else { Close::Over };
            tracing::warn!(
                last = last.unwrap_or("-"),
                "source skips: {when}: {} more since the last line, the last {:.0} s ago (STATUS backend.health)",
                what.join(", "),
                self.log.since_last(now).as_secs_f64()
            );
        } else {
            tracing::warn!(
                last = last.unwrap_or("-"),
                "source skipped {} since the last such line (STATUS backend.health)",
                what.join(", ")
            );
        }
        self.said = now_n;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    /// Soak audit: a board sending garbage all week was a WARN every
    /// second. Copied once a second for an hour, 10 bad lines a second:
    /// lines at 0, 1, 11, 71 s and then every 10 min (9), whose numbers
    /// add up to STATUS's count; the copy at exit tells the rest.
    #[test]
    fn a_source_that_keeps_skipping_is_logged_less_and_less_often() {
        let t0 = Instant::now();
        let mut log = HealthLog::default();
        let health = |s: u64| SourceHealth {
            bad_lines: 10 * s,
            last_bad_line: Some("ttyUSB0 line 7: no checksum".into()),
            ..SourceHealth::default()
        };
        let text = lightpose_testkit::logs::logged(|| {
            for s in 1..=3600 {
                let at = t0 + Duration::from_secs(s);
                log.note(Some(&health(s - 1)), &health(s), at, false);
            }
            log.note(Some(&health(3600)), &health(3605), t0, true);
        });
        let told: Vec<u64> = text
            .lines()
            .filter_map(|l| l.split("source skipped ").nth(1))
            .map(|l| l.split(' ').next().unwrap().parse().unwrap())
            .collect();
        assert_eq!(told.len(), 4 + 5, "{text}");
        assert_eq!(&told[..4], [10, 10, 100, 600]);
        let at_stop: Vec<u64> = text
            .lines()
            .filter_map(|l| l.split("source skips: at stop: ").nth(1))
            .map(|l| l.split(' ').next().unwrap().parse().unwrap())
            .collect();
        assert_eq!(at_stop.len(), 1, "{text}");
        assert_eq!(told.iter().sum::<u64>() + at_stop[0], 36_050);
        assert!(text.contains("no checksum"), "{text}");
    }

    /// A board that sent garbage for 3 s and then stopped: lines at 1 s
    /// and 2 s, and the third second's 10 bad lines, not due then (the
    /// 10 s step), told by the closing line once the faults have not
    /// grown for that step (at 13 s); then nothing, and nothing at exit.
    #[test]
    fn skips_that_stop_are_told_by_a_closing_line() {
        let t0 = Instant::now();
        let mut log = HealthLog::default();
        let health = |s: u64| SourceHealth {
            bad_lines: 10 * s.min(3),
            last_bad_line: Some("ttyUSB0 line 7: no checksum".into()),
            ..SourceHealth::default()
        };
        let text = lightpose_testkit::logs::logged(|| {
            for s in 1..=60 {
                let at = t0 + Duration::from_secs(s);
                log.note(Some(&health(s - 1)), &health(s), at, false);
                if s == 12 {
                    assert_eq!(log.log.pending(), 1, "not yet");
                }
            }
            log.note(Some(&health(60)), &health(60), t0, true);
        });
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 3, "{text}");
        assert!(lines[0].contains("skipped 10 bad lines"), "{text}");
        assert!(lines[1].contains("skipped 10 bad lines"), "{text}");
        assert!(
            lines[2].contains("WARN")
                && lines[2].contains(
                    "source skips: the condition is over: 10 bad lines more since the last line, the last 10 s ago"
                ),
            "{text}"
        );
    }

    /// Superseded lines alone are no fault: no line, but they are named
    /// in the next line the faults make; at exit with nothing untold,
    /// nothing.
    #[test]
    fn superseded_lines_alone_make_no_line() {
        let t0 = Instant::now();
        let mut log = HealthLog::default();
        let h = |superseded_lines, glitches| SourceHealth {
            superseded_lines,
            glitches,
            ..SourceHealth::default()
        };
        let text = lightpose_testkit::logs::logged(|| {
            log.note(None, &h(50, 0), t0, false);
            log.note(Some(&h(50, 0)), &h(90, 1), t0, false);
            log.note(Some(&h(90, 1)), &h(90, 1), t0, true);
        });
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 1, "{text}");
        assert!(
            lines[0].contains("1 glitches in seq or t, 90 lines superseded"),
            "{text}"
        );
    }
}
