//! What the MAVLink link did, for STATUS: messages used per kind, refused
//! per reason, sent per kind, skipped per reason, and the last error.
//! Counters are atomics; the last error and the autopilot's last heartbeat
//! are kept under a lock that only the I/O task and STATUS take, the
//! refusals' log rule under one that only the I/O task takes.

use super::inbound::{Refusal, Refused};
use super::outbound::Skip;
use lightpose_core::ratelog::{Close, RateLog};
use serde::Serialize;
use std::io;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::sync::Mutex;
use std::time::Instant;

/// Kinds of used input, in `Input::kind` order.
pub const USED: [&str; 5] = [
    "attitude",
    "depth",
    "temperature",
    "autopilot_heartbeat",
    "timesync_request",
];
/// Kinds of output.
pub const SENT: [&str; 4] = [
    "vision_position_estimate",
    "vision_speed_estimate",
    "heartbeat",
    "timesync",
];

#[derive(Default)]
pub struct MavCounters {
    pub(crate) frames: AtomicU64,
    pub(crate) used: [AtomicU64; USED.len()],
    pub(crate) unused: AtomicU64,
    pub(crate) refused: [AtomicU64; Refusal::ALL.len()],
    pub(crate) garbage_bytes: AtomicU64,
    pub(crate) refused_datagrams: AtomicU64,
    pub(crate) refused_bytes: AtomicU64,
    pub(crate) sent: [AtomicU64; SENT.len()],
    pub(crate) skipped: [AtomicU64; Skip::ALL.len()],
    pub(crate) speed_skipped: [AtomicU64; Skip::ALL.len()],
    pub(crate) no_peer: AtomicU64,
    pub(crate) send_errors: AtomicU64,
    pub(crate) recv_errors: AtomicU64,
    pub(crate) link_opens: AtomicU64,
    pub(crate) link_failures: AtomicU64,
    pub(crate) autopilot_seen: Mutex<Option<Instant>>,
    /// The autopilot, once configured or learned (see `inbound::origin`).
    pub(crate) autopilot: Mutex<Option<AutopilotId>>,
    /// Where poses go on `udpin`: a copy of the link's, for STATUS.
    pub(crate) peer: Mutex<Option<SocketAddr>>,
    pub(crate) peer_changes: AtomicU64,
    pub(crate) refused_connections: AtomicU64,
    pub(crate) last_error: Mutex<Option<LastError>>,
    /// MAVLink 2 signing as the task runs it (null: off).
    pub(crate) signing: Mutex<Option<SigningStatus>>,
    /// Per refusal reason, core's rule: the first at once, then less and
    /// less often while they go on (a flood was a line every 1000th).
    refused_log: Mutex<[RateLog; Refusal::ALL.len()]>,
}

/// Who the autopilot is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct AutopilotId {
    pub system: u8,
    pub component: u8,
    /// From `[mavlink] autopilot_system_id` (else learned from its
    /// HEARTBEAT).
    pub configured: bool,
}

/// Signing as configured, for STATUS: the key by its fingerprint only.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct SigningStatus {
    /// The first 4 bytes of the key's SHA-256, in hex.
    pub key: String,
    pub link_id: u8,
    /// Unsigned frames are taken too.
    pub allow_unsigned: bool,
}

