//! The MAVLink component as one tokio task: it reads the autopilot's
//! messages into the hub's readings, sends the outbox's poses and a
//! heartbeat, and reopens the link (with a capped back-off) when it fails.
//! It returns only when `shutdown` resolves.

use super::counters::{AutopilotId, LastError, NetOp, SigningStatus};
use super::inbound::{
    interpret, is_autopilot_heartbeat, origin, Input, InputConfig, Refusal, Refused,
};
use super::link::{Endpoint, Link, PeerChange, PEER_SILENCE};
use super::outbound::{heartbeat, monotonic_ns, timesync_reply, OutputConfig};
use super::scan::{Framing, RawFrame, Scanned, Scanner};
use super::sender::Sender;
use super::signing::{Rejected, Signer, SigningConfig};
use crate::backoff::Backoff;
use crate::ned::Site;
use crate::Hub;
use lightpose_core::ratelog::{Close, RateLog};
use std::future::Future;
use std::io;
use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::atomic::Ordering::Relaxed;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Everything the MAVLink task needs to know.
#[derive(Debug, Clone, PartialEq)]
pub struct MavlinkSettings {
    pub endpoint: Endpoint,
    /// This component's system id: the vehicle's (the autopilot's).
    pub system_id: u8,
    /// This component's id (197, MAV_COMP_ID_VISUAL_INERTIAL_ODOMETRY, by
    /// default).
    pub component_id: u8,
    pub site: Site,
    pub input: InputConfig,
    pub output: OutputConfig,
    pub heartbeat_period: Duration,
    /// Longest wait between attempts to (re)open the link.
    pub reopen_max: Duration,
    /// MAVLink 2 signing: every frame sent signed, only signed frames
    /// taken (`signing`).
    pub signing: Option<SigningConfig>,
}

impl MavlinkSettings {
    /// Defaults around an endpoint and a site.
    pub fn new(endpoint: Endpoint, site: Site) -> Self {
        MavlinkSettings {
            endpoint,
            system_id: 1,
            component_id: 197,
            site,
            input: InputConfig::default(),
            output: OutputConfig::default(),
            heartbeat_period: Duration::from_secs(1),
            reopen_max: Duration::from_secs(5),
            signing: None,
        }
    }
}

/// ArduPilot's visual odometry is unhealthy when no estimate came in the
/// last 300 ms (`AP_VISUALODOM_TIMEOUT_MS`): a pre-arm failure ("VisOdom:
/// not healthy") and gaps in what the EKF fuses. Below this rate the
/// limit alone leaves no margin.
pub const MIN_POSITION_RATE_HZ: f64 = 4.0;

/// Why the position rate limit is too slow for the autopilot, if it is.
pub fn slow_rate(out: &OutputConfig) -> Option<String> {
    let r = out.position_rate_hz.filter(|r| *r < MIN_POSITION_RATE_HZ)?;
    Some(format!(
        "position_rate_hz = {r} sends a VISION_POSITION_ESTIMATE at most every {:.0} ms; \
         ArduPilot calls visual odometry unhealthy after 300 ms without one \
         (pre-arm \"VisOdom: not healthy\", gaps in the EKF): use {MIN_POSITION_RATE_HZ} Hz or more",
        1000.0 / r
    ))
}

/// How a session on one open link ended.
enum Ended {
    Shutdown,
    Lost(io::Error),
}

/// Run the MAVLink component until `shutdown` resolves.
pub async fn run(s: MavlinkSettings, hub: Arc<Hub>, shutdown: impl Future<Output = ()>) {
    run_with(s, hub, None, shutdown).await
}

