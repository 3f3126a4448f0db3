//! Optional attitude input: the vehicle's AHRS sends
//! `{"class":"ATTITUDE","t":..,"pitch":..,"yaw":..}` over UDP, and spec v3's
//! `"roll":..` when it has one (degrees, starboard side down: the same
//! angle in B as on the compass); yaw is the
//! compass heading, referred here to the beam frame with the beacon's axis
//! heading so that each frame carries pitch and yaw in B (MODEL.md), which is
//! what lets an estimator tell y from yaw and z from pitch. A sender without
//! `roll` (spec v2's) gives readings without roll, as before: not a roll of
//! 0, which would claim a level vehicle.
//!
//! A datagram is refused, counted by reason (STATUS `attitude.rejected_by`)
//! and logged (the first, then every 100th) when it is not a JSON object of
//! numbers (`malformed`), not of class ATTITUDE (`class`), has no `t` that
//! is a time in seconds (|t| ≤ 1e10, the rule of core's `FrameOrder`:
//! `time`), or a pitch outside ±90°, a roll outside ±180° or a heading
//! outside ±360° (`angle`; a `"roll":null` is no roll).
//! A datagram the same byte for byte as the one before, `t` included, is
//! taken (an AHRS at rest behind a sender that leaves `t` alone sends
//! just that) but counted `repeated`, and told once it has lasted
//! [`FROZEN_AFTER`]: a bridge that re-sends a stopped AHRS's last reading
//! looks the same, and keeps that reading fresh.
//! With `allow_from`, a datagram from any other sender is refused unread
//! (`sender`), its refusals logged apart so that a stranger's flood cannot
//! crowd out the lines about the AHRS's own.

use super::Input;
use crate::config::AttitudeInput;
use lightpose_core::log::plausible_t;
use lightpose_core::ratelog::{Close, RateLog};
use lightpose_core::textfile::excerpt;
use lightpose_core::{Angle, AttitudeReading, Frame};
use lightpose_vehicle::readings::ReadingStatus;
use lightpose_vehicle::Readings;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::time::{Duration, Instant};

/// Why a datagram was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reason {
    Malformed = 0,
    Class = 1,
    Time = 2,
    Angle = 3,
    Sender = 4,
}

impl Reason {
    pub const ALL: [Reason; 5] = [
        Reason::Malformed,
        Reason::Class,
        Reason::Time,
        Reason::Angle,
        Reason::Sender,
    ];
    pub fn as_str(self) -> &'static str {
        match self {
            Reason::Malformed => "malformed",
            Reason::Class => "class",
            Reason::Time => "time",
            Reason::Angle => "angle",
            Reason::Sender => "sender",
        }
    }
}

/// A refused datagram: why, and a one-line message.
#[derive(Debug, Clone, PartialEq)]
pub struct Rejected {
    pub reason: Reason,
    pub msg: String,
}

impl std::fmt::Display for Rejected {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.msg)
    }
}

/// The latest reading, written by the listener and read once per frame:
/// the vehicle's own lock-free attitude slot ([`Readings`]), so that under
/// a flood of valid datagrams the frame thread never waits on the
/// receiver; with this input's counts.
#[derive(Default)]
pub struct AttitudeCell {
    latest: Readings,
    pub received: AtomicU64,
    pub rejected: AtomicU64,
    /// Refusals by [`Reason`], in the order of [`Reason::ALL`].
    pub rejected_by: [AtomicU64; Reason::ALL.len()],
    /// Datagrams taken that were the same as the one before, `t` too.
    pub repeated: AtomicU64,
    /// Frames that got this input's reading.
    pub attached: AtomicU64,
    /// Frames that carried their own attitude (the simulator's sensor, a
    /// replayed log's) while this input had a fresh one: theirs won.
    pub superseded: AtomicU64,
}

impl AttitudeCell {
    /// Count a refusal; the total after it.
    pub fn reject(&self, reason: Reason) -> u64 {
        self.rejected_by[reason as usize].fetch_add(1, Relaxed);
        self.rejected.fetch_add(1, Relaxed) + 1
    }