/// STATUS figures of the MAVLink link.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MavlinkStatus {
    /// CRC-valid frames received.
    pub frames: u64,
    /// Messages used, per kind.
    #[serde(serialize_with = "crate::counts_as_map")]
    pub used: Vec<(&'static str, u64)>,
    /// Valid messages with nothing for us.
    pub unused: u64,
    /// Messages or frame candidates refused, per reason.
    #[serde(serialize_with = "crate::counts_as_map")]
    pub refused: Vec<(&'static str, u64)>,
    /// Bytes that were no part of any frame.
    pub garbage_bytes: u64,
    /// Datagrams ended by a candidate that failed (its reason is counted
    /// once in `refused`), and their bytes from it on.
    pub refused_datagrams: u64,
    pub refused_bytes: u64,
    #[serde(serialize_with = "crate::counts_as_map")]
    pub sent: Vec<(&'static str, u64)>,
    /// `ok` poses not sent, per reason.
    #[serde(serialize_with = "crate::counts_as_map")]
    pub skipped: Vec<(&'static str, u64)>,
    /// Speeds not sent although the surge was known, per reason.
    #[serde(serialize_with = "crate::counts_as_map")]
    pub speed_skipped: Vec<(&'static str, u64)>,
    /// Frames not sent because a `udpin` link had heard nobody yet.
    pub no_peer: u64,
    pub send_errors: u64,
    pub recv_errors: u64,
    pub link_opens: u64,
    pub link_failures: u64,
    /// Seconds since the autopilot's last HEARTBEAT.
    pub autopilot_heartbeat_age_s: Option<f64>,
    /// The autopilot whose readings are taken (null until known).
    pub autopilot: Option<AutopilotId>,
    /// Where poses go on `udpin` (null before the autopilot spoke, and on
    /// other transports).
    pub peer: Option<String>,
    /// Moves of the `udpin` peer after it was silent (the first is none).
    pub peer_changes: u64,
    /// `tcpin` connections closed at once while another still spoke.
    pub refused_connections: u64,
    pub last_error: Option<String>,
    /// Signing, when configured (its refusals are `unsigned`,
    /// `bad_signature` and `replayed` in `refused`).
    pub signing: Option<SigningStatus>,
}

fn table<const N: usize>(names: [&'static str; N], c: &[AtomicU64; N]) -> Vec<(&'static str, u64)> {
    names
        .iter()
        .zip(c)
        .map(|(n, v)| (*n, v.load(Relaxed)))
        .collect()
}

/// The name of a message id, for error lines.
pub fn message_name(id: u32) -> String {
    use mavlink::dialects::ardupilotmega::MavMessage;
    use mavlink::Message;
    match MavMessage::default_message_from_id(id) {
        Some(m) => m.message_name().to_string(),
        None => format!("message {id}"),
    }
}

/// Which side of a UDP link failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum NetOp {
    Recv,
    Send,
}

/// The latest thing that went wrong, kept as data and worded only when
/// STATUS asks (a flood of bad messages formats nothing).
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum LastError {
    Refused(Refused),
    Dropped(Refusal, Option<u32>),
    /// A UDP receive or send that failed: the OS's error number (else the
    /// kind), not its text. A `udpout` peer that is down fails about once
    /// per pose (ECONNREFUSED), and that must not allocate.
    Net {
        op: NetOp,
        kind: io::ErrorKind,
        os: Option<i32>,
    },
    /// Opening or losing the link: rare, worded when it happens.
    Io(String),
}

impl LastError {
    fn line(&self) -> String {
        match self {
            LastError::Refused(r) => format!(
                "{} from system {}: {} ({})",
                message_name(r.msg_id),
                r.system,
                r.reason.as_str(),
                r.value
            ),
            LastError::Dropped(reason, id) => format!(
                "{}: {}",
                id.map(message_name).unwrap_or_else(|| "frame".into()),
                reason.as_str()
            ),
            LastError::Net { op, kind, os } => {
                let e = os.map_or_else(|| io::Error::from(*kind), io::Error::from_raw_os_error);
                let op = match op {
                    NetOp::Recv => "receive",
                    NetOp::Send => "send",
                };
                format!("{op}: {e}")
            }
            LastError::Io(s) => s.clone(),
        }
    }

    /// A failed UDP receive or send, without wording it.
    pub(crate) fn net(op: NetOp, e: &io::Error) -> Self {
        LastError::Net {
            op,
            kind: e.kind(),
            os: e.raw_os_error(),
        }
    }
}

impl MavCounters {
    /// Count a refused message; the first of each reason is logged at
    /// once, then less and less often while more come (core's `RateLog`),
    /// and the latest is kept for STATUS.
    pub(crate) fn refuse(&self, r: &Refused) {
        let e = LastError::Refused(*r);
        if let Some((count, since)) = self.count_refusal(r.reason) {
            tracing::warn!(
                count,
                since_last_line = since,
                "mavlink: refused {}",
                e.line()
            );
        }
        self.set_error(e);
    }

    /// Count a dropped frame candidate (bad CRC, unknown id, bad flags).
    pub(crate) fn drop_frame(&self, reason: Refusal, msg_id: Option<u32>) {
        let e = LastError::Dropped(reason, msg_id);
        if let Some((count, since)) = self.count_refusal(reason) {
            tracing::warn!(
                count,
                since_last_line = since,
                "mavlink: dropped {}",
                e.line()
            );
        }
        self.set_error(e);
    }

    /// The closing line `when` of each refusal reason that stopped coming
    /// (core's `RateLog::settle`) or, at stop, with refusals not told yet
    /// (`RateLog::flush`), with its count in all.
    pub(crate) fn close(&self, now: Instant, when: Close) {
        let mut logs = self.refused_log.lock().unwrap_or_else(|p| p.into_inner());
        for (r, log) in Refusal::ALL.iter().zip(logs.iter_mut()) {
            let Some(since) = log.close(now, when) else {
                continue;
            };
            tracing::warn!(
                count = self.refused(*r),
                since_last_line = since,
                "mavlink: refused or dropped ({}): {when}: {since} more since the \
                 last line, the last {:.1} s ago",
                r.as_str(),
                log.since_last(now).as_secs_f64()
            );
        }
    }

    /// Count one of `reason`: (its count, those since the last line) when
    /// a line is due.
    fn count_refusal(&self, reason: Refusal) -> Option<(u64, u64)> {
        let i = reason.index();
        let count = self.refused[i].fetch_add(1, Relaxed) + 1;
        let mut logs = self.refused_log.lock().unwrap_or_else(|p| p.into_inner());
        let since = logs.get_mut(i)?.tick(Instant::now())?;
        Some((count, since))
    }

    pub(crate) fn set_error(&self, e: LastError) {
        if let Ok(mut g) = self.last_error.lock() {
            *g = Some(e);
        }
    }

    /// The autopilot, once known.
    pub fn autopilot(&self) -> Option<AutopilotId> {
        self.autopilot.lock().ok().and_then(|g| *g)
    }

    /// The `udpin` peer, if any.
    pub fn peer(&self) -> Option<SocketAddr> {
        self.peer.lock().ok().and_then(|g| *g)
    }

    pub fn peer_changes(&self) -> u64 {
        self.peer_changes.load(Relaxed)
    }

    pub(crate) fn set_autopilot(&self, id: AutopilotId) {
        if let Ok(mut g) = self.autopilot.lock() {
            *g = Some(id);
        }
    }

    pub(crate) fn set_peer(&self, p: Option<SocketAddr>) {
        if let Ok(mut g) = self.peer.lock() {
            *g = p;
        }
    }

    pub fn refused(&self, reason: Refusal) -> u64 {
        self.refused[reason.index()].load(Relaxed)
    }

    /// Messages used of kind `k` (see [`USED`]).
    pub fn used(&self, k: usize) -> u64 {
        self.used.get(k).map_or(0, |c| c.load(Relaxed))
    }

    /// Messages sent of kind `k` (see [`SENT`]).
    pub fn sent(&self, k: usize) -> u64 {
        self.sent.get(k).map_or(0, |c| c.load(Relaxed))
    }

    /// Seconds since the autopilot's last HEARTBEAT (`None`: none yet).
    pub fn autopilot_heartbeat_age_s(&self, now: Instant) -> Option<f64> {
        self.autopilot_seen
            .lock()
            .ok()
            .and_then(|g| *g)
            .map(|t| now.saturating_duration_since(t).as_secs_f64())
    }

    pub fn status(&self, now: Instant) -> MavlinkStatus {
        let nz = |v: Vec<(&'static str, u64)>| v.into_iter().filter(|(_, n)| *n > 0).collect();
        MavlinkStatus {
            frames: self.frames.load(Relaxed),
            used: table(USED, &self.used),
            unused: self.unused.load(Relaxed),
            refused: nz(table(Refusal::ALL.map(Refusal::as_str), &self.refused)),
            garbage_bytes: self.garbage_bytes.load(Relaxed),
            refused_datagrams: self.refused_datagrams.load(Relaxed),
            refused_bytes: self.refused_bytes.load(Relaxed),
            sent: table(SENT, &self.sent),
            skipped: nz(table(Skip::ALL.map(Skip::as_str), &self.skipped)),
            speed_skipped: nz(table(Skip::ALL.map(Skip::as_str), &self.speed_skipped)),
            no_peer: self.no_peer.load(Relaxed),
            send_errors: self.send_errors.load(Relaxed),
            recv_errors: self.recv_errors.load(Relaxed),
            link_opens: self.link_opens.load(Relaxed),
            link_failures: self.link_failures.load(Relaxed),
            autopilot_heartbeat_age_s: self.autopilot_heartbeat_age_s(now),
            autopilot: self.autopilot(),
            peer: self.peer().map(|a| a.to_string()),
            peer_changes: self.peer_changes(),
            refused_connections: self.refused_connections.load(Relaxed),
            last_error: self
                .last_error
                .lock()
                .ok()
                .and_then(|g| g.as_ref().map(LastError::line)),
            signing: self.signing.lock().ok().and_then(|g| g.clone()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A failed receive or send is kept as its error number and worded,
    /// as the OS words it, only when STATUS asks.
    #[test]
    fn a_network_error_is_worded_when_status_asks() {
        let c = MavCounters::default();
        let refused = io::Error::from_raw_os_error(nix::libc::ECONNREFUSED);
        let e = LastError::net(NetOp::Send, &refused);
        assert_eq!(
            e,
            LastError::Net {
                op: NetOp::Send,
                kind: io::ErrorKind::ConnectionRefused,
                os: Some(nix::libc::ECONNREFUSED),
            }
        );
        c.set_error(e);
        let line = c.status(Instant::now()).last_error.unwrap_or_default();
        assert_eq!(line, format!("send: {refused}"));
        // An error with no number keeps its kind.
        let e = io::Error::new(io::ErrorKind::TimedOut, "slow");
        c.set_error(LastError::net(NetOp::Recv, &e));
        let line = c.status(Instant::now()).last_error.unwrap_or_default();
        assert_eq!(
            line,
            format!("receive: {}", io::Error::from(io::ErrorKind::TimedOut))
        );
    }
}
