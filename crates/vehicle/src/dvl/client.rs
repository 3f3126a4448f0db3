//! The DVL's TCP client: connect, read reports line by line into the
//! hub's velocity reading, and when the DVL closes the connection, errs,
//! falls silent or sends a line longer than a report can be, connect again
//! after a capped back-off. Never returns before `shutdown`; every loss is
//! counted.
//!
//! Silence is judged on messages, not bytes: only a line that is a DVL
//! message (a `type`d JSON object: a velocity report, even one refused as
//! `velocity_invalid`, water-track or out of range, or another report such
//! as dead reckoning) keeps the connection. A peer that trickles bytes, or
//! sends garbage or one endless line, is not a DVL speaking its protocol
//! and is dropped. A refused velocity report still counts: the DVL is
//! there and says why it has no velocity (no bottom lock above its range,
//! out of the water), which reconnecting cannot change; dropping it every
//! `silence` would only turn that into a loop of warnings, while the
//! reading going stale and `refused` already show it.

use super::{parse_line, DvlLine, DvlRefusal};
use crate::backoff::Backoff;
use crate::Hub;
use lightpose_core::ratelog::Close;
use std::future::Future;
use std::sync::atomic::Ordering::Relaxed;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::io::AsyncReadExt;
use tokio::net::TcpStream;

/// A line longer than this is no report (the vendor's are < 2 KiB).
const MAX_LINE: usize = 64 * 1024;

/// Where the DVL is and how to treat it.
#[derive(Debug, Clone, PartialEq)]
pub struct DvlSettings {
    /// HOST:PORT of the DVL's TCP JSON server (port 16171).
    pub address: String,
    /// Components faster than this (m/s) are refused.
    pub max_speed_mps: f64,
    pub reconnect_first: Duration,
    pub reconnect_max: Duration,
    /// No DVL message for this long and the connection is given up (the
    /// DVL reports at 2–15 Hz while it is in the water and pinging; bytes
    /// that make no message do not count).
    pub silence: Duration,
    pub connect_timeout: Duration,
}

impl DvlSettings {
    pub fn new(address: impl Into<String>) -> Self {
        DvlSettings {
            address: address.into(),
            max_speed_mps: 5.0,
            reconnect_first: Duration::from_millis(500),
            reconnect_max: Duration::from_secs(5),
            silence: Duration::from_secs(3),
            connect_timeout: Duration::from_secs(3),
        }
    }
}

/// How a connection ended.
enum Ended {
    Shutdown,
    Closed,
    Error(std::io::Error),
    Silent,
    /// A line passed [`MAX_LINE`] without its end.
    Overlong,
}

/// What one line was, for the connection.
enum Heard {
    /// A good velocity report.
    Report,
    /// Another DVL message, or a velocity report refused on its content.
    Message,
    /// Blank, garbage, malformed: no sign of a DVL.
    Nothing,
}

/// Run the DVL client until `shutdown` resolves; then tell the log what
/// it was not told yet (failed connects, refused lines: at stop).
pub async fn run(s: DvlSettings, hub: Arc<Hub>, shutdown: impl Future<Output = ()>) {
    run_until(&s, &hub, shutdown).await;
    close(&s, &hub, Instant::now(), Close::AtStop);
}