    pub fn store(&self, at: Instant, r: AttitudeReading) {
        self.latest.store_attitude(at, &r);
        self.received.fetch_add(1, Relaxed);
    }

    /// The latest reading if it is younger than `max_age` at `at` (one
    /// received after `at` is fresh). No rates come with it: as received.
    #[inline]
    pub fn fresh(&self, at: Instant, max_age: Duration) -> Option<AttitudeReading> {
        self.latest.attitude(at, max_age)
    }

    /// Age of the latest reading, for STATUS.
    pub fn age(&self, now: Instant) -> Option<Duration> {
        self.latest.attitude_age(now)
    }

    /// This input's figures as a hub reading's, for STATUS and the stale
    /// watch: frames that got it, and that found only an old one.
    pub fn status(&self, now: Instant) -> ReadingStatus {
        let s = self.latest.status(now).attitude;
        ReadingStatus {
            attached: self.attached.load(Relaxed),
            ..s
        }
    }
}

/// The engine's end of the cell: the latest reading, attached to a frame
/// that has none when it is younger than `max_age`.
pub struct LatestAttitude {
    pub cell: std::sync::Arc<AttitudeCell>,
    pub max_age: Duration,
    /// Whether the first superseded reading was told.
    told_superseded: bool,
}

impl LatestAttitude {
    pub fn new(cell: std::sync::Arc<AttitudeCell>, max_age: Duration) -> Self {
        LatestAttitude {
            cell,
            max_age,
            told_superseded: false,
        }
    }
}

impl Input for LatestAttitude {
    #[inline]
    fn attach(&mut self, frame: &mut Frame, capture: Instant) {
        // No rates come with it: attached as received, if fresh at the
        // capture.
        if frame.attitude.is_none() {
            frame.attitude = self.cell.fresh(capture, self.max_age);
            if frame.attitude.is_some() {
                self.cell.attached.fetch_add(1, Relaxed);
            }
            return;
        }
        // Frames with their own reading (a replayed log, a scene with an
        // [attitude] sensor) keep it. The input's readings then go unused:
        // counted, and told once, or STATUS would look healthy while the
        // AHRS's pitch and yaw reach no estimate.
        // Its age, not `fresh`, which would count it stale when old: the
        // frame has an attitude, and the stale watch would say it went
        // without.
        if self.cell.age(capture).is_some_and(|a| a <= self.max_age) {
            self.cell.superseded.fetch_add(1, Relaxed);
            if !self.told_superseded {
                self.told_superseded = true;
                tracing::warn!("attitude input: the frames carry an attitude of their own (the simulator's sensor or the replayed log's), which wins over this input's: its readings go unused, counted in STATUS attitude.superseded");
            }
        }
    }
}

/// Wrap degrees into (−180, 180].
pub fn wrap180(deg: f64) -> f64 {
    let r = deg.rem_euclid(360.0);
    if r > 180.0 {
        r - 360.0
    } else {
        r
    }
}