/// As [`run`], on a link the caller has already opened (the daemon opens
/// it before it starts, so that a port it cannot have stops the start);
/// later failures reopen it as `run` does.
pub async fn run_with(
    s: MavlinkSettings,
    hub: Arc<Hub>,
    mut first: Option<Link>,
    shutdown: impl Future<Output = ()>,
) {
    if let Some(why) = slow_rate(&s.output) {
        tracing::warn!("mavlink: {why}");
    }
    announce_signing(&s, &hub);
    let mut shutdown = std::pin::pin!(shutdown);
    let mut backoff = Backoff::new(Duration::from_millis(200), s.reopen_max);
    let mut tx = Sender::new(&s);
    let mut ap = Autopilot::new(&s.input, &hub);
    let c = &hub.mavlink;
    // Failed opens (an autopilot off for the week, its serial device
    // gone): core's rule, not every 20th attempt (a line every 100 s at
    // the 5 s back-off).
    let mut open_log = RateLog::new();
    loop {
        let opened = match first.take() {
            Some(link) => Ok(link),
            None => tokio::select! {
                _ = &mut shutdown => break,
                r = Link::open(&s.endpoint) => r,
            },
        };
        match opened {
            Ok(link) => {
                c.link_opens.fetch_add(1, Relaxed);
                tracing::info!("mavlink: link open on {}", s.endpoint);
                let io = Io {
                    tx: &mut tx,
                    ap: &mut ap,
                    backoff: &mut backoff,
                    open_log: &mut open_log,
                };
                match serve(&s, &hub, link, io, shutdown.as_mut()).await {
                    Ended::Shutdown => break,
                    Ended::Lost(e) => {
                        c.link_failures.fetch_add(1, Relaxed);
                        tracing::warn!("mavlink: link {} lost: {e}", s.endpoint);
                        c.set_error(LastError::Io(format!("{}: {e}", s.endpoint)));
                    }
                }
            }
            Err(e) => {
                let k = c.link_failures.fetch_add(1, Relaxed) + 1;
                let line = crate::error_chain(&e);
                if let Some(since) = open_log.tick(Instant::now()) {
                    tracing::warn!(attempts = k, since_last_line = since, "mavlink: {line}");
                }
                c.set_error(LastError::Io(line));
            }
        }
        close(&s, &hub, &mut tx, &mut ap, &mut open_log, Close::Over);
        tokio::select! {
            _ = &mut shutdown => break,
            _ = tokio::time::sleep(backoff.next_delay()) => {}
        }
    }
    // Shutdown: what the log was not told yet, at stop.
    close(&s, &hub, &mut tx, &mut ap, &mut open_log, Close::AtStop);
}

/// The closing lines of the link's repeated events `when`: whose
/// condition is over (core's `RateLog::settle`), or at stop, every count
/// not told yet (`RateLog::flush`): refusals, skips, other autopilots,
/// failed opens. Over: on each heartbeat tick while the link is up and
/// before each back-off wait while it is not, so a line comes at most a
/// second (or a back-off) after it is due; at stop: once `run_with` ends.
fn close(
    s: &MavlinkSettings,
    hub: &Hub,
    tx: &mut Sender,
    ap: &mut Autopilot,
    open_log: &mut RateLog,
    when: Close,
) {
    let now = Instant::now();
    hub.mavlink.close(now, when);
    tx.pos_skips.close(&hub.mavlink.skipped, now, when);
    tx.speed_skips.close(&hub.mavlink.speed_skipped, now, when);
    ap.close(now, when);
    if let Some(k) = tx.send_log.close(now, when) {
        tracing::warn!(
            send_errors = hub.mavlink.send_errors.load(Relaxed),
            since_last_line = k,
            "mavlink: send errors: {when}: {k} more since the last line, the last {:.1} s ago",
            tx.send_log.since_last(now).as_secs_f64()
        );
    }
    if let Some(k) = open_log.close(now, when) {
        tracing::warn!(
            attempts = hub.mavlink.link_failures.load(Relaxed),
            since_last_line = k,
            "mavlink: failed opens of {}: {when}: {k} more since the last line, \
             the last {:.1} s ago",
            s.endpoint,
            open_log.since_last(now).as_secs_f64()
        );
    }
}

/// Say at start how the link is signed (journal and STATUS).
fn announce_signing(s: &MavlinkSettings, hub: &Hub) {
    let Some(sg) = &s.signing else { return };
    let status = SigningStatus {
        key: sg.key.fingerprint(),
        link_id: sg.link_id,
        allow_unsigned: sg.allow_unsigned,
    };
    tracing::info!(
        "mavlink: signing with key {} on link id {}; unsigned frames {}",
        status.key,
        status.link_id,
        if status.allow_unsigned {
            "taken too"
        } else {
            "refused"
        }
    );
    if super::signing::timestamp_now() == 0 {
        tracing::warn!(
            "mavlink: the clock reads before 2015: signatures take their time from the \
             autopilot's first signed frame, and until then the autopilot may refuse ours"
        );
    }
    if let Ok(mut g) = hub.mavlink.signing.lock() {
        *g = Some(status);
    }
}