async fn run_until(s: &DvlSettings, hub: &Arc<Hub>, shutdown: impl Future<Output = ()>) {
    let mut shutdown = std::pin::pin!(shutdown);
    let mut backoff = Backoff::new(s.reconnect_first, s.reconnect_max);
    let c = &hub.dvl;
    // A connection's lines come in pairs: "connected" is told when the
    // loss before it was (a DVL that closes each connection at once wrote
    // both lines 4 times a second, for good).
    let mut told = true;
    loop {
        let conn = tokio::select! {
            _ = &mut shutdown => return,
            r = tokio::time::timeout(s.connect_timeout, TcpStream::connect(s.address.as_str())) => r,
        };
        match conn {
            Ok(Ok(stream)) => {
                c.connects.fetch_add(1, Relaxed);
                if told {
                    tracing::info!("dvl: connected to {}", s.address);
                }
                let ended = session(s, hub, stream, shutdown.as_mut(), &mut backoff).await;
                let why = match ended {
                    Ended::Shutdown => return,
                    Ended::Closed => "closed by the DVL".to_string(),
                    Ended::Error(e) => e.to_string(),
                    Ended::Silent => {
                        c.silences.fetch_add(1, Relaxed);
                        format!("silent: no DVL message for {:?}", s.silence)
                    }
                    Ended::Overlong => "a line longer than 64 KiB".to_string(),
                };
                let n = c.drops.fetch_add(1, Relaxed) + 1;
                let since = tick(&c.drop_log);
                told = since.is_some();
                if let Some(since) = since {
                    tracing::warn!(
                        drops = n,
                        since_last_line = since,
                        "dvl: connection to {} lost: {why}",
                        s.address
                    );
                }
                c.set_error(format!("{}: {why}", s.address));
            }
            Ok(Err(e)) => connect_failed(s, hub, &e.to_string()),
            Err(_) => connect_failed(s, hub, "connect timed out"),
        }
        // Between attempts (at most `reconnect_max` + `connect_timeout`
        // apart); while connected, `session` asks once a second.
        settle(s, hub, Instant::now());
        tokio::select! {
            _ = &mut shutdown => return,
            _ = tokio::time::sleep(backoff.next_delay()) => {}
        }
    }
}

/// Whether to log a repeated event now, and for how many (core's rule).
fn tick(log: &std::sync::Mutex<lightpose_core::ratelog::RateLog>) -> Option<u64> {
    // A poisoned lock still holds a usable rule (MavCounters does the same).
    let mut l = log.lock().unwrap_or_else(|p| p.into_inner());
    l.tick(std::time::Instant::now())
}

/// The closing lines of failed connects and refused lines that stopped
/// (core's `RateLog::settle`), at the level of their lines.
fn settle(s: &DvlSettings, hub: &Hub, now: Instant) {
    close(s, hub, now, Close::Over);
}

/// The closing lines `when`: as [`settle`], or at stop every count not
/// told yet (core's `RateLog::flush`).
fn close(s: &DvlSettings, hub: &Hub, now: Instant, when: Close) {
    let c = &hub.dvl;
    let closed = |log: &std::sync::Mutex<lightpose_core::ratelog::RateLog>| {
        let mut l = log.lock().unwrap_or_else(|p| p.into_inner());
        l.close(now, when)
            .map(|k| (k, l.since_last(now).as_secs_f64()))
    };
    if let Some((since, ago)) = closed(&c.connect_log) {
        tracing::warn!(
            attempts = c.connect_failures.load(Relaxed),
            since_last_line = since,
            "dvl: failed connects to {}: {when}: {since} more since the last line, the last {ago:.1} s ago",
            s.address
        );
    }
    if let Some((since, ago)) = closed(&c.drop_log) {
        tracing::warn!(
            drops = c.drops.load(Relaxed),
            since_last_line = since,
            "dvl: lost connections to {}: {when}: {since} more since the last line, the last {ago:.1} s ago",
            s.address
        );
    }
    if let Some((since, ago)) = closed(&c.refuse_log) {
        let refused: u64 = c.refused.iter().map(|n| n.load(Relaxed)).sum();
        tracing::warn!(
            refused,
            since_last_line = since,
            "dvl: refused lines: {when}: {since} more since the last line, the last {ago:.1} s ago (STATUS dvl.refused)"
        );
    }
}

fn connect_failed(s: &DvlSettings, hub: &Hub, why: &str) {
    let k = hub.dvl.connect_failures.fetch_add(1, Relaxed) + 1;
    if let Some(since) = tick(&hub.dvl.connect_log) {
        tracing::warn!(
            attempts = k,
            since_last_line = since,
            "dvl: cannot connect to {}: {why}",
            s.address
        );
    }
    hub.dvl.set_error(format!("{}: {why}", s.address));
}