/// Parse one ATTITUDE datagram into a reading in B.
///
/// A vehicle that faces the beacon (yaw 0 in B) heads opposite to the
/// beacon's axis, and a turn to starboard raises both the compass heading
/// and yaw in B: ψ_B = heading − (axis heading + 180°).
pub fn parse(datagram: &[u8], beacon_axis_heading_deg: f64) -> Result<AttitudeReading, Rejected> {
    #[derive(serde::Deserialize)]
    struct Msg {
        class: String,
        #[serde(default)]
        t: Option<serde_json::Value>,
        pitch: f64,
        yaw: f64,
        #[serde(default)]
        roll: Option<f64>,
    }
    let no = |reason, msg: String| Rejected { reason, msg };
    // serde takes a struct from an array too (["ATTITUDE", t, pitch, yaw]
    // was read as one): an object or nothing.
    if !datagram.trim_ascii_start().starts_with(b"{") {
        return Err(no(
            Reason::Malformed,
            "not an ATTITUDE message: not a JSON object".into(),
        ));
    }
    let m: Msg = serde_json::from_slice(datagram).map_err(|e| {
        let e = excerpt(&e.to_string(), 120);
        no(Reason::Malformed, format!("not an ATTITUDE message: {e}"))
    })?;
    if m.class != "ATTITUDE" {
        let class = excerpt(&m.class, 40);
        return Err(no(
            Reason::Class,
            format!("class \"{class}\" is not ATTITUDE"),
        ));
    }
    match m.t.as_ref().map(|t| t.as_f64()) {
        Some(Some(t)) if plausible_t(t) => {}
        Some(Some(t)) => {
            return Err(no(
                Reason::Time,
                format!("t = {t:e} is not a time (|t| ≤ 1e10 s)"),
            ))
        }
        Some(None) => return Err(no(Reason::Time, "t is not a number of seconds".into())),
        None => return Err(no(Reason::Time, "t is missing".into())),
    }
    if !m.pitch.is_finite() || m.pitch.abs() > 90.0 {
        return Err(no(
            Reason::Angle,
            format!("pitch {:e}° is not in -90..=90", m.pitch),
        ));
    }
    if !m.yaw.is_finite() || m.yaw.abs() > 360.0 {
        return Err(no(
            Reason::Angle,
            format!("yaw {:e}° is not a heading in -360..=360", m.yaw),
        ));
    }
    if let Some(r) = m.roll.filter(|r| !r.is_finite() || r.abs() > 180.0) {
        return Err(no(
            Reason::Angle,
            format!("roll {r:e}° is not in -180..=180"),
        ));
    }
    Ok(AttitudeReading {
        pitch: Angle::from_deg(m.pitch),
        yaw: Angle::from_deg(wrap180(m.yaw - beacon_axis_heading_deg - 180.0)),
        roll: m.roll.map(Angle::from_deg),
        std: None,
    })
}

/// Whether `allow_from` (if given) lets `from` send.
#[inline]
fn admitted(cfg: &AttitudeInput, from: SocketAddr) -> bool {
    cfg.allow_from
        .as_ref()
        .is_none_or(|list| list.iter().any(|s| s.admits(from)))
}

/// Receive ATTITUDE datagrams until the task is dropped.
pub async fn listen(
    sock: tokio::net::UdpSocket,
    cfg: AttitudeInput,
    cell: std::sync::Arc<AttitudeCell>,
) {
    // Any UDP datagram whole: a longer one cut to a smaller buffer had its
    // tail unread (garbage past byte 2048 went unseen).
    let mut buf = vec![0u8; 1 << 16];
    // The last datagram taken, for `repeated`.
    let mut last = Repeats::default();
    let repeated = &cell.repeated;
    // A peer sending garbage at any rate costs lines by core's rule, not
    // one per 100 datagrams; strangers have their own log so that their
    // flood does not hide the AHRS's refusals. Dropped with the task
    // (aborted at stop), they tell what is pending.
    let mut logs = RefusalLogs {
        ahrs: RateLog::new(),
        strangers: RateLog::new(),
        cell: cell.clone(),
    };
    loop {
        // Refusals not told yet: wake at least every second for their
        // closing line (the AHRS may stop sending too; recv_from is
        // cancel-safe); else wait for the next datagram as long as it
        // takes.
        let pending = logs.ahrs.pending() > 0 || logs.strangers.pending() > 0;
        let got = if pending {
            tokio::time::timeout(Duration::from_secs(1), sock.recv_from(&mut buf))
                .await
                .ok()
        } else {
            Some(sock.recv_from(&mut buf).await)
        };
        if pending {
            logs.close(Instant::now(), Close::Over);
        }
        let Some(got) = got else { continue };
        let (n, from) = match got {
            Ok(x) => x,
            Err(e) => {
                tracing::warn!("attitude: receive failed: {e}");
                tokio::time::sleep(Duration::from_millis(100)).await;
                continue;
            }
        };
        if !admitted(&cfg, from) {
            // Not parsed: a stranger's content is neither read nor quoted.
            let k = cell.reject(Reason::Sender);
            if let Some(since) = logs.strangers.tick(Instant::now()) {
                tracing::warn!(from = %from, rejected = k, since_last_line = since, reason = Reason::Sender.as_str(), "attitude: datagram from {from} refused: not in attitude.allow_from");
            }
            continue;
        }
        let datagram = &buf[..n];
        match parse(datagram, cfg.beacon_axis_heading_deg) {
            Ok(r) => {
                let now = Instant::now();
                if last.same(datagram, now) {
                    repeated.fetch_add(1, Relaxed);
                }
                cell.store(now, r);
            }
            Err(e) => {
                let k = cell.reject(e.reason);
                if let Some(since) = logs.ahrs.tick(Instant::now()) {
                    tracing::warn!(from = %from, rejected = k, since_last_line = since, reason = e.reason.as_str(), "attitude: {e}");
                }
            }
        }
    }
}