/// What a session borrows from the run: the sender, who the autopilot
/// is, and the reopen back-off.
struct Io<'a> {
    tx: &'a mut Sender,
    ap: &'a mut Autopilot,
    backoff: &'a mut Backoff,
    /// Failed opens: their closing line comes once the link is up.
    open_log: &'a mut RateLog,
}

async fn serve(
    s: &MavlinkSettings,
    hub: &Hub,
    mut link: Link,
    io: Io<'_>,
    mut shutdown: Pin<&mut impl Future<Output = ()>>,
) -> Ended {
    let Io {
        tx,
        ap,
        backoff,
        open_log,
    } = io;
    hub.mavlink.set_peer(None);
    let mut scanner = Scanner::new(link.framing());
    let mut beat = tokio::time::interval(s.heartbeat_period);
    beat.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        let had_peer = link.has_peer();
        tokio::select! {
            _ = &mut shutdown => return Ended::Shutdown,
            r = link.recv(scanner.spare()) => match r {
                Ok(n) => {
                    scanner.commit(n);
                    let refused = link.take_refused_connections();
                    if refused > 0 {
                        hub.mavlink.refused_connections.fetch_add(refused, Relaxed);
                    }
                    let now = Instant::now();
                    let from = Source {
                        addr: link.sender(),
                        admitted: link.sender_admitted(now),
                    };
                    let mut ask = None;
                    if absorb(&mut scanner, s, hub, ap, from, tx.enc.signer_mut(), &mut ask) {
                        if let Some(change) = link.accept_sender(now) {
                            peer_changed(hub, change);
                        }
                    }
                    // The autopilot's TIMESYNC request, answered at once
                    // (the round trip is what it measures).
                    if let Some(ask) = ask {
                        let msg = timesync_reply(ask.ts1, monotonic_ns(), ask.from);
                        tokio::select! {
                            _ = &mut shutdown => return Ended::Shutdown,
                            r = tx.send(&mut link, hub, &msg, 3) => if let Err(e) = r {
                                return Ended::Lost(e);
                            },
                        }
                    }
                    backoff.reset();
                    // On udpin the autopilot is known from its first
                    // valid frame: greet it now, not up to a period later.
                    if !had_peer && link.has_peer() {
                        beat.reset_immediately();
                    }
                }
                Err(e) if link.framing() == Framing::Stream => return Ended::Lost(e),
                // UDP: an ICMP "port unreachable" from a peer not yet up.
                Err(e) => {
                    hub.mavlink.recv_errors.fetch_add(1, Relaxed);
                    hub.mavlink.set_error(LastError::net(NetOp::Recv, &e));
                }
            },
            // A send may wait up to the serial link's write bound (the
            // autopilot not reading): a stop must not.
            _ = hub.outbox.offered() => tokio::select! {
                _ = &mut shutdown => return Ended::Shutdown,
                r = tx.poses(&mut link, s, hub) => if let Err(e) = r {
                    return Ended::Lost(e);
                },
            },
            _ = beat.tick() => {
                close(s, hub, tx, ap, open_log, Close::Over);
                let active = tx.last_sent.is_some_and(|t| t.elapsed() < 2 * s.heartbeat_period.max(Duration::from_secs(1)));
                let msg = heartbeat(active);
                tokio::select! {
                    _ = &mut shutdown => return Ended::Shutdown,
                    r = tx.send(&mut link, hub, &msg, 2) => if let Err(e) = r {
                        return Ended::Lost(e);
                    },
                }
            }
        }
    }
}

/// Who the autopilot is, for the whole run (kept across reopened links):
/// its system as configured, or learned from its first HEARTBEAT; its
/// component is configured (1 by default).
struct Autopilot {
    system: Option<u8>,
    /// Whether "autopilot: …" has been logged.
    announced: bool,
    /// Other autopilots' heartbeats (a second vehicle on the LAN): core's
    /// rule, the first at once, then less and less often.
    others: RateLog,
}

impl Autopilot {
    fn new(cfg: &InputConfig, hub: &Hub) -> Self {
        if let Some(system) = cfg.autopilot_system {
            hub.mavlink.set_autopilot(AutopilotId {
                system,
                component: cfg.autopilot_component,
                configured: true,
            });
        }
        Autopilot {
            system: cfg.autopilot_system,
            announced: false,
            others: RateLog::new(),
        }
    }