async fn session(
    s: &DvlSettings,
    hub: &Hub,
    mut stream: TcpStream,
    mut shutdown: std::pin::Pin<&mut impl Future<Output = ()>>,
    backoff: &mut Backoff,
) -> Ended {
    let mut chunk = [0u8; 4096];
    let mut line: Vec<u8> = Vec::with_capacity(4096);
    // The deadline moves only with a DVL message, not with any byte.
    let mut deadline = tokio::time::Instant::now() + s.silence;
    // The back-off starts again only for a connection that lasts: one
    // that a DVL closes after a report each time is retried less and less
    // often, as one that fails.
    let lasts = Instant::now() + s.reconnect_max;
    // The logs' closing lines, asked on the first read a second after the
    // last ask: the DVL reports at 2–15 Hz, and a DVL silent for
    // `silence` ends the session (then `run` asks between attempts).
    let mut settle_at = Instant::now();
    loop {
        let n = tokio::select! {
            _ = &mut shutdown => return Ended::Shutdown,
            r = tokio::time::timeout_at(deadline, stream.read(&mut chunk)) => match r {
                Err(_) => return Ended::Silent,
                Ok(Err(e)) => return Ended::Error(e),
                Ok(Ok(0)) => return Ended::Closed,
                Ok(Ok(n)) => n,
            },
        };
        let now = Instant::now();
        if now >= settle_at {
            settle(s, hub, now);
            settle_at = now + Duration::from_secs(1);
        }
        for &b in &chunk[..n] {
            if b != b'\n' {
                if line.len() >= MAX_LINE {
                    // No report is this long: the peer is no DVL, or broken.
                    refuse(hub, DvlRefusal::Garbage, "a line longer than 64 KiB");
                    return Ended::Overlong;
                }
                line.push(b);
                continue;
            }
            match take_line(s, hub, &line) {
                Heard::Report => {
                    if Instant::now() >= lasts {
                        backoff.reset();
                    }
                    deadline = tokio::time::Instant::now() + s.silence;
                }
                Heard::Message => deadline = tokio::time::Instant::now() + s.silence,
                Heard::Nothing => {}
            }
            line.clear();
        }
    }
}

/// Use one line; what it was.
fn take_line(s: &DvlSettings, hub: &Hub, line: &[u8]) -> Heard {
    let text = line.trim_ascii();
    if text.is_empty() {
        return Heard::Nothing;
    }
    match parse_line(text, s.max_speed_mps) {
        Ok(DvlLine::Velocity(v)) => {
            let now = Instant::now();
            let taken = v.latency.and_then(|l| now.checked_sub(l)).unwrap_or(now);
            hub.readings.store_velocity(taken, &v.reading);
            hub.dvl.reports.fetch_add(1, Relaxed);
            if v.high_temperature && hub.dvl.high_temperature.fetch_add(1, Relaxed) == 0 {
                tracing::warn!(
                    "dvl: reports high temperature (status bit 0): it will shut down soon"
                );
            }
            Heard::Report
        }
        Ok(DvlLine::Other) => {
            hub.dvl.other.fetch_add(1, Relaxed);
            Heard::Message
        }
        Err(r) => {
            // Control characters escaped: the line goes to the log.
            let head = String::from_utf8_lossy(&text[..text.len().min(60)]);
            refuse(hub, r, &lightpose_core::textfile::excerpt(&head, 60));
            match r {
                DvlRefusal::Garbage | DvlRefusal::Malformed => Heard::Nothing,
                // A velocity report, refused on its content.
                DvlRefusal::Invalid
                | DvlRefusal::WaterTrack
                | DvlRefusal::OutOfRange
                | DvlRefusal::BadCovariance
                | DvlRefusal::BadTime => Heard::Message,
            }
        }
    }
}