/// How long the same datagram, `t` included, may come before it is told.
pub const FROZEN_AFTER: Duration = Duration::from_secs(10);

/// The last datagram taken, and since when the same one comes.
#[derive(Default)]
struct Repeats {
    last: Vec<u8>,
    since: Option<Instant>,
    told: bool,
}

impl Repeats {
    /// Whether `datagram` (taken at `now`) is the same as the last one;
    /// told once the same has come for [`FROZEN_AFTER`], and when it
    /// changes after that. Allocates only while datagrams grow longer
    /// than any before.
    fn same(&mut self, datagram: &[u8], now: Instant) -> bool {
        if self.last == datagram {
            let since = *self.since.get_or_insert(now);
            if !self.told && now.saturating_duration_since(since) >= FROZEN_AFTER {
                self.told = true;
                tracing::warn!(
                    "attitude input: the same datagram, t included, for {} s: a bridge re-sending a stopped AHRS's last reading keeps it fresh; have the sender stamp t with each reading (STATUS attitude.repeated)",
                    FROZEN_AFTER.as_secs()
                );
            }
            return true;
        }
        if self.told {
            let s = self
                .since
                .map_or(0.0, |s| now.saturating_duration_since(s).as_secs_f64());
            tracing::info!("attitude input: datagrams change again after {s:.1} s of the same one");
        }
        self.since = None;
        self.told = false;
        self.last.clear();
        self.last.extend_from_slice(datagram);
        false
    }
}

/// The listener's refusals, by core's rule for repeated lines: the AHRS's,
/// and strangers' apart (their flood must not hide the AHRS's refusals).
struct RefusalLogs {
    ahrs: RateLog,
    strangers: RateLog,
    cell: std::sync::Arc<AttitudeCell>,
}

impl RefusalLogs {
    /// The closing lines of refusals `when` (core's `RateLog::settle`
    /// once they stopped, `RateLog::flush` at stop): the AHRS's, then
    /// strangers'.
    fn close(&mut self, now: Instant, when: Close) {
        let rejected = || self.cell.rejected.load(Relaxed);
        if let Some(since) = self.ahrs.close(now, when) {
            tracing::warn!(
                rejected = rejected(),
                since_last_line = since,
                "attitude: datagrams refused: {when}: {since} more since the last line, the last {:.1} s ago",
                self.ahrs.since_last(now).as_secs_f64()
            );
        }
        if let Some(since) = self.strangers.close(now, when) {
            tracing::warn!(
                rejected = rejected(),
                since_last_line = since,
                reason = Reason::Sender.as_str(),
                "attitude: datagrams from senders not in attitude.allow_from: {when}: {since} more since the last line, the last {:.1} s ago",
                self.strangers.since_last(now).as_secs_f64()
            );
        }
    }
}