    /// An autopilot HEARTBEAT that passed `origin`: the autopilot's own,
    /// which teaches its system if not yet known.
    fn heartbeat(&mut self, f: &RawFrame, s: &MavlinkSettings, hub: &Hub, from: &Source) {
        if self.announced {
            return;
        }
        let configured = self.system.is_some();
        self.system = Some(f.system);
        self.announced = true;
        hub.mavlink.set_autopilot(AutopilotId {
            system: f.system,
            component: f.component,
            configured,
        });
        let at = from.describe(s);
        tracing::info!(
            "mavlink: autopilot: system {} component {} at {at}{}",
            f.system,
            f.component,
            if configured {
                ""
            } else {
                " (learned from its HEARTBEAT)"
            }
        );
    }

    /// The closing line of other autopilots' heartbeats `when`: once
    /// they stopped, or at stop.
    fn close(&mut self, now: Instant, when: Close) {
        if let Some(k) = self.others.close(now, when) {
            tracing::warn!(
                since_last_line = k,
                "mavlink: another autopilot's heartbeats: {when}: {k} more since \
                 the last line, the last {:.1} s ago",
                self.others.since_last(now).as_secs_f64()
            );
        }
    }

    /// A frame `origin` refused: if it is another autopilot's HEARTBEAT,
    /// say so (it is counted with the refusal and not adopted).
    fn other(&mut self, f: &RawFrame, s: &MavlinkSettings, from: &Source) {
        if !is_autopilot_heartbeat(f) {
            return;
        }
        if let Some(since) = self.others.tick(Instant::now()) {
            let at = from.describe(s);
            tracing::warn!(
                since_last_line = since,
                "mavlink: another autopilot, system {} component {} at {at}, is not adopted \
                 (the autopilot is system {:?} component {})",
                f.system,
                f.component,
                self.system,
                s.input.autopilot_component
            );
        }
    }
}

/// Where a datagram came from, and whether it may speak for the autopilot
/// (on `udpin`, see `Link::sender_admitted`).
#[derive(Clone, Copy)]
struct Source {
    addr: Option<SocketAddr>,
    admitted: bool,
}

impl Source {
    /// For a log line (rare: allocates).
    fn describe(&self, s: &MavlinkSettings) -> String {
        self.addr
            .map_or_else(|| s.endpoint.to_string(), |a| a.to_string())
    }
}

/// Count and log a move of the `udpin` peer.
fn peer_changed(hub: &Hub, change: PeerChange) {
    let c = &hub.mavlink;
    match change {
        PeerChange::First(to) => {
            tracing::info!("mavlink: poses go to {to}, where the autopilot's frames come from");
            c.set_peer(Some(to));
        }
        PeerChange::Moved { from, to } => {
            let n = c.peer_changes.fetch_add(1, Relaxed) + 1;
            tracing::warn!(
                peer_changes = n,
                "mavlink: poses go to {to} now: the autopilot's frames come from there, \
                 and {from} sent none for {} s",
                PEER_SILENCE.as_secs()
            );
            c.set_peer(Some(to));
        }
    }
}

/// A TIMESYNC request of the autopilot's, to be answered.
#[derive(Debug, Clone, Copy)]
struct TimesyncAsk {
    ts1: i64,
    /// Its (system, component): the answer's target.
    from: (u8, u8),
}