fn refuse(hub: &Hub, r: DvlRefusal, what: &str) {
    let k = hub.dvl.refused[r.index()].fetch_add(1, Relaxed) + 1;
    if let Some(since) = tick(&hub.dvl.refuse_log) {
        tracing::warn!(
            count = k,
            since_last_line = since,
            "dvl: refused ({}): {what}",
            r.as_str()
        );
    }
    hub.dvl.set_error(format!("{}: {what}", r.as_str()));
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Refused lines and failed connects that stop are told to the end:
    /// each log's first event at once, the rest by its closing line once
    /// none came for the step in force (1 s); once.
    #[test]
    fn refusals_and_failed_connects_that_stop_are_told_by_a_closing_line() {
        let hub = Hub::new();
        let s = DvlSettings::new("127.0.0.1:9");
        let text = lightpose_testkit::logs::logged(|| {
            for _ in 0..3 {
                refuse(&hub, DvlRefusal::Garbage, "not json");
            }
            refuse(&hub, DvlRefusal::Invalid, "velocity_valid false");
            for _ in 0..2 {
                connect_failed(&s, &hub, "connection refused");
            }
            let now = Instant::now();
            settle(&s, &hub, now);
            settle(&s, &hub, now + Duration::from_secs(2));
            settle(&s, &hub, now + Duration::from_secs(3));
        });
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 4, "{text}");
        assert!(
            lines[2].contains("WARN")
                && lines[2].contains("attempts=2 since_last_line=1")
                && lines[2].contains(
                    "dvl: failed connects to 127.0.0.1:9: the condition is over: 1 more since the last line"
                ),
            "{text}"
        );
        assert!(
            lines[3].contains("WARN")
                && lines[3].contains("refused=4 since_last_line=3")
                && lines[3].contains(
                    "dvl: refused lines: the condition is over: 3 more since the last line"
                ),
            "{text}"
        );
    }

    /// Refused lines and failed connects whose end the stop cuts (none
    /// for the step yet) are told at stop, each in one line; once.
    #[test]
    fn refusals_and_failed_connects_not_told_yet_are_told_at_stop() {
        let hub = Hub::new();
        let s = DvlSettings::new("127.0.0.1:9");
        let text = lightpose_testkit::logs::logged(|| {
            for _ in 0..3 {
                refuse(&hub, DvlRefusal::Garbage, "not json");
            }
            for _ in 0..2 {
                connect_failed(&s, &hub, "connection refused");
            }
            let now = Instant::now();
            settle(&s, &hub, now);
            close(&s, &hub, now, Close::AtStop);
            close(&s, &hub, now, Close::AtStop);
        });
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 4, "{text}");
        assert!(
            lines[2].contains("attempts=2 since_last_line=1")
                && lines[2].contains("dvl: failed connects to 127.0.0.1:9: at stop: 1 more"),
            "{text}"
        );
        assert!(
            lines[3].contains("refused=3 since_last_line=2")
                && lines[3].contains("dvl: refused lines: at stop: 2 more"),
            "{text}"
        );
    }

    /// A DVL that closes each connection after one good report (a network
    /// audit: reconnected every 0.5 s for good, with a "connected" and a
    /// "lost" line each time, 13 000 lines an hour): the back-off starts
    /// again only after a connection that lasted, and lost connections follow
    /// the rule for repeated lines. (Here, not in tests/: there, other
    /// tests' clients meet the same lines on threads without a subscriber,
    /// and tracing's cache of which lines are wanted then drops them here.)
    #[test]
    fn a_dvl_that_closes_after_each_report_is_retried_less_often_and_told_by_the_rule() {
        use std::io::Write;
        let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let port = listener.local_addr().unwrap().port();
        std::thread::spawn(move || {
            while let Ok((mut s, _)) = listener.accept() {
                let _ = s.write_all(
                    lightpose_testkit::dvl::report([0.3, 0.0, 0.0], true, 50_000).as_bytes(),
                );
            }
        });
        let hub = Hub::new();
        let mut s = DvlSettings::new(format!("127.0.0.1:{port}"));
        s.reconnect_first = Duration::from_millis(25);
        s.reconnect_max = Duration::from_millis(400);
        let run_for = Duration::from_secs(2);
        let text = lightpose_testkit::logs::logged(|| {
            let rt = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
                .unwrap();
            rt.block_on(async {
                let stop = tokio::time::sleep(run_for);
                run(s, hub.clone(), stop).await
            });
        });
        let c = &hub.dvl;
        // 25, 50, 100, 200, 400, 400, … ms apart: 8 or so in 2 s, where a
        // back-off started again by each report made 80.
        assert!(
            (3..=12).contains(&c.connects()),
            "{} connects\n{text}",
            c.connects()
        );
        assert!(c.reports() >= 3, "{} reports", c.reports());
        let lost = text.matches("dvl: connection to").count();
        let connected = text.matches("dvl: connected to").count();
        assert!(lost <= 3 && connected <= lost + 1, "{text}");
        assert!(
            text.contains("dvl: lost connections to") && text.contains("at stop"),
            "the count not told yet is told at stop:\n{text}"
        );
    }
}