/// The listener ends only by being dropped (its task aborted at stop).
impl Drop for RefusalLogs {
    fn drop(&mut self) {
        self.close(Instant::now(), Close::AtStop);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use lightpose_core::AttitudeStd;

    #[test]
    fn heading_is_referred_to_the_beam() {
        // Beam points north (0°): facing the beacon is heading 180° = yaw 0.
        let r = parse(
            br#"{"class":"ATTITUDE","t":1.0,"pitch":5.0,"yaw":180.0}"#,
            0.0,
        )
        .unwrap();
        assert!(r.yaw.deg().abs() < 1e-9);
        assert!((r.pitch.deg() - 5.0).abs() < 1e-9);
        // Heading 190° is 10° to starboard of facing the beacon.
        let r = parse(br#"{"class":"ATTITUDE","t":1.0,"pitch":0,"yaw":190}"#, 0.0).unwrap();
        assert!((r.yaw.deg() - 10.0).abs() < 1e-9);
        // Beam points east (90°): facing it is heading 270°; 265° is −5°.
        let r = parse(br#"{"class":"ATTITUDE","t":0,"pitch":0,"yaw":265}"#, 90.0).unwrap();
        assert!((r.yaw.deg() + 5.0).abs() < 1e-9);
    }

    #[test]
    fn bad_datagrams_are_refused_with_reason() {
        assert!(parse(b"garbage", 0.0)
            .unwrap_err()
            .msg
            .contains("not an ATTITUDE"));
        let e = parse(br#"{"class":"POSE","pitch":0,"yaw":0}"#, 0.0).unwrap_err();
        assert!(e.msg.contains("POSE") && e.reason == Reason::Class, "{e}");
        assert!(parse(br#"{"class":"ATTITUDE","pitch":100,"yaw":0}"#, 0.0).is_err());
    }

    /// Issue 16: t must be a time, angles finite and in range.
    #[test]
    fn malformed_times_and_angles_are_refused() {
        use Reason::{Angle as A, Time as T};
        for (d, names, reason) in [
            (r#"{"class":"ATTITUDE","t":1e12,"pitch":0,"yaw":0}"#, "t", T),
            (
                r#"{"class":"ATTITUDE","t":-1e12,"pitch":0,"yaw":0}"#,
                "t",
                T,
            ),
            (
                r#"{"class":"ATTITUDE","t":"yesterday","pitch":0,"yaw":0}"#,
                "t",
                T,
            ),
            (r#"{"class":"ATTITUDE","pitch":0,"yaw":0}"#, "t", T),
            (
                r#"{"class":"ATTITUDE","t":1.0,"pitch":0,"yaw":1e308}"#,
                "yaw",
                A,
            ),
            (
                r#"{"class":"ATTITUDE","t":1.0,"pitch":0,"yaw":-400}"#,
                "yaw",
                A,
            ),
            (
                r#"{"class":"ATTITUDE","t":1.0,"pitch":-90.5,"yaw":0}"#,
                "pitch",
                A,
            ),
        ] {
            let e = parse(d.as_bytes(), 0.0).map(|r| r.yaw.deg()).unwrap_err();
            assert!(e.msg.contains(names) && e.reason == reason, "{d}: {e:?}");
        }
        let long = format!(
            r#"{{"class":"{}","t":1,"pitch":0,"yaw":0}}"#,
            "x".repeat(5000)
        );
        assert!(parse(long.as_bytes(), 0.0).unwrap_err().msg.len() < 300);
        // Found by the fuzz target: a class with newlines in it is quoted
        // on one line.
        let e = parse(
            br#"{"class":"A#b\ny\n{ \nK#b\n\n\n\nTTITUDE","t":1.0,"pitch":4.0,"yaw":280.0}"#,
            0.0,
        )
        .unwrap_err();
        assert!(
            !e.msg.contains('\n') && e.msg.contains(r"A#b\ny"),
            "{}",
            e.msg
        );
        let e = parse(format!("\"{}\"", "y".repeat(5000)).as_bytes(), 0.0).unwrap_err();
        assert!(
            e.msg.len() < 300 && e.reason == Reason::Malformed,
            "{}",
            e.msg.len()
        );
        let c = AttitudeCell::default();
        assert_eq!((c.reject(T), c.reject(A), c.reject(T)), (1, 2, 3));
        assert_eq!(c.rejected_by[Reason::Time as usize].load(Relaxed), 2);
        // In range: heading 0..360 (and -360..0), t an epoch's seconds.
        assert!(parse(
            br#"{"class":"ATTITUDE","t":1.7e9,"pitch":-90,"yaw":359.9}"#,
            0.0
        )
        .is_ok());
        assert!(parse(br#"{"class":"ATTITUDE","t":0,"pitch":90,"yaw":-360}"#, 0.0).is_ok());
    }

    fn reading(pitch: f64, yaw: f64, std: Option<(f64, f64)>) -> AttitudeReading {
        AttitudeReading {
            pitch: Angle::from_deg(pitch),
            yaw: Angle::from_deg(yaw),
            roll: None,
            std: std.map(|(p, y)| AttitudeStd {
                pitch: Angle::from_deg(p),
                yaw: Angle::from_deg(y),
            }),
        }
    }

    /// Audit item 2: the lock-free cell gives the latest reading, its σ
    /// and its age as the mutex did.
    #[test]
    fn the_cell_gives_the_latest_reading() {
        let c = AttitudeCell::default();
        let t0 = Instant::now();
        assert!(c.age(t0).is_none());
        c.store(t0, reading(1.0, 2.0, Some((0.5, 1.5))));
        let t1 = t0 + Duration::from_millis(40);
        c.store(t1, reading(-3.0, 170.0, None));
        let got = c.fresh(t1, Duration::from_millis(1)).expect("fresh");
        assert_eq!(got, reading(-3.0, 170.0, None));
        assert_eq!(
            c.age(t1 + Duration::from_millis(7)),
            Some(Duration::from_millis(7))
        );
        c.store(t1, reading(4.0, -5.0, Some((0.25, 2.0))));
        assert_eq!(
            c.fresh(t1, Duration::ZERO),
            Some(reading(4.0, -5.0, Some((0.25, 2.0))))
        );
        assert_eq!(c.received.load(Relaxed), 3);
    }

    /// A reader alongside a flooding writer sees whole readings only, and
    /// the last one once the writer stops.
    #[test]
    fn a_reader_beside_a_flood_sees_whole_readings() {
        let c = std::sync::Arc::new(AttitudeCell::default());
        let w = {
            let c = c.clone();
            std::thread::spawn(move || {
                for k in 0..200_000u32 {
                    let v = f64::from(k % 90);
                    c.store(Instant::now(), reading(v, -v, Some((v, v))));
                }
            })
        };
        let max = Duration::from_secs(60);
        while !w.is_finished() {
            if let Some(r) = c.fresh(Instant::now(), max) {
                assert_eq!(r.yaw, -r.pitch);
                assert_eq!(r.std.map(|s| s.pitch), Some(r.pitch));
            }
        }
        w.join().expect("writer");
        let last = f64::from(199_999u32 % 90);
        assert_eq!(
            c.fresh(Instant::now(), max),
            Some(reading(last, -last, Some((last, last))))
        );
    }

    #[test]
    fn stale_readings_are_not_fresh() {
        let c = AttitudeCell::default();
        let t0 = Instant::now();
        assert!(c.fresh(t0, Duration::from_secs(1)).is_none());
        c.store(
            t0,
            AttitudeReading {
                pitch: Angle::ZERO,
                yaw: Angle::ZERO,
                roll: None,
                std: None,
            },
        );
        assert!(c
            .fresh(t0 + Duration::from_millis(100), Duration::from_millis(500))
            .is_some());
        assert!(c
            .fresh(t0 + Duration::from_secs(1), Duration::from_millis(500))
            .is_none());
        assert_eq!(wrap180(190.0), -170.0);
        assert_eq!(wrap180(-180.0), 180.0);
    }

    /// Spec v3: a sender's roll goes on the reading as it is (and through
    /// the cell); without one (spec v2's sender) the reading has none.
    #[test]
    fn roll_is_read_when_the_sender_gives_it() {
        let r = parse(
            br#"{"class":"ATTITUDE","t":1.0,"pitch":2,"yaw":190,"roll":-6.5}"#,
            0.0,
        )
        .unwrap();
        assert_eq!(r.roll.map(|a| a.deg()), Some(-6.5));
        assert!((r.yaw.deg() - 10.0).abs() < 1e-9);
        let v2 = parse(br#"{"class":"ATTITUDE","t":1.0,"pitch":2,"yaw":190}"#, 0.0).unwrap();
        assert_eq!(v2.roll, None);
        let null = br#"{"class":"ATTITUDE","t":1.0,"pitch":2,"yaw":190,"roll":null}"#;
        assert_eq!(parse(null, 0.0).unwrap().roll, None);
        for bad in [
            &br#"{"class":"ATTITUDE","t":1.0,"pitch":2,"yaw":190,"roll":181}"#[..],
            br#"{"class":"ATTITUDE","t":1.0,"pitch":2,"yaw":190,"roll":-1e300}"#,
        ] {
            let e = parse(bad, 0.0).unwrap_err();
            assert!(e.reason == Reason::Angle && e.msg.contains("roll"), "{e}");
        }
        let e = parse(
            br#"{"class":"ATTITUDE","t":1.0,"pitch":2,"yaw":190,"roll":"level"}"#,
            0.0,
        )
        .unwrap_err();
        assert_eq!(e.reason, Reason::Malformed);
        let c = AttitudeCell::default();
        let t0 = Instant::now();
        c.store(t0, r);
        assert_eq!(c.fresh(t0, Duration::ZERO), Some(r));
        c.store(t0, v2);
        assert_eq!(c.fresh(t0, Duration::ZERO).map(|a| a.roll), Some(None));
    }

    /// Audit: an array with the fields in order was read as a message.
    #[test]
    fn arrays_are_refused() {
        let e = parse(br#" ["ATTITUDE", 1.7e9, 42.0, 200.0]"#, 0.0).unwrap_err();
        assert!(
            e.reason == Reason::Malformed && e.msg.contains("not a JSON object"),
            "{e}"
        );
    }

    /// Audit: a datagram re-sent whole kept its reading fresh unsaid. It
    /// is still taken (an AHRS at rest behind a sender that leaves t alone
    /// sends the same), counted, and told once after FROZEN_AFTER.
    #[test]
    fn repeats_are_counted_and_a_frozen_sender_told() {
        let d1 = br#"{"class":"ATTITUDE","t":1,"pitch":3,"yaw":10}"#;
        let d2 = br#"{"class":"ATTITUDE","t":2,"pitch":3,"yaw":10}"#;
        let t0 = Instant::now();
        let text = lightpose_testkit::logs::logged(|| {
            let mut r = Repeats::default();
            assert!(!r.same(d1, t0));
            assert!(r.same(d1, t0 + Duration::from_secs(1)));
            // t on, same angles: no repeat.
            assert!(!r.same(d2, t0 + Duration::from_secs(2)));
            for k in 0..=12 {
                assert!(r.same(d2, t0 + Duration::from_secs(3 + k)));
            }
            assert!(!r.same(d1, t0 + Duration::from_secs(16)));
        });
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 2, "{text}");
        assert!(
            lines[0].contains("WARN")
                && lines[0].contains("the same datagram, t included, for 10 s"),
            "{text}"
        );
        assert!(lines[1].contains("change again after 13.0 s"), "{text}");
    }

    /// Audit: with frames that carry their own attitude (a scene with an
    /// [attitude] sensor), the input's fresh readings were counted received
    /// and went nowhere unsaid; they are counted superseded, the frame's
    /// kept, and a frame without one gets the input's, counted attached.
    #[test]
    fn a_frame_s_own_attitude_supersedes_the_input_s() {
        let cell = std::sync::Arc::new(AttitudeCell::default());
        let mut input = LatestAttitude::new(cell.clone(), Duration::from_secs(1));
        let t0 = Instant::now();
        cell.store(t0, reading(5.0, 1.0, None));
        let mut own = Frame::new(0, 0.0, 10, [0; lightpose_core::NDET]);
        own.attitude = Some(reading(2.0, 0.0, None));
        input.attach(&mut own, t0);
        input.attach(&mut own, t0);
        assert_eq!(own.attitude.map(|a| a.pitch.deg()), Some(2.0));
        let mut bare = Frame::new(1, 0.1, 10, [0; lightpose_core::NDET]);
        input.attach(&mut bare, t0);
        assert_eq!(bare.attitude.map(|a| a.pitch.deg()), Some(5.0));
        assert_eq!(
            (cell.superseded.load(Relaxed), cell.attached.load(Relaxed)),
            (2, 1)
        );
        // Stale: counted so, neither attached nor superseded.
        let mut late = Frame::new(2, 2.0, 10, [0; lightpose_core::NDET]);
        input.attach(&mut late, t0 + Duration::from_secs(2));
        let st = cell.status(t0 + Duration::from_secs(2));
        assert_eq!((st.attached, st.stale, late.attitude), (1, 1, None));
        // A frame with its own attitude and the input's reading old:
        // neither superseded nor stale (a re-audit: the stale watch then
        // said frames went without an attitude they had).
        own.seq = 3;
        input.attach(&mut own, t0 + Duration::from_secs(3));
        let st = cell.status(t0 + Duration::from_secs(3));
        assert_eq!((st.stale, cell.superseded.load(Relaxed)), (1, 2));
    }

    /// Refusals whose end the stop cuts: the listener's task is aborted
    /// (the supervisor awaits it), and its logs, dropped with it, tell
    /// what is pending at stop, the AHRS's and strangers' apart; the
    /// journal's counts then add up to `rejected`.
    #[test]
    fn refusals_not_told_yet_are_told_when_the_listener_is_aborted() {
        let text = lightpose_testkit::logs::logged(|| {
            let rt = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
                .unwrap();
            rt.block_on(async {
                let sock = tokio::net::UdpSocket::bind("127.0.0.1:0").await.unwrap();
                let to = sock.local_addr().unwrap();
                let cfg = AttitudeInput {
                    listen: to,
                    beacon_axis_heading_deg: 0.0,
                    max_age: Duration::from_secs(1),
                    allow_from: Some(vec![crate::config::attitude::Sender {
                        ip: "127.0.0.2".parse().unwrap(),
                        port: None,
                    }]),
                };
                let cell = std::sync::Arc::new(AttitudeCell::default());
                let task = tokio::spawn(listen(sock, cfg, cell.clone()));
                let peer = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
                for _ in 0..3 {
                    peer.send_to(b"not an attitude", to).unwrap();
                }
                let deadline = Instant::now() + Duration::from_secs(5);
                while cell.rejected.load(Relaxed) < 3 && Instant::now() < deadline {
                    tokio::time::sleep(Duration::from_millis(5)).await;
                }
                assert_eq!(cell.rejected.load(Relaxed), 3);
                task.abort();
                assert!(task.await.unwrap_err().is_cancelled());
            });
        });
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 2, "{text}");
        assert!(lines[0].contains("since_last_line=1"), "{text}");
        assert!(
            lines[1].contains("WARN")
                && lines[1].contains("rejected=3 since_last_line=2")
                && lines[1].contains(
                    "attitude: datagrams from senders not in attitude.allow_from: at stop: 2 more since the last line"
                ),
            "{text}"
        );
    }
}