/// Turn everything the scanner holds into readings or counts. True when
/// it held a CRC-valid frame of the autopilot (on `udpin`, what makes its
/// sender the peer). With signing, a frame without the key's signature is
/// dropped first: it is nobody's, so it neither reads nor moves the peer.
fn absorb(
    sc: &mut Scanner,
    s: &MavlinkSettings,
    hub: &Hub,
    ap: &mut Autopilot,
    from: Source,
    mut signer: Option<&mut Signer>,
    ask: &mut Option<TimesyncAsk>,
) -> bool {
    let c = &hub.mavlink;
    let mut from_autopilot = false;
    while let Some(ev) = sc.next_frame() {
        match ev {
            Scanned::Frame(f) => {
                let checked = signer
                    .as_deref_mut()
                    .map_or(Ok(None), |sg| sg.verify(f.bytes));
                match checked {
                    Ok(ts) => {
                        let autopilot = take(&f, s, hub, ap, &from, ask);
                        from_autopilot |= autopilot;
                        // Our signing clock follows the autopilot's alone.
                        if let (true, Some(ts), Some(sg)) = (autopilot, ts, signer.as_deref_mut()) {
                            sg.follow(ts);
                        }
                    }
                    Err(r) => c.drop_frame(refusal_of(r), Some(f.msg_id)),
                }
            }
            Scanned::BadCrc { msg_id } => c.drop_frame(Refusal::BadCrc, Some(msg_id)),
            Scanned::Unknown { msg_id } => c.drop_frame(Refusal::UnknownMessage, Some(msg_id)),
            Scanned::BadFlags => c.drop_frame(Refusal::BadFlags, None),
        }
    }
    if sc.framing() == Framing::Datagram {
        sc.end_of_datagram();
    }
    c.garbage_bytes.fetch_add(sc.take_garbage(), Relaxed);
    let (datagrams, bytes) = sc.take_refused();
    if datagrams > 0 {
        c.refused_datagrams.fetch_add(datagrams, Relaxed);
        c.refused_bytes.fetch_add(bytes, Relaxed);
    }
    from_autopilot
}

fn refusal_of(r: Rejected) -> Refusal {
    match r {
        Rejected::Unsigned => Refusal::Unsigned,
        Rejected::BadSignature => Refusal::BadSignature,
        Rejected::Replayed => Refusal::Replayed,
        Rejected::Behind => Refusal::SigningClockBehind,
    }
}

/// One CRC-valid frame: a reading, a count or a refusal. True when it
/// came from the autopilot (a frame refused for its values, NaN or out of
/// range, still does).
fn take(
    f: &RawFrame,
    s: &MavlinkSettings,
    hub: &Hub,
    ap: &mut Autopilot,
    from: &Source,
    ask: &mut Option<TimesyncAsk>,
) -> bool {
    let c = &hub.mavlink;
    let now = Instant::now();
    c.frames.fetch_add(1, Relaxed);
    if let Err(r) = origin(f, &s.input, ap.system) {
        ap.other(f, s, from);
        c.refuse(&r);
        return false;
    }
    // The autopilot's ids from another address than the peer's, while
    // the peer speaks: a second vehicle with the same default ids.
    if !from.admitted {
        c.refuse(&Refused {
            reason: Refusal::OtherAddress,
            msg_id: f.msg_id,
            system: f.system,
            value: from.addr.map_or(f64::NAN, |a| a.port() as f64),
        });
        return false;
    }
    let input = match interpret(f, &s.input, &s.site) {
        Ok(i) => i,
        Err(r) => {
            c.refuse(&r);
            return ap.system.is_some();
        }
    };
    match input {
        Input::Attitude(a, rates) => hub.readings.store_attitude_with_rates(now, &a, rates),
        Input::Depth(d) => hub.readings.store_depth(now, &d),
        Input::Temperature(t) => hub.readings.store_temperature(now, t),
        Input::AutopilotHeartbeat => {
            ap.heartbeat(f, s, hub, from);
            if let Ok(mut g) = c.autopilot_seen.lock() {
                *g = Some(now);
            }
        }
        // The latest of a datagram's requests is answered.
        Input::TimesyncRequest { ts1 } => {
            *ask = Some(TimesyncAsk {
                ts1,
                from: (f.system, f.component),
            })
        }
        Input::Unused => {
            c.unused.fetch_add(1, Relaxed);
        }
    }
    if let Some(k) = input.kind() {
        c.used[k].fetch_add(1, Relaxed);
    }
    // Before the system is known only a HEARTBEAT passes `origin`, and
    // one of a GCS or a companion is not the autopilot's.
    ap.system.is_some()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_position_rate_below_4_hz_is_warned_about() {
        let at = |r| OutputConfig {
            position_rate_hz: r,
            ..OutputConfig::default()
        };
        let why = slow_rate(&at(Some(3.0))).expect("3 Hz is too slow");
        assert!(why.contains("333 ms") && why.contains("300 ms"), "{why}");
        assert_eq!(slow_rate(&at(Some(4.0))), None);
        assert_eq!(slow_rate(&at(None)), None);
    }
}
